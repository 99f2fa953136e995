#!/usr/bin/env python3
"""The crack path of a load-stepped fracture run: the phase field v (nodal coefficients) at a step,
with the nodes, and the crack's course (per 0.05 of x, the y of the nodes with v < 0.1).
    crack_path.py RUN_DIR STEP OUT.png [--title TEXT]
"""
import pathlib
import sys

import h5py
import numpy as np


def main():
    run, step, out = pathlib.Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    title = sys.argv[sys.argv.index("--title") + 1] if "--title" in sys.argv else run.name
    path = next((run / "series").glob(f"*_{step:06d}.h5"))
    with h5py.File(path, "r") as f:
        x = np.array(f["nodes"])
        v = np.array(f["fields"]["v"]).ravel()
    broken = v < 0.1
    print(f"{path.name}: {len(x)} nodes, {broken.sum()} with v < 0.1")
    for xc in np.arange(0.5, 1.0001, 0.05):
        ys = x[broken & (np.abs(x[:, 0] - xc) < 0.025), 1]
        if ys.size:
            print(f"  x = {xc:.2f}: crack at y = {ys.min():.3f} .. {ys.max():.3f}")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(4.8, 4.4))
    s = ax.tricontourf(x[:, 0], x[:, 1], np.clip(v, 0, 1), levels=np.linspace(0, 1, 21), cmap="inferno")
    ax.plot(x[:, 0], x[:, 1], ",", color="0.6")
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    fig.colorbar(s, ax=ax, label="v")
    fig.tight_layout()
    pathlib.Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
