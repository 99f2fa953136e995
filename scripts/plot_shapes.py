#!/usr/bin/env python3
"""Energy against eps for each shape of the family (bench_shapes): one panel per branch, one curve per
reduced volume; the last stage at each eps is plotted (a relocation and the solve that lowers eps share
one eps). A curve that rises as eps falls is marked."""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SHARP = {("oblate", 0.8): 9.12657, ("prolate", 0.8): 8.71756}  # seed Paper A Sec. 4


def main() -> int:
    if len(sys.argv) != 3:
        print("usage: plot_shapes.py shapes.json out.png", file=sys.stderr)
        return 2
    records = [r for r in json.load(open(sys.argv[1])) if "record" not in r]  # stages only, not the extrapolation
    branches = [b for b in ("oblate", "prolate") if any(r["branch"] == b for r in records)]
    fig, axes = plt.subplots(1, len(branches), figsize=(5.2 * len(branches), 4.2), squeeze=False)
    for ax, branch in zip(axes[0], branches):
        for v in sorted({r["v"] for r in records if r["branch"] == branch}):
            rows = [r for r in records if r["branch"] == branch and r["v"] == v]
            last = {}
            for r in rows:
                last[r["eps"]] = r  # the later stage at the same eps (after its relocation)
            eps = sorted(last, reverse=True)
            energy = [last[e]["energy"] for e in eps]
            rising = any(energy[i + 1] > energy[i] for i in range(len(energy) - 1))
            line, = ax.plot(eps, energy, "o-", label=f"v = {v:g}" + (" (rises)" if rising else ""))
            if (branch, v) in SHARP:
                ax.axhline(SHARP[(branch, v)], color=line.get_color(), ls=":", lw=1)
        ax.set_xscale("log")
        ax.invert_xaxis()
        ax.set_xlabel("eps (decreasing)")
        ax.set_ylabel("E / k")
        ax.set_title(f"{branch} starts (dotted: sharp reference)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    tmp = sys.argv[2] + ".tmp.png"
    fig.savefig(tmp, dpi=120)
    os.replace(tmp, sys.argv[2])
    return 0


if __name__ == "__main__":
    sys.exit(main())
