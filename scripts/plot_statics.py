#!/usr/bin/env python3
"""Relative energy error against wall time for the discocyte ladder (bench_statics): uniform vs adapted."""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main() -> int:
    if len(sys.argv) != 3:
        print("usage: plot_statics.py statics.json out.png", file=sys.stderr)
        return 2
    records = json.load(open(sys.argv[1]))
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for grid, marker in (("uniform", "o-"), ("adapted", "s--")):
        rows = [r for r in records if r["grid"] == grid]
        if not rows:
            continue
        nodes = sorted({r["nodes"] for r in rows})
        label = f"{grid} ({', '.join(str(n) for n in nodes)} nodes)" if grid == "adapted" else grid
        ax.plot([r["wall_s"] for r in rows], [100 * abs(r["relative_error_sharp"]) for r in rows], marker, label=label)
        # One label per eps (an adapted stage that relocates and the next that lowers eps share one).
        for i, r in enumerate(rows):
            if i + 1 < len(rows) and rows[i + 1]["eps"] == r["eps"]:
                continue
            text = f"eps {r['eps']:g}" + (f", {r['nodes']} nodes" if grid == "uniform" else "")
            ax.annotate(text, (r["wall_s"], 100 * abs(r["relative_error_sharp"])), textcoords="offset points",
                        xytext=(6, -10 if grid == "adapted" else 5), fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("|E - E_sharp| / E_sharp [%]")
    ax.set_title("Discocyte: error against the sharp-interface energy vs time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    tmp = sys.argv[2] + ".tmp.png"
    fig.savefig(tmp, dpi=120)
    os.replace(tmp, sys.argv[2])
    return 0


if __name__ == "__main__":
    sys.exit(main())
