#!/usr/bin/env python3
"""Convergence and sensitivity plots of bench_stokes (BUILD/bench/stokes.json).

    plot_convergence.py STOKES.json OUT_DIR

Writes OUT_DIR/stokes_convergence.png (errors against the mean spacing for every problem, node set
and stabilization at gamma = 1, C = 0.1), OUT_DIR/stokes_sensitivity.png (GLS errors against C on
one grid, and against the spacing for gamma = 0.8, 1.0, 1.6) and prints markdown tables with rates.
"""
import json
import math
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

PROBLEMS = ("colliding_flow", "poiseuille", "manufactured")
STABILIZATIONS = ("none", "gls", "supg", "douglas_wang")
NORMS = (("error_u_l2", "u, L2"), ("error_u_h1", "u, H1 semi-norm"), ("error_p_l2", "p, L2"))
STYLE = {"none": "k:", "gls": "o-", "supg": "s--", "douglas_wang": "^-."}


def spacing(r):
    side = 2.0 if r["problem"] == "colliding_flow" else 1.0
    return side / (math.sqrt(r["nodes"]) - 1)


def ladders(records):
    """(problem, node_set, stabilization, gamma) -> records of C = 0.1 (or 0 for none), by nodes."""
    out = defaultdict(dict)
    for r in records:
        if r["stabilization"] != "none" and abs(r["C"] - 0.1) > 1e-12:
            continue
        out[(r["problem"], r["node_set"], r["stabilization"], r["gamma"])][r["nodes"]] = r
    return {k: [v[n] for n in sorted(v)] for k, v in out.items()}


def rate(a, b, key):
    return math.log(b[key] / a[key]) / math.log(spacing(b) / spacing(a))


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    records = json.load(open(sys.argv[1]))
    out = sys.argv[2]
    lad = ladders(records)

    fig, axes = plt.subplots(len(PROBLEMS), len(NORMS), figsize=(14, 11))
    for i, pb in enumerate(PROBLEMS):
        for j, (key, label) in enumerate(NORMS):
            ax = axes[i, j]
            for st in STABILIZATIONS:
                for node_set, color in (("uniform", "C0"), ("graded", "C3")):
                    l = lad.get((pb, node_set, st, 1.0))
                    if not l:
                        continue
                    ax.loglog([spacing(r) for r in l], [r[key] for r in l], STYLE[st], color=color,
                              label=f"{st}, {node_set}", ms=4)
            ax.set_title(f"{pb}: {label}")
            ax.set_xlabel("mean spacing h")
            ax.grid(True, which="both", alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(f"{out}/stokes_convergence.png", dpi=100)

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    ax = axes[0]
    for pb in PROBLEMS:
        cs = sorted((r for r in records if r["problem"] == pb and r["stabilization"] == "gls"
                     and r["node_set"] == "uniform" and r["gamma"] == 1.0), key=lambda r: (r["nodes"], r["C"]))
        if not cs:
            continue
        n = max(set(r["nodes"] for r in cs), key=lambda n: sum(1 for r in cs if r["nodes"] == n))
        cs = [r for r in cs if r["nodes"] == n]
        ax.loglog([r["C"] for r in cs], [r["error_p_l2"] for r in cs], "o-", label=f"{pb} p L2 ({n} nodes)")
        ax.loglog([r["C"] for r in cs], [r["error_u_l2"] for r in cs], "s--", label=f"{pb} u L2")
    ax.set_xlabel("C in tau = C rho^2 / nu")
    ax.set_title("GLS: sensitivity to C")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax = axes[1]
    for pb in PROBLEMS:
        for gamma, style in ((0.8, "v-"), (1.0, "o-"), (1.6, "^-")):
            l = lad.get((pb, "uniform", "gls", gamma))
            if l:
                ax.loglog([spacing(r) for r in l], [r["error_p_l2"] for r in l], style, label=f"{pb}, gamma {gamma}")
    ax.set_xlabel("h")
    ax.set_title("GLS: pressure L2 error for gamma = 0.8, 1.0, 1.6")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(f"{out}/stokes_sensitivity.png", dpi=100)

    for pb in PROBLEMS:
        print(f"\n#### {pb}\n")
        print("| node set | stabilization | nodes | unknowns | u L2 | rate | u H1 | rate | p L2 | rate | assembly s | solve s |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for node_set in ("uniform", "graded"):
            for st in STABILIZATIONS:
                l = lad.get((pb, node_set, st, 1.0), [])
                for k, r in enumerate(l):
                    rates = ["" if k == 0 else f"{rate(l[k - 1], r, key):.2f}" for key, _ in NORMS]
                    print(f"| {node_set} | {st} | {r['nodes']} | {r['unknowns']} | {r['error_u_l2']:.3e} | {rates[0]} | "
                          f"{r['error_u_h1']:.3e} | {rates[1]} | {r['error_p_l2']:.3e} | {rates[2]} | "
                          f"{r['assembly_s']:.2f} | {r['solve_s']:.2f} |")
    print("\n#### GLS sensitivity to C (uniform)\n")
    print("| problem | nodes | C | u L2 | u H1 | p L2 |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in records:
        if r["stabilization"] == "gls" and r["gamma"] == 1.0 and r["node_set"] == "uniform" and abs(r["C"] - 0.1) > 1e-12:
            print(f"| {r['problem']} | {r['nodes']} | {r['C']} | {r['error_u_l2']:.3e} | {r['error_u_h1']:.3e} | {r['error_p_l2']:.3e} |")
    print("\n#### GLS sensitivity to gamma (uniform, C = 0.1)\n")
    print("| problem | gamma | nodes | u L2 | rate | p L2 | rate |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for pb in PROBLEMS:
        for gamma in (0.8, 1.0, 1.6):
            l = lad.get((pb, "uniform", "gls", gamma), [])
            for k, r in enumerate(l):
                ru = "" if k == 0 else f"{rate(l[k - 1], r, 'error_u_l2'):.2f}"
                rp = "" if k == 0 else f"{rate(l[k - 1], r, 'error_p_l2'):.2f}"
                print(f"| {pb} | {gamma} | {r['nodes']} | {r['error_u_l2']:.3e} | {ru} | {r['error_p_l2']:.3e} | {rp} |")


if __name__ == "__main__":
    main()
