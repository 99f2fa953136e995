#!/usr/bin/env python3
"""Pressure and velocity of two lmeform Stokes runs side by side (seed thesis Fig. 5.1).

    plot_pressure.py UNSTABILIZED.h5 STABILIZED.h5 OUT.png

Each .h5 is the output of `lmeform run` (nodes, cells, fields/u, fields/p). The pressure is drawn
as a piecewise-linear field on the Delaunay cells of the nodes (nodal values), the velocity as arrows.
"""
import sys

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.tri as mtri
import numpy as np


def read(path):
    with h5py.File(path, "r") as f:
        return f["nodes"][()], f["cells"][()], f["fields/u"][()], f["fields/p"][()]


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    titles = ("without stabilization (C = 0)", "GLS-stabilized")
    fig, axes = plt.subplots(2, 2, figsize=(10, 9))
    for col, (path, title) in enumerate(zip(sys.argv[1:3], titles)):
        x, cells, u, p = read(path)
        tri = mtri.Triangulation(x[:, 0], x[:, 1], cells)
        ax = axes[0, col]
        speed = np.hypot(u[:, 0], u[:, 1])
        ax.quiver(x[:, 0], x[:, 1], u[:, 0], u[:, 1], speed, cmap="viridis")
        ax.set_title(f"velocity, {title}")
        ax.set_aspect("equal")
        ax = axes[1, col]
        levels = 30
        c = ax.tricontourf(tri, p, levels=levels, cmap="RdBu_r")
        fig.colorbar(c, ax=ax, shrink=0.8)
        ax.set_title(f"pressure, {title}\nmin {p.min():.3g}, max {p.max():.3g}")
        ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(sys.argv[3], dpi=110)
    print(f"wrote {sys.argv[3]}")


if __name__ == "__main__":
    main()
