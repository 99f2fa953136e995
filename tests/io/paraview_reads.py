# Opens a field file's XDMF sidecar with ParaView's XDMF reader (run by pvbatch) and checks that it
# sees what the HDF5 file holds: the points, the cells, every field with its values.
#   pvbatch paraview_reads.py FILE.xmf
import sys

import h5py
import numpy as np
from paraview import servermanager
from paraview.simple import XDMFReader
from vtk.util.numpy_support import vtk_to_numpy

xmf = sys.argv[1]
reader = XDMFReader(FileNames=[xmf])
reader.UpdatePipeline()
grid = servermanager.Fetch(reader)
if grid.IsA("vtkMultiBlockDataSet"):
    grid = grid.GetBlock(0)
with h5py.File(xmf[: -len(".xmf")] + ".h5", "r") as f:
    nodes = np.array(f["nodes"])
    cells = np.array(f["cells"])
    fields = {name: np.array(f["fields"][name]) for name in f["fields"]}
failures = []
if grid.GetNumberOfPoints() != len(nodes):
    failures.append(f"{grid.GetNumberOfPoints()} points, the file has {len(nodes)}")
if grid.GetNumberOfCells() != len(cells):
    failures.append(f"{grid.GetNumberOfCells()} cells, the file has {len(cells)}")
points = vtk_to_numpy(grid.GetPoints().GetData())[:, : nodes.shape[1]]
if not np.array_equal(points, nodes):
    failures.append("the points differ from /nodes")
for name, values in fields.items():
    array = grid.GetPointData().GetArray(name)
    if array is None:
        failures.append(f"no point array '{name}'")
    elif not np.array_equal(vtk_to_numpy(array).reshape(values.shape), values):
        failures.append(f"'{name}' differs from /fields/{name}")
if failures:
    print("FAIL: " + "; ".join(failures))
    sys.exit(1)
print(f"ParaView reads {xmf}: {len(nodes)} points, {len(cells)} cells, fields {', '.join(sorted(fields))}")
