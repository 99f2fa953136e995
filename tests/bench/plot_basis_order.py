#!/usr/bin/python3
"""Draws bench_basis_approximation and bench_plate_convergence (docs/lme_basis.md, docs/convergence.md).

    /usr/bin/python3 tests/bench/plot_basis_order.py [build/bench] [-o docs/figures]

Writes, from DIR/basis_approximation.json and DIR/basis_order.json:
  lme_order_hessian.png  Hessian error of sum p_a c_a for the generic test function against h,
                         interior and near the hull, uniform / jittered / graded nodes, both bases;
  lme_order_floor.png    first-order basis: the Hessian error, the second-moment floor P and the
                         remainder H - P against h (the floor is the error, the remainder converges);
  lme_order_plate.png    the manufactured Kirchhoff plate: L2, H1 and H2 errors of w_h against h;
  lme_order_cost.png     its L2 and H2 errors against the number of nodes and the wall time.
"""
import argparse
import json
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STYLE = {  # (basis, gamma) -> colour, marker
    ("first", 0.5): ("tab:orange", "o"),
    ("first", 0.8): ("tab:red", "s"),
    ("first", 1.8): ("tab:brown", "^"),
    ("second", 0.5): ("tab:blue", "o"),
    ("second", 0.8): ("tab:green", "s"),
}


def records(path, section=None):
    with open(path) as f:
        data = json.load(f)
    rs = data["records"] if isinstance(data, dict) else data
    return [r for r in rs if section is None or r.get("section") == section]


def slope_guide(ax, hs, e0, order, label):
    ax.plot(hs, [e0 * (h / hs[0]) ** order for h in hs], "k:", lw=0.8)
    ax.annotate(label, (hs[-1], e0 * (hs[-1] / hs[0]) ** order), fontsize=7)


def plot_hessian(rs, out):
    fig, axes = plt.subplots(3, 2, figsize=(10, 11), sharex=True)
    for row, nodes in enumerate(["uniform", "jittered", "graded"]):
        for col, region in enumerate(["interior", "hull"]):
            ax = axes[row][col]
            for (basis, gamma), (colour, marker) in STYLE.items():
                sel = [r for r in rs if r.get("nodes") == nodes and r.get("region") == region and r.get("basis") == basis
                       and r.get("gamma") == gamma and r.get("function") == "generic" and "err_hess" in r]
                sel.sort(key=lambda r: -r["h"])
                if not sel:
                    continue
                ax.loglog([r["h"] for r in sel], [r["err_hess"] for r in sel], marker=marker, color=colour,
                          ls="-" if basis == "second" else "--", label="%s order, $\\gamma$ = %g" % (basis, gamma))
            hs = sorted({r["h"] for r in rs if "h" in r}, reverse=True)
            slope_guide(ax, hs, 0.3, 1, "h")
            ax.set_title("%s nodes, %s" % (nodes, "interior" if region == "interior" else "0.02 h .. h from the hull"))
            ax.grid(True, which="both", alpha=0.3)
            if col == 0:
                ax.set_ylabel("max |H f_h - H f| / max |H f|")
            if row == 2:
                ax.set_xlabel("h")
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Hessian of the approximation of a smooth f (first order: c_a = f(x_a); second: gap-corrected)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lme_order_hessian.png"), dpi=110)


def plot_floor(rs, out):
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), sharey=True)
    cases = [("uniform", "interior"), ("uniform", "hull"), ("jittered", "interior")]
    for ax, (nodes, region) in zip(axes, cases):
        for gamma, colour in [(0.5, "tab:orange"), (0.8, "tab:red"), (1.8, "tab:brown")]:
            sel = [r for r in rs if r.get("nodes") == nodes and r.get("region") == region and r.get("basis") == "first"
                   and r.get("gamma") == gamma and r.get("function") == "generic" and "err_hess" in r]
            sel.sort(key=lambda r: -r["h"])
            h = [r["h"] for r in sel]
            ax.loglog(h, [r["err_hess"] for r in sel], "o-", color=colour, label="error, $\\gamma$ = %g" % gamma)
            ax.loglog(h, [r["floor"] for r in sel], "x:", color=colour, ms=9, label="floor P")
            ax.loglog(h, [r["remainder"] for r in sel], "v--", color=colour, alpha=0.6, label="remainder H - P")
        ax.set_title("first order, %s nodes, %s" % (nodes, region))
        ax.set_xlabel("h")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("max |.| / max |H f|")
    axes[0].legend(fontsize=7, ncol=1)
    fig.suptitle("P = 1/2 sum_kl (H f)_kl E_kl, E_kl = Hessian error of the approximant of x_k x_l (of J_kl)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lme_order_floor.png"), dpi=110)


def plate_groups(rs):
    def key(r):
        return (r["node_set"], r["basis"], r["gamma"], r["quadrature_points"], r.get("integration", "gauss"))
    for node_set, basis, gamma, qp, integration in sorted({key(r) for r in rs}):
        sel = sorted([r for r in rs if key(r) == (node_set, basis, gamma, qp, integration)], key=lambda r: -r["spacing"])
        colour, marker = STYLE.get((basis, gamma), ("k", "."))
        if node_set != "uniform":
            marker = {6: "s", 12: "D", 19: "P"}.get(qp, marker)
        ls = ("-" if basis == "second" else "--") if node_set == "uniform" else ":"
        if integration == "consistent":
            ls, colour = "-.", {"first": "tab:purple", "second": "k"}[basis]
        style = dict(marker=marker, ls=ls, color=colour, mfc="none" if node_set == "jittered" else colour,
                     label="%s, %s, $\\gamma$ = %g, %d pts%s" % (node_set, basis, gamma, qp,
                                                             ", consistent" if integration == "consistent" else ""))
        yield sel, style


def plot_plate(rs, out):
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for ax, key, name in zip(axes, ["error_l2", "error_h1", "error_h2"], ["L2", "H1 semi-norm", "H2 semi-norm"]):
        for sel, style in plate_groups(rs):
            ax.loglog([r["spacing"] for r in sel], [r[key] for r in sel], **style)
        ax.set_title("plate: %s error of w_h" % name)
        ax.set_xlabel("h")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lme_order_plate.png"), dpi=110)


def plot_cost(rs, out):
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    for row, (key, name) in enumerate([("error_l2", "L2"), ("error_h2", "H2 semi-norm")]):
        for col, (x, xname) in enumerate([("nodes", "nodes"), ("wall_s", "wall time [s] (lmeform run, one core)")]):
            ax = axes[row][col]
            for sel, style in plate_groups(rs):
                ax.loglog([r[x] for r in sel], [r[key] for r in sel], **style)
            ax.set_xlabel(xname)
            ax.set_ylabel("%s error of w_h" % name)
            ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lme_order_cost.png"), dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("dir", nargs="?", default="build/bench")
    parser.add_argument("-o", "--output", default="docs/figures")
    args = parser.parse_args()
    approximation = os.path.join(args.dir, "basis_approximation.json")
    if os.path.exists(approximation):
        convergence = records(approximation, "convergence")
        plot_hessian(convergence, args.output)
        plot_floor(convergence, args.output)
    plate = os.path.join(args.dir, "basis_order.json")
    if os.path.exists(plate):
        plot_plate(records(plate), args.output)
        plot_cost(records(plate), args.output)


if __name__ == "__main__":
    main()
