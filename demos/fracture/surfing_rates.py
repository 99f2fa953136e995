#!/usr/bin/python3
"""The surfing runs' dissipation per unit of load advance, step by step, against the effective
toughness Gc (1 + h/(2l)) of AT2 on linear elements (docs/fracture.md, "Against linear elements").

    surfing_rates.py OUT.png LABEL=RUN[:H] ...

The slope is fitted over a window of 6 steps (a crack on linear elements advances cell by cell).
RUN is an lmeform output folder (its history.csv) or a fenicsx_surfing.py JSON; H the band's
spacing (default 0.01), which sets the dashed line 1 + H/(2l) drawn in the run's colour.
Gc = 1, l = 0.02 (the surfing scenes').
"""
import csv
import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

L = 0.02
WINDOW = 6


def series(run):
    path = pathlib.Path(run)
    if path.suffix == ".json":
        steps = json.loads(path.read_text())["steps"]
        return np.array([s["xt"] for s in steps]), np.array([s["dissipated"] for s in steps])
    rows = list(csv.DictReader(open(path / "history.csv")))
    return np.array([float(r["xt"]) for r in rows]), np.array([float(r["dissipated"]) for r in rows])


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for k, spec in enumerate(sys.argv[2:]):
        label, _, rest = spec.rpartition("=")
        run, _, h = rest.partition(":")
        h = float(h) if h else 0.01
        xt, dissipated = series(run)
        # A crack on linear elements advances cell by cell: the slope over a window of WINDOW steps.
        ends = range(WINDOW, len(xt))
        rate = [np.polyfit(xt[e - WINDOW:e + 1], dissipated[e - WINDOW:e + 1], 1)[0] for e in ends]
        centre = [0.5 * (xt[e - WINDOW] + xt[e]) for e in ends]
        colour = f"C{k}"
        ax.plot(centre, rate, "o-", ms=3, color=colour, label=label)
        ax.axhline(1 + h / (2 * L), color=colour, ls="--", lw=0.8)
    ax.set_xlabel("load position xt")
    ax.set_ylabel("dissipation per unit advance / Gc")
    ax.set_ylim(1.0, 1.45)
    ax.set_title(f"surfing: d(E_s)/d(xt) fitted over {WINDOW} steps (at their centre); dashed: Gc (1 + h/(2l))", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(sys.argv[1], dpi=130)
    print(sys.argv[1])


if __name__ == "__main__":
    main()
