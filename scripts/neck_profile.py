#!/usr/bin/python3
"""The neck and bulbs of an axisymmetric budding vesicle, from series files of lmeform run.

    /usr/bin/python3 scripts/neck_profile.py SERIES.h5... [--zmin 0.6 --zmax 1.0] [--plot OUT.png]

For each file (current node positions, their triangulation and the nodal phi) it takes the
phi = 0 contour of the linear interpolant of the nodal coefficients and prints

  neck r (z)      the smallest r of the contour with zmin < z < zmax, and its height;
  lower bulb r    the largest r of the contour below the neck, and the contour's z range there;
  upper bulb r    the same above the neck.

With --plot it draws the nodes near the neck coloured by their coefficient, with the contour, one
panel per file (the coefficients scramble at the node scale where a map compresses too much).
LME is not interpolating: the radii carry an error of the node spacing.
"""
import argparse

import h5py
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.tri as mtri  # noqa: E402


def load(path):
    with h5py.File(path, "r") as h:
        return h["nodes"][:], h["fields/phi"][:], h["cells"][:]


def contour(x, phi, cells):
    tri = mtri.Triangulation(x[:, 0], x[:, 1], cells)
    cs = plt.tricontour(tri, phi, levels=[0.0])
    segments = [s for s in cs.allsegs[0] if len(s)]
    plt.close()
    return tri, np.vstack(segments)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("series", nargs="+")
    parser.add_argument("--zmin", type=float, default=0.6, help="the neck is searched above this height")
    parser.add_argument("--zmax", type=float, default=1.0, help="... and below this one")
    parser.add_argument("--plot", help="PNG of the nodes near the neck")
    args = parser.parse_args()
    panels = []
    for path in args.series:
        x, phi, cells = load(path)
        tri, c = contour(x, phi, cells)
        band = c[(c[:, 1] > args.zmin) & (c[:, 1] < args.zmax)]
        if len(band) == 0:
            print(f"{path}: no contour between z = {args.zmin} and {args.zmax}")
            continue
        neck = band[np.argmin(band[:, 0])]
        lower, upper = c[c[:, 1] < neck[1]], c[c[:, 1] > neck[1]]
        lo, up = lower[np.argmax(lower[:, 0])], upper[np.argmax(upper[:, 0])]
        print(f"{path}: neck r {neck[0]:.4f} (z {neck[1]:.3f}) | lower bulb r {lo[0]:.4f}, z {lower[:, 1].min():.3f}-{neck[1]:.3f}"
              f" | upper bulb r {up[0]:.4f}, z {neck[1]:.3f}-{upper[:, 1].max():.3f}")
        panels.append((path, x, phi, tri, neck))
    if args.plot and panels:
        fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.6), squeeze=False)
        for ax, (path, x, phi, tri, neck) in zip(axes[0], panels):
            sc = ax.scatter(x[:, 0], x[:, 1], c=phi, s=6, cmap="coolwarm", vmin=-1.2, vmax=1.2)
            ax.tricontour(tri, phi, levels=[0.0], colors="k", linewidths=1)
            ax.set_xlim(0, 0.35)
            ax.set_ylim(neck[1] - 0.25, neck[1] + 0.3)
            ax.set_aspect("equal")
            digits = "".join(ch for ch in path.rsplit("_", 1)[-1] if ch.isdigit())
            ax.set_title(f"step {int(digits)}" if digits else path)
            ax.set_xlabel("r")
            ax.set_ylabel("z")
        fig.colorbar(sc, ax=axes[0].tolist(), label="nodal coefficient of phi", shrink=0.8)
        fig.savefig(args.plot, dpi=110)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
