#!/usr/bin/python3
"""Draw a scalar nodal field of a 2D lmeform field file (docs/output.md).

    /usr/bin/python3 plot_field.py FILE.h5 OUT.png [--title T] [--mirror] [--field phi]

The node set is drawn as points coloured by the field, its zero contour (a phase field's interface)
over it by tricontour on the stored background triangles, at equal aspect with a colorbar. --mirror
reflects r -> -r to show the full cross-section of an axisymmetric field (axes r and z; else x, y).
`lmeform run` calls it where a scene asks for a figure ([output] png = true) and `lmeform plot`
on any field file; both find it next to the lmeform binary (share/lmeform/).
Needs Debian's python3-matplotlib, python3-h5py and numpy (call /usr/bin/python3, not a pyenv one);
without them it exits with status 3.
"""

import argparse
import os
import sys


def fail(message, code=1):
    print(f"plot_field.py: {message}", file=sys.stderr)
    sys.exit(code)


def load(path, field):
    import h5py
    import numpy as np

    try:
        f = h5py.File(path, "r")
    except OSError as e:
        fail(f"{path}: cannot open: {e}")
    with f:
        for name in ("nodes", "cells", f"fields/{field}"):
            if name not in f:
                fail(f"{path}: missing dataset /{name}")
        nodes = np.asarray(f["nodes"][...], dtype=float)
        cells = np.asarray(f["cells"][...], dtype=np.int64)
        values = np.asarray(f[f"fields/{field}"][...], dtype=float)
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    if nodes.ndim != 2 or nodes.shape[1] != 2:
        fail(f"{path}: /nodes is {nodes.shape}; the plot needs 2D nodes")
    if cells.ndim != 2 or cells.shape[1] != 3:
        fail(f"{path}: /cells is {cells.shape}; expected triangles (M x 3)")
    if values.ndim != 1 or values.shape[0] != nodes.shape[0]:
        fail(f"{path}: /fields/{field} is {values.shape}; expected one value per node ({nodes.shape[0]})")
    return nodes, cells, values, attrs


def mirror(nodes, cells, values):
    """Reflect r -> -r; nodes on the axis (r = 0) are shared by both halves."""
    import numpy as np

    n = nodes.shape[0]
    on_axis = nodes[:, 0] == 0.0
    off = np.flatnonzero(~on_axis)
    index = np.arange(n)
    index[off] = n + np.arange(off.size)  # mirrored copy of node i; axis nodes map to themselves
    mirrored = nodes[off].copy()
    mirrored[:, 0] = -mirrored[:, 0]
    all_nodes = np.vstack([nodes, mirrored])
    all_values = np.concatenate([values, values[off]])
    all_cells = np.vstack([cells, index[cells][:, ::-1]])
    return all_nodes, all_cells, all_values


def subtitle(attrs):
    parts = []
    for key, label in (("energy", "E"), ("eps", "ε"), ("step", "step")):
        if key in attrs:
            v = attrs[key]
            parts.append(f"{label} = {v:.6g}" if isinstance(v, float) else f"{label} = {v}")
    return ",  ".join(parts)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file", help="field file written by lmeform (HDF5)")
    parser.add_argument("out", help="PNG to write")
    parser.add_argument("--title", default=None, help="title above the plot (default: the file name)")
    parser.add_argument("--mirror", action="store_true", help="mirror r -> -r: the full cross-section")
    parser.add_argument("--field", default="phi", help="nodal field to colour by (default: phi)")
    parser.add_argument("--dpi", type=int, default=150)
    args = parser.parse_args()

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import matplotlib.tri as mtri
        import numpy as np
        import h5py  # noqa: F401  (checked here, used in load)
    except ImportError as e:
        fail(f"{e}; run with Debian's /usr/bin/python3 (python3-matplotlib, python3-h5py)", code=3)

    nodes, cells, values, attrs = load(args.file, args.field)
    n_file = len(values)
    if args.mirror:
        nodes, cells, values = mirror(nodes, cells, values)
    r, z = nodes[:, 0], nodes[:, 1]
    tri = mtri.Triangulation(r, z, cells)

    width = r.max() - r.min()
    height = z.max() - z.min()
    fig_h = 6.0
    fig_w = min(max((fig_h - 1.0) * width / max(height, 1e-12) + 1.9, 4.0), 14.0)
    fig, ax = plt.subplots(figsize=(fig_w, fig_h), layout="constrained")

    lim = max(1.0, float(np.nanmax(np.abs(values)))) if args.field == "phi" else None
    vmin, vmax = (-lim, lim) if lim is not None else (float(np.nanmin(values)), float(np.nanmax(values)))
    # Marker area from the mean spacing, so that dense and coarse node sets both read as points.
    spacing = np.sqrt(width * height / max(len(r), 1))
    points_per_unit = 72.0 * fig_h * 0.8 / max(height, 1e-12)
    size = float(np.clip((0.45 * spacing * points_per_unit) ** 2, 0.3, 30.0))
    sc = ax.scatter(r, z, c=values, s=size, cmap="coolwarm", vmin=vmin, vmax=vmax, linewidths=0,
                    rasterized=True)
    if values.min() < 0.0 < values.max():
        ax.tricontour(tri, values, levels=[0.0], colors="k", linewidths=1.6)
        ax.plot([], [], color="k", linewidth=1.6, label=f"{args.field} = 0")
        ax.legend(loc="upper right", framealpha=0.85, fontsize=9)
    if args.mirror:
        ax.axvline(0.0, color="0.5", linewidth=0.6, linestyle=":")

    ax.set_aspect("equal")
    ax.set_xlim(r.min(), r.max())
    ax.set_ylim(z.min(), z.max())
    ax.set_xlabel("r" if args.mirror else "x")
    ax.set_ylabel("z" if args.mirror else "y")
    title = args.title if args.title is not None else args.file.rsplit("/", 1)[-1]
    info = subtitle(attrs)
    info = f"{n_file} nodes" + (f",  {info}" if info else "")
    ax.set_title(f"{title}\n{info}", fontsize=10)
    cb = fig.colorbar(sc, ax=ax, shrink=0.85, pad=0.02)
    cb.set_label(args.field)

    # Written beside the target and renamed: no half-written PNG on failure.
    tmp = args.out + ".tmp"
    try:
        fig.savefig(tmp, dpi=args.dpi, format="png")
        os.replace(tmp, args.out)
    except OSError as e:
        if os.path.exists(tmp):
            os.remove(tmp)
        fail(f"{args.out}: cannot write: {e}")
    finally:
        plt.close(fig)


if __name__ == "__main__":
    main()
