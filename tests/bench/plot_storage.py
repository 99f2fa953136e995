#!/usr/bin/python3
"""Draws the storage experiment (bench_storage, seed Paper C Sec. 4.2, Fig. 11) into a PNG.

    /usr/bin/python3 tests/bench/plot_storage.py [build/bench/storage.json] [-o docs/figures/storage.png]

Left: stored basis doubles of full and compressed storage against the number of nodes; middle:
memory ratio full / compressed; right: fill-time ratio compressed / full (best wall time of the
Hessian assembly). One series per support cutoff tol0 (mean neighbours per point in the legend);
the seed's ~20x and ~1.1 are drawn as dotted lines.
"""
import argparse
import json
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("json", nargs="?", default="build/bench/storage.json")
    parser.add_argument("-o", "--output", default="docs/figures/storage.png")
    args = parser.parse_args()

    with open(args.json) as f:
        records = json.load(f)
    if isinstance(records, dict):  # tolerate a {"records": [...]} wrapper
        records = records["records"]
    series = defaultdict(list)
    for r in records:
        series[r["tol0"]].append(r)

    fig, (ax_mem, ax_ratio, ax_time) = plt.subplots(1, 3, figsize=(14, 4.2))
    markers = "os^dv<>"
    for k, (tol0, rs) in enumerate(sorted(series.items(), reverse=True)):
        rs.sort(key=lambda r: r["nodes"])
        nodes = [r["nodes"] for r in rs]
        nbar = rs[-1]["mean_neighbours"]
        label = f"tol0 = {tol0:g} (n̄ ≈ {nbar:.0f})"
        m = markers[k % len(markers)]
        ax_mem.loglog(nodes, [r["full_storage_doubles"] for r in rs], m + "-", color=f"C{k}",
                      label=f"full, {label}")
        ax_mem.loglog(nodes, [r["compressed_storage_doubles"] for r in rs], m + "--", color=f"C{k}",
                      mfc="none", label="compressed (every tol0: 21 per point)" if k == 0 else None)
        ax_ratio.semilogx(nodes, [r["memory_ratio"] for r in rs], m + "-", color=f"C{k}", label=label)
        ax_time.semilogx(nodes, [r["time_ratio"] for r in rs], m + "-", color=f"C{k}", label=f"{label}, wall")
        if "time_ratio_cpu" in rs[0]:
            ax_time.semilogx(nodes, [r["time_ratio_cpu"] for r in rs], m + ":", color=f"C{k}", mfc="none",
                             label="CPU time" if k == 0 else None)

    ax_mem.set_xlabel("nodes")
    ax_mem.set_ylabel("stored basis doubles")
    ax_mem.set_title("basis storage")
    ax_mem.legend(fontsize=8)
    ax_ratio.axhline(20, color="gray", ls=":", label="seed: ~20 (n̄ = 72)")
    ax_ratio.set_ylim(0, 25)
    ax_ratio.set_xlabel("nodes")
    ax_ratio.set_ylabel("full / compressed doubles")
    ax_ratio.set_title("memory ratio")
    ax_ratio.legend(fontsize=8)
    ax_time.axhline(1.1, color="gray", ls=":", label="seed: ~1.1")
    ax_time.axhline(1.0, color="black", lw=0.5)
    ax_time.set_ylim(0.8, 1.5)
    ax_time.set_xlabel("nodes")
    ax_time.set_ylabel("compressed / full fill time")
    ax_time.set_title("Hessian fill time ratio")
    ax_time.legend(fontsize=8)
    r0 = records[0]
    fig.suptitle(f"Full vs compressed LME basis storage: fourth-order fracture Hessian, 2D, γ = {r0['gamma']:g}, "
                 f"{r0['gauss_points_per_cell']} Gauss points per cell, l0 = 2h (seed Paper C §4.2)", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.output, dpi=120)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
