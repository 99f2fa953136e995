# ParaView picture of a 3D vesicle computed on one octant (three mirror planes): the octant's field
# file is mirrored into the whole body, its membrane drawn as the surface phi = 0, and beside it
# the diffuse interface in the plane y = 0 (phi from -1 outside to 1 inside). Takes a run's closing
# file or a schedule's stage file (NAME_stage_K.xmf).
#
#   xvfb-run -a pvbatch demos/shapes/render_octant.py build/demo/dumbbell_octant/dumbbell_octant.xmf OUT.png
#
# Needs ParaView (Debian: paraview, python3-paraview; xvfb for a machine without a display). The
# membrane is the zero contour of the nodal field as the file holds it, which is what ParaView shows
# of the .xmf; docs/scaling.md measures the membrane with the LME interpolant instead.
import argparse
import os

from paraview.simple import (  # noqa: F401  (pvbatch's module)
    Contour, CreateLayout, CreateView, GetColorTransferFunction, GetScalarBar, Reflect, Render, SaveScreenshot, Show,
    Slice, XDMFReader)

parser = argparse.ArgumentParser(description="ParaView picture of a 3D vesicle computed on one octant")
parser.add_argument("xmf", help="the octant run's .xmf (its .h5 beside it)")
parser.add_argument("png", help="the picture to write")
parser.add_argument("--width", type=int, default=1600)
parser.add_argument("--height", type=int, default=700)
args = parser.parse_args()

octant = XDMFReader(registrationName=os.path.basename(args.xmf), FileNames=[os.path.abspath(args.xmf)])
# A run's closing file names the phase field phi; a schedule's stage checkpoint holds it as its state.
field = next((name for name in ("phi", "state") if name in octant.PointData.keys()), None)
if field is None:
    raise SystemExit(f"{args.xmf} holds neither phi nor state: {', '.join(octant.PointData.keys())}")
octant.PointArrayStatus = [field]
body = octant
for plane in ("X Min", "Y Min", "Z Min"):  # each mirror plane doubles the body
    body = Reflect(Input=body, Plane=plane, CopyInput=1)

membrane = Contour(Input=body, ContourBy=["POINTS", field], Isosurfaces=[0.0], ComputeNormals=1)
section = Slice(Input=body)
section.SliceType = "Plane"
section.SliceType.Origin = [0.0, 0.0, 0.0]
section.SliceType.Normal = [0.0, 1.0, 0.0]

layout = CreateLayout("vesicle")
left = CreateView("RenderView")
layout.AssignView(0, left)
layout.SplitHorizontal(0, 0.5)
right = CreateView("RenderView")
layout.AssignView(2, right)
for view in (left, right):
    view.OrientationAxesVisibility = 0
    view.Background = [1.0, 1.0, 1.0]
    try:  # ParaView >= 5.10 keeps the background in a palette unless told to use its own
        view.UseColorPaletteForBackground = 0
    except AttributeError:
        pass

surface = Show(membrane, left)
surface.DiffuseColor = [0.85, 0.35, 0.3]
surface.AmbientColor = [0.85, 0.35, 0.3]
surface.Specular = 0.3
surface.ColorArrayName = [None, ""]
left.CameraPosition = [3.2, -4.2, 2.6]
left.CameraFocalPoint = [0.0, 0.0, 0.0]
left.CameraViewUp = [0.0, 0.0, 1.0]
left.ResetCamera()

shown = Show(section, right)
shown.ColorArrayName = ["POINTS", field]
phi_colours = GetColorTransferFunction(field)
phi_colours.ApplyPreset("Cool to Warm", True)
phi_colours.RescaleTransferFunction(-1.0, 1.0)
shown.SetScalarBarVisibility(right, True)
bar = GetScalarBar(phi_colours, right)
bar.Title = "phi in the plane y = 0"
bar.ComponentTitle = ""
bar.TitleColor = [0.0, 0.0, 0.0]
bar.LabelColor = [0.0, 0.0, 0.0]
bar.WindowLocation = "Any Location"
bar.Position = [0.78, 0.08]
bar.ScalarBarLength = 0.45
bar.RangeLabelFormat = "%.0f"
zero = Show(Contour(Input=section, ContourBy=["POINTS", field], Isosurfaces=[0.0]), right)
zero.ColorArrayName = [None, ""]
zero.DiffuseColor = [0.0, 0.0, 0.0]
zero.AmbientColor = [0.0, 0.0, 0.0]
zero.LineWidth = 2.0
right.CameraPosition = [0.0, -6.0, 0.0]
right.CameraFocalPoint = [0.0, 0.0, 0.0]
right.CameraViewUp = [0.0, 0.0, 1.0]
right.CameraParallelProjection = 1
right.ResetCamera()
# The section framed around the membrane, not the whole box.
membrane.UpdatePipeline()
lo_x, hi_x, _, _, lo_z, hi_z = membrane.GetDataInformation().GetBounds()
right.CameraParallelScale = 0.85 * max(hi_x - lo_x, hi_z - lo_z)

Render(left)
Render(right)
SaveScreenshot(args.png, layout, ImageResolution=[args.width, args.height])
print(f"wrote {args.png}")
