#!/usr/bin/env python3
"""A 3D octant vesicle against its axisymmetric twin: energies and the membrane (phi = 0) in the
octant's mirror planes against the axisymmetric meridian.

    octant_vs_axisymmetric.py OCTANT_DIR AXISYMMETRIC_DIR --axis x|z --out FIGURE.png

Each directory is a run's output folder (`lmeform run SCENE --output DIR --json DIR.json`): its
NAME.h5, and the run's JSON as DIR/run.json or DIR.json. `--axis` is the 3D axis of revolution (the axisymmetric z). The octant's
energy is multiplied by 8 (three mirror planes). Prints the energies, their relative difference and
the membrane's extent along and across the axis in each mirror plane. The figure has the contours
and a 3D view of the membrane: phi = 0 on the octant's tetrahedra (piecewise linear, marching
tetrahedra), mirrored into the other seven octants (the view ParaView gives of NAME.xmf).
"""
import argparse
import glob
import json
import os
import sys

import h5py
import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.tri as mtri


def load(run_dir):
    h5 = [f for f in glob.glob(os.path.join(run_dir, "*.h5")) if not f.endswith("_checkpoint.h5")]
    if len(h5) != 1:
        sys.exit(f"{run_dir}: expected one output .h5, found {h5}")
    with h5py.File(h5[0], "r") as f:
        nodes, phi, cells = f["nodes"][:], f["fields/phi"][:].ravel(), f["cells"][:]
    json_path = os.path.join(run_dir, "run.json")
    if not os.path.exists(json_path):
        json_path = run_dir.rstrip("/") + ".json"
    with open(json_path) as f:
        record = json.load(f)
    return nodes, phi, cells, record


def zero_surface(nodes, phi, tets):
    """Triangles of phi = 0 over tetrahedra, linear along each edge (marching tetrahedra)."""
    triangles = []
    for tet in tets:
        values = phi[tet]
        inside = [v for v in range(4) if values[v] >= 0]
        if len(inside) in (0, 4):
            continue
        outside = [v for v in range(4) if values[v] < 0]

        def cross(a, b):
            t = values[a] / (values[a] - values[b])
            return nodes[tet[a]] + t * (nodes[tet[b]] - nodes[tet[a]])

        if len(inside) in (1, 3):
            lone, rest = (inside[0], outside) if len(inside) == 1 else (outside[0], inside)
            triangles.append([cross(lone, r) for r in rest])
        else:
            (a, b), (c, d) = inside, outside
            quad = [cross(a, c), cross(a, d), cross(b, d), cross(b, c)]
            triangles += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
    return np.array(triangles)


def zero_contour(points2d, phi):
    """Segments of phi = 0 over the Delaunay triangulation of the points (piecewise linear)."""
    cs = plt.figure().add_subplot().tricontour(mtri.Triangulation(points2d[:, 0], points2d[:, 1]), phi, levels=[0.0])
    segments = [s for s in cs.allsegs[0] if len(s) > 1]
    plt.close()
    return segments


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("octant")
    parser.add_argument("axisymmetric")
    parser.add_argument("--axis", choices=["x", "z"], required=True)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()

    nodes3, phi3, tets3, rec3 = load(args.octant)
    nodes2, phi2, _, rec2 = load(args.axisymmetric)
    e3, e2 = 8 * rec3["energy"], rec2["energy"]
    print(f"energy  3D octant x 8 = {e3:.6f} ({rec3['nodes']} nodes, {rec3['wall_s']:.0f} s)   "
          f"axisymmetric = {e2:.6f} ({rec2['nodes']} nodes, {rec2['wall_s']:.0f} s)   3D - axisymmetric: {100 * (e3 - e2) / e2:+.3f} %")

    along = {"x": 0, "z": 2}[args.axis]
    # The two mirror planes that contain the axis, each as (along, across) coordinates.
    planes = [(along, c) for c in range(3) if c != along]
    meridian = zero_contour(nodes2, phi2)  # (r, z)

    fig = plt.figure(figsize=(11, 5))
    ax = fig.add_subplot(1, 2, 1)
    for seg in meridian:
        for sr in (1, -1):
            for sz in (1, -1):
                ax.plot(sz * seg[:, 1], sr * seg[:, 0], color="k", lw=2.5, alpha=0.35,
                        label="axisymmetric" if (sr, sz) == (1, 1) and seg is meridian[0] else None)
    r_axi = max(np.abs(s[:, 0]).max() for s in meridian)
    z_axi = max(np.abs(s[:, 1]).max() for s in meridian)
    print(f"axisymmetric membrane: {z_axi:.4f} along the axis, {r_axi:.4f} across")
    styles = ["tab:red", "tab:blue"]
    for (a, c), color in zip(planes, styles):
        normal = 3 - a - c
        on_plane = np.abs(nodes3[:, normal]) < 1e-12
        segs = zero_contour(nodes3[on_plane][:, [a, c]], phi3[on_plane])
        ext_a = max(np.abs(s[:, 0]).max() for s in segs)
        ext_c = max(np.abs(s[:, 1]).max() for s in segs)
        name = "xyz"[normal]
        print(f"3D membrane in the plane {name} = 0: {ext_a:.4f} along the axis, {ext_c:.4f} across")
        # The plane z = 0 (or y = 0) is drawn in the upper (lower) half, mirrored along the axis.
        sign = 1 if color == styles[0] else -1
        for i, seg in enumerate(segs):
            for s_along in (1, -1):
                ax.plot(s_along * seg[:, 0], sign * seg[:, 1], color=color, lw=1.2,
                        label=f"3D octant, plane {name} = 0" if i == 0 and s_along == 1 else None)
    ax.set_aspect("equal")
    ax.set_xlabel(f"{args.axis} (3D) = z (axisymmetric)")
    ax.set_ylabel("across the axis")
    ax.set_title(f"E(3D) = {e3:.4f}, E(axisymmetric) = {e2:.4f} ({100 * (e3 - e2) / e2:+.2f} %)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.32), fontsize=8, ncol=3)

    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    octant = zero_surface(nodes3, phi3, tets3)
    whole = np.concatenate([octant * np.array([sx, sy, sz]) for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)])
    view = fig.add_subplot(1, 2, 2, projection="3d")
    normals = np.cross(whole[:, 1] - whole[:, 0], whole[:, 2] - whole[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    light = np.array([-0.4, -0.6, 0.7]) / np.linalg.norm([-0.4, -0.6, 0.7])
    brightness = 0.35 + 0.65 * np.abs(normals @ light)
    colors = np.outer(brightness, matplotlib.colors.to_rgb("tab:orange"))
    view.add_collection3d(Poly3DCollection(whole, facecolors=colors, edgecolor="none"))
    reach = np.abs(whole).max()
    for setter in (view.set_xlim, view.set_ylim, view.set_zlim):
        setter(-reach, reach)
    view.set_box_aspect((1, 1, 1))
    view.view_init(elev=25, azim=-60)
    view.set_title(f"phi = 0, {len(octant)} triangles per octant")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
