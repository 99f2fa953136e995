#!/usr/bin/python3
"""Plot an lmeform dynamics run: energy/time-step/constraint history and shape snapshots.

    /usr/bin/python3 scripts/plot_dynamics.py RUN_history.json --out PREFIX
        [--reference-energy E] [--snapshots K] [--mirror]
        [--compare OTHER_history.json ...] [--labels LABEL ...]
        [--max-energy-shapes] [--equilibrium FIELDS.h5]

RUN_history.json is written by `lmeform run` for a dynamics scene; its "series" entries name HDF5
field files relative to the JSON's folder. It writes:

  PREFIX_energy.png     E* against t* (log t*, with --reference-energy as a dashed "static
                        equilibrium" line, --compare runs overlaid), dt* against t* (log-log), and
                        the relative drift |C(t) - C(0)| / |C(0)| of each constraint (floor 1e-17).
  PREFIX_snapshots.png  K series files evenly spaced from first to last (default 4): nodes coloured
                        by phi, the phi = 0 contour in black; --mirror adds the image r -> -r.
  PREFIX_max_energy.png (--max-energy-shapes) each run's shape at its largest energy, and
                        PREFIX_max_energy_contours.png: their phi = 0 contours in one panel, with
                        the static equilibrium's (--equilibrium FIELDS.h5, a static run's output)
                        dashed.
  PREFIX_final_contours.png (--equilibrium without --max-energy-shapes) the first and the last
                        shape of the run with the static equilibrium dashed: where a relaxation
                        ended against the shape it should reach.

--labels names the main run and then each --compare run (default: their "method" fields).
Needs Debian's python3-matplotlib, python3-h5py and numpy (call /usr/bin/python3, not a pyenv one).
"""

import argparse
import json
import os
import sys

STEP_KEYS = ("t_star", "dt_star", "energy", "constraints")


def fail(message):
    print(f"plot_dynamics.py: {message}", file=sys.stderr)
    sys.exit(1)


def load_history(path):
    try:
        with open(path) as f:
            history = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        fail(f"{path}: cannot read: {e}")
    for key in ("method", "constraints", "steps", "series"):
        if key not in history:
            fail(f"{path}: missing key '{key}'")
    for i, step in enumerate(history["steps"]):
        missing = [k for k in STEP_KEYS if k not in step]
        if missing:
            fail(f"{path}: steps[{i}] is missing {', '.join(missing)}")
    for i, entry in enumerate(history["series"]):
        if "file" not in entry:
            fail(f"{path}: series[{i}] is missing 'file'")
    if not history["steps"]:
        fail(f"{path}: no steps recorded")
    return history


def column(history, key):
    import numpy as np
    return np.array([s[key] for s in history["steps"]], dtype=float)


def load_snapshot(path):
    import h5py
    import numpy as np

    if not os.path.isfile(path):
        fail(f"{path}: series file not found")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        fail(f"{path}: cannot open: {e}")
    with f:
        for name in ("nodes", "cells", "fields/phi"):
            if name not in f:
                fail(f"{path}: missing dataset /{name}")
        nodes = np.asarray(f["nodes"][...], dtype=float)
        cells = np.asarray(f["cells"][...], dtype=np.int64)
        phi = np.asarray(f["fields/phi"][...], dtype=float)
        t_star = float(f.attrs["t_star"]) if "t_star" in f.attrs else None
    if nodes.ndim != 2 or nodes.shape[1] != 2 or cells.ndim != 2 or cells.shape[1] != 3:
        fail(f"{path}: expected /nodes N x 2 and /cells M x 3, got {nodes.shape} and {cells.shape}")
    if phi.shape != (nodes.shape[0],):
        fail(f"{path}: /fields/phi is {phi.shape}; expected ({nodes.shape[0]},)")
    return nodes, cells, phi, t_star


def save(fig, path):
    import matplotlib.pyplot as plt

    try:
        fig.savefig(path, dpi=150)
    except OSError as e:
        fail(f"{path}: cannot write: {e}")
    finally:
        plt.close(fig)
    print(path)


def plot_energy(runs, names, reference, path):
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (ax_e, ax_dt, ax_c) = plt.subplots(3, 1, figsize=(7, 9), sharex=True, layout="constrained")
    main = runs[0]
    t = column(main, "t_star")
    pos = t > 0  # log t*: t* = 0 cannot be drawn
    for run, name in zip(runs, names):
        tr = column(run, "t_star")
        ax_e.plot(tr[tr > 0], column(run, "energy")[tr > 0], label=name)
    if reference is not None:
        ax_e.axhline(reference, color="k", linestyle="--", linewidth=1, label="static equilibrium")
    ax_e.set_xscale("log")
    ax_e.set_ylabel("E*")
    ax_e.legend()
    ax_e.set_title(f"{main.get('scene', '')} ({main['method']})")

    dt = column(main, "dt_star")
    ax_dt.loglog(t[pos & (dt > 0)], dt[pos & (dt > 0)])
    ax_dt.set_ylabel("dt*")

    c = np.array([s["constraints"] for s in main["steps"]], dtype=float).reshape(len(t), -1)
    c0 = np.where(c[0] != 0, np.abs(c[0]), 1.0)
    drift = np.maximum(np.abs(c - c[0]) / c0, 1e-17)
    cnames = main["constraints"]
    for j in range(c.shape[1]):
        ax_c.plot(t[pos], drift[pos, j], label=cnames[j] if j < len(cnames) else f"C{j}")
    ax_c.set_yscale("log")
    ax_c.set_ylabel("|C(t) - C(0)| / |C(0)|")
    ax_c.set_xlabel("t*")
    if c.shape[1]:
        ax_c.legend()
    for ax in (ax_e, ax_dt, ax_c):
        ax.grid(True, which="major", alpha=0.3)
    save(fig, path)


def mirrored(nodes, cells, phi):
    """Append the image r -> -r; nodes on the axis are shared by both halves."""
    import numpy as np

    off = np.flatnonzero(nodes[:, 0] != 0.0)
    index = np.arange(len(nodes))
    index[off] = len(nodes) + np.arange(off.size)
    image = nodes[off] * [-1.0, 1.0]
    return (np.vstack([nodes, image]), np.vstack([cells, index[cells][:, ::-1]]),
            np.concatenate([phi, phi[off]]))


def load_snapshots(history, folder, count):
    """The series files evenly spaced in the list, always the first and the last."""
    import numpy as np

    series = history["series"]
    if not series:
        fail("the history lists no series files")
    picks = sorted(set(np.linspace(0, len(series) - 1, max(count, 1)).round().astype(int)))
    return [(series[i].get("time"), load_snapshot(os.path.join(folder, series[i]["file"])))
            for i in picks]


def load_max_energy_snapshots(runs, paths):
    """Per run, the series file nearest in time to the step of largest energy (kinetics)."""
    import numpy as np

    picks = []
    for run, path in zip(runs, paths):
        series = run["series"]
        if not series:
            fail(f"{path}: the history lists no series files")
        t_max = run["steps"][int(np.argmax(column(run, "energy")))]["t_star"]
        entry = min(series, key=lambda e: abs(e["time"] - t_max))
        picks.append((entry["time"], load_snapshot(os.path.join(os.path.dirname(os.path.abspath(path)), entry["file"]))))
    return picks


def plot_snapshots(snapshots, mirror, path, titles=None):
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    import numpy as np

    snaps = [s for _, s in snapshots]
    nodes = snaps[0][0]
    extent = np.ptp(nodes, axis=0) * [2.0 if mirror else 1.0, 1.0]
    panel = float(np.clip(2.9 * extent[0] / max(extent[1], 1e-12), 1.5, 6.0))
    fig, axes = plt.subplots(1, len(snaps), figsize=(panel * len(snaps) + 1.0, 4.2), sharey=True,
                             squeeze=False, layout="constrained")
    fig.get_layout_engine().set(wspace=0.06)  # keep neighbouring r tick labels apart
    for ax, (time, (nodes, cells, phi, t_star)) in zip(axes[0], snapshots):
        if mirror:
            nodes, cells, phi = mirrored(nodes, cells, phi)
        r, z = nodes[:, 0], nodes[:, 1]
        sc = ax.scatter(r, z, c=phi, s=1.5, cmap="coolwarm", vmin=-1, vmax=1, linewidths=0,
                        rasterized=True)
        if phi.min() < 0.0 < phi.max():
            ax.tricontour(mtri.Triangulation(r, z, cells), phi, levels=[0.0], colors="k",
                          linewidths=1.2)
        ax.set_aspect("equal")
        ax.set_xlabel("r")
        t = t_star if t_star is not None else time
        title = f"t* = {t:.4g}" if t is not None else "t* = ?"
        if titles:
            title = f"{titles[list(axes[0]).index(ax)]}\n{title}"
        ax.set_title(title)
    axes[0][0].set_ylabel("z")
    fig.colorbar(sc, cax=axes[0][-1].inset_axes([1.04, 0.0, 0.04, 1.0]), label="phi")
    save(fig, path)


def print_axisymmetric_profile(name, nodes, cells, phi):
    """Prints the measures of an axisymmetric shape's phi = 0 contour that tell an oblate from a
    discocyte: the equatorial radius, the thickness on the axis and the largest thickness."""
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    import numpy as np

    cs = plt.tricontour(mtri.Triangulation(nodes[:, 0], nodes[:, 1], cells), phi, levels=[0.0])
    points = np.vstack([seg for seg in cs.allsegs[0] if len(seg)])
    plt.close()
    r, z = points[:, 0], points[:, 1]
    r_eq = r.max()
    edges = np.linspace(0.0, r_eq, 41)
    slab = np.digitize(r, edges) - 1
    thickness = np.array([np.ptp(z[slab == k]) if np.any(slab == k) else 0.0 for k in range(40)])
    k = int(np.argmax(thickness))
    print(f"{name}: equator r {r_eq:.4f}, thickness on the axis {thickness[0]:.4f}, "
          f"largest thickness {thickness[k]:.4f} at r {0.5 * (edges[k] + edges[k + 1]):.3f}")
    return points


def plot_contours(shapes, names, mirror, path, reference=None):
    """The phi = 0 contours of several shapes in one panel (kinetics: the shapes at the energy
    maxima), with a reference shape (the static equilibrium) dashed; shapes are (nodes, cells, phi)."""
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    import numpy as np
    from matplotlib.lines import Line2D

    fig, ax = plt.subplots(figsize=(6.0, 4.2), layout="constrained")
    curves = [(shape, name, f"C{i}", "-") for i, (shape, name) in enumerate(zip(shapes, names))]
    if reference is not None:
        curves.append((reference, "static equilibrium", "k", "--"))
    handles = []
    bounds = []
    for (nodes, cells, phi), name, color, style in curves:
        if not phi.min() < 0.0 < phi.max():
            fail(f"{name}: phi does not change sign, no interface to draw")
        points = print_axisymmetric_profile(name, nodes, cells, phi)
        bounds.append((points.min(axis=0), points.max(axis=0)))
        if mirror:
            nodes, cells, phi = mirrored(nodes, cells, phi)
        ax.tricontour(mtri.Triangulation(nodes[:, 0], nodes[:, 1], cells), phi, levels=[0.0],
                      colors=color, linestyles=style, linewidths=1.4)
        handles.append(Line2D([], [], color=color, linestyle=style, label=name))
    low = np.min([b[0] for b in bounds], axis=0)
    high = np.max([b[1] for b in bounds], axis=0)
    margin = 0.15 * (high - low).max()
    ax.set_xlim(-high[0] - margin if mirror else 0.0, high[0] + margin)
    ax.set_ylim(low[1] - margin, high[1] + 2.5 * margin)  # room for the legend above the shapes
    ax.set_aspect("equal")
    ax.set_xlabel("r")
    ax.set_ylabel("z")
    ax.legend(handles=handles, fontsize=8, loc="upper center", ncol=2)
    ax.grid(True, alpha=0.3)
    save(fig, path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("history", help="<name>_history.json written by lmeform run")
    parser.add_argument("--out", required=True, help="output prefix: PREFIX_energy.png, PREFIX_snapshots.png")
    parser.add_argument("--reference-energy", type=float, default=None,
                        help="static equilibrium energy, drawn as a horizontal line")
    parser.add_argument("--snapshots", type=int, default=4, help="number of shape panels (default 4)")
    parser.add_argument("--mirror", action="store_true", help="also draw the image r -> -r")
    parser.add_argument("--compare", nargs="+", default=[], metavar="HISTORY",
                        help="further history files whose energy curves are overlaid")
    parser.add_argument("--max-energy-shapes", action="store_true",
                        help="also PREFIX_max_energy.png: each run's shape at its largest energy")
    parser.add_argument("--equilibrium", default=None, metavar="FIELDS.h5",
                        help="a static run's fields, drawn dashed in a contour panel: with --max-energy-shapes "
                             "PREFIX_max_energy_contours.png, else PREFIX_final_contours.png (the first and the last "
                             "shape of the run)")
    parser.add_argument("--labels", nargs="+", default=None,
                        help="curve labels: the main run, then each --compare run")
    args = parser.parse_args()

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot  # noqa: F401
        import numpy  # noqa: F401
        import h5py  # noqa: F401
    except ImportError as e:
        fail(f"{e}; run with Debian's /usr/bin/python3 (python3-matplotlib, python3-h5py)")

    runs = [load_history(p) for p in [args.history] + args.compare]
    names = [r["method"] for r in runs]
    if args.labels:
        if len(args.labels) != len(runs):
            fail(f"--labels gives {len(args.labels)} names for {len(runs)} runs")
        names = args.labels

    # Everything is read before anything is written: a missing series file leaves no half output.
    snapshots = load_snapshots(runs[0], os.path.dirname(os.path.abspath(args.history)),
                               args.snapshots)
    peaks = load_max_energy_snapshots(runs, [args.history] + args.compare) if args.max_energy_shapes else None
    equilibrium = load_snapshot(args.equilibrium)[:3] if args.equilibrium else None
    # Where a relaxation began and ended, against the static shape it should reach.
    ends = load_snapshots(runs[0], os.path.dirname(os.path.abspath(args.history)), 2) if equilibrium is not None and not peaks else None
    folder = os.path.dirname(args.out)
    if folder:
        os.makedirs(folder, exist_ok=True)
    plot_energy(runs, names, args.reference_energy, args.out + "_energy.png")
    plot_snapshots(snapshots, args.mirror, args.out + "_snapshots.png")
    if peaks:
        plot_snapshots(peaks, args.mirror, args.out + "_max_energy.png", titles=names)
        shapes = [snapshot[:3] for _, snapshot in peaks]
        labels = [f"{name}, t* = {time:.3g}" for name, (time, _) in zip(names, peaks)]
        plot_contours(shapes, labels, args.mirror, args.out + "_max_energy_contours.png", reference=equilibrium)
    elif ends:
        plot_contours([snapshot[:3] for _, snapshot in ends], [f"t* = {time:.3g}" for time, _ in ends], args.mirror,
                      args.out + "_final_contours.png", reference=equilibrium)


if __name__ == "__main__":
    main()
