#!/usr/bin/python3
"""Figures and tables of docs/flexoelectricity.md from bench_flexo's records and the pyramid demos.

    /usr/bin/python3 demos/flexoelectric/plot_flexo.py BENCH_DIR FIGURE_DIR [--fields DEMO_DIR]

BENCH_DIR holds flexo.json and flexo_midlines.json (bench_flexo --out BENCH_DIR); FIGURE_DIR gets
flexo_cantilever.png (Y' and Y' - 1 against h'), flexo_midlines.png, flexo_pyramid.png (e'
against h'), flexo_convergence.png (Y' and e' on the node ladders, solve time against unknowns)
and, with --fields (the output folder of `lmeform run demos/flexoelectric/pyramid_*.toml`, default
build/demo/flexoelectric), flexo_pyramid_fields.png (potential and eps_22: the one-dimensional
model, the flexible and the rigid support). The markdown tables go to standard output.
Needs Debian's python3-matplotlib, python3-h5py and numpy (/usr/bin/python3).
"""

import argparse
import json
import math
import os
import sys

NU = 0.37                  # the demos' Poisson ratio
A1, A2, H = 1.0, 2.0, 1.0  # the pyramid's top and bottom widths, its height
FORCE = 1e-3               # the pyramid's load (t = -1e-3 over a1 = 1)


def load(bench):
    with open(os.path.join(bench, "flexo.json")) as f:
        records = json.load(f)
    with open(os.path.join(bench, "flexo_midlines.json")) as f:
        midlines = json.load(f)
    return records, midlines


def series(records, case, key, setting):
    rows = [r for r in records if r["case"] == case and r.get(key) == setting]
    return sorted(rows, key=lambda r: (r["h_prime"], -r["spacing"]))


def slope(rows, quantity=lambda r: r["value"] - 1):
    """Log-log slope between the two largest h'."""
    if len(rows) < 2:
        return float("nan")
    a, b = rows[-2], rows[-1]
    qa, qb = quantity(a), quantity(b)
    if qa <= 0 or qb <= 0:
        return float("nan")
    return math.log(qb / qa) / math.log(b["h_prime"] / a["h_prime"])


def cantilever_figure(records, out):
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    styles = {"closed": ("C0", "o", "closed circuit (both faces grounded)"),
              "floating": ("C1", "s", "floating top electrode, bottom grounded"),
              "open": ("C2", "^", "open circuit, no electrodes")}
    for circuit, (color, marker, label) in styles.items():
        rows = series(records, "cantilever", "circuit", circuit)
        if not rows:
            continue
        h = [r["h_prime"] for r in rows]
        left.semilogx(h, [r["value"] for r in rows], marker=marker, color=color, label=label)
        right.loglog(h, [abs(r["value"] - 1) for r in rows], marker=marker, color=color, label=label)
    rows = series(records, "cantilever", "circuit", "open")
    if rows:
        h = [r["h_prime"] for r in rows]
        left.semilogx(h, [r["reference"] for r in rows], "k--", label="Euler-Bernoulli, open circuit")
        right.loglog(h, [r["reference"] - 1 for r in rows], "k--", label="Euler-Bernoulli, open circuit")
    left.set_xlabel("h' = h / l")
    left.set_ylabel("Y' (Eq. 5.17)")
    left.set_ylim(0.95, max(2.0, max(r["value"] for r in records if r["case"] == "cantilever") * 1.05))
    left.axhline(1.0, color="0.6", lw=0.8)
    left.legend(fontsize=8)
    right.set_xlabel("h' = h / l")
    right.set_ylabel("|Y' - 1|")
    right.legend(fontsize=8)
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle("Flexoelectric cantilever, L/h = 20, plane strain, nu = 0.37, mu_L = mu_T, mu_S = 0")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "flexo_cantilever.png"), dpi=120)
    plt.close(fig)


def midlines_figure(midlines, out):
    import matplotlib.pyplot as plt

    sizes = sorted({m["h_prime"] for m in midlines})
    fig, axes = plt.subplots(2, len(sizes), figsize=(5.5 * len(sizes), 7), squeeze=False)
    for col, size in enumerate(sizes):
        top, bottom = axes[0][col], axes[1][col]
        drawn_elastic = False
        for m in midlines:
            if m["h_prime"] != size:
                continue
            if not drawn_elastic:
                top.plot(m["x"], m["deflection_elastic"], "k-", lw=2, label="without flexoelectricity")
                drawn_elastic = True
            top.plot(m["x"], m["deflection"], "--", marker=".", label=f"with, {m['circuit']}")
            bottom.plot(m["x"], [f - e for f, e in zip(m["deflection"], m["deflection_elastic"])], marker=".", label=m["circuit"])
        top.set_title(f"h' = {size:g}")
        top.set_ylabel("midline deflection u_y(x, 0) / h")
        bottom.set_ylabel("with minus without flexoelectricity")
        bottom.set_xlabel("x / h")
        for ax in (top, bottom):
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8)
    fig.suptitle("Deformed midlines under the same tip load (L/h = 20)")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "flexo_midlines.png"), dpi=120)
    plt.close(fig)


def pyramid_figure(records, out):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    for support, color in (("rigid", "C0"), ("flexible", "C1")):
        rows = series(records, "pyramid", "support", support)
        if rows:
            ax.loglog([r["h_prime"] for r in rows], [r["value"] for r in rows], marker="o", color=color, label=f"{support} support")
    rows = series(records, "pyramid", "support", "rigid")
    if rows:
        ax.loglog([r["h_prime"] for r in rows], [r["reference"] for r in rows], "k--", label="one-dimensional model")
    ax.set_xlabel("h' = h / l")
    ax.set_ylabel("e' = e_eff / sqrt(kappa E)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Truncated pyramid (a1 = h, a2 = 2h), floating bottom electrode")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "flexo_pyramid.png"), dpi=120)
    plt.close(fig)


def convergence_figure(records, out):
    import matplotlib.pyplot as plt

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4))
    for ax, support_key, setting, label in ((a, "circuit", "open", "Y', open-circuit beam, h' = 4"),
                                            (b, "support", "rigid", "e', rigid pyramid, h' = 2")):
        rows = sorted([r for r in records if r["case"] == "convergence" and r.get(support_key) == setting], key=lambda r: r["nodes"])
        if rows:
            ax.semilogx([r["nodes"] for r in rows], [r["value"] for r in rows], marker="o")
        ax.set_xlabel("nodes")
        ax.set_title(label)
        ax.grid(True, which="both", alpha=0.3)
    for case, marker in (("cantilever", "o"), ("pyramid", "s"), ("convergence", "^")):
        rows = [r for r in records if r["case"] == case]
        if rows:
            c.loglog([r["unknowns"] for r in rows], [r["solve_s"] for r in rows], marker, label=case, alpha=0.7)
    c.set_xlabel("unknowns (3 per node)")
    c.set_ylabel("solve s (assembly + MUMPS LDL^T)")
    c.grid(True, which="both", alpha=0.3)
    c.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "flexo_convergence.png"), dpi=120)
    plt.close(fig)


def one_dimensional_fields(x, y, h_prime):
    """The 1D model's potential and eps_22 at (x, y) of the trapezoid."""
    import numpy as np

    mu_eff = (1.0 / h_prime) * (1 - NU / (1 - NU))
    c = 1.0 / (1 - NU * NU)                           # E / (1 - nu^2), E = 1
    width = A2 - (A2 - A1) * y / H
    eps = -FORCE / (c * width)
    eps_top, eps_bottom = -FORCE / (c * A1), -FORCE / (c * A2)
    phi = mu_eff * (eps - eps_top)                    # D_y = 0, phi(h) = 0 (kappa = 1)
    del x, eps_bottom
    return np.asarray(phi), np.asarray(eps)


def fields_figure(demo, out):
    import h5py
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    import numpy as np

    panels = []
    for support in ("flexible", "rigid"):
        path = os.path.join(demo, f"pyramid_{support}", f"flexo_pyramid_{support}.h5")
        if not os.path.exists(path):
            print(f"plot_flexo.py: {path} missing: run build/lmeform run demos/flexoelectric/pyramid_{support}.toml", file=sys.stderr)
            return
        with h5py.File(path, "r") as f:
            nodes = np.asarray(f["nodes"][...])
            cells = np.asarray(f["cells"][...])
            phi = np.asarray(f["fields/potential"][...]).reshape(-1)
            eps22 = np.asarray(f["fields/strain_field"][...])[:, 3]
        panels.append((f"{support} support", nodes, cells, phi, eps22))
    nodes, cells = panels[0][1], panels[0][2]
    phi1, eps1 = one_dimensional_fields(nodes[:, 0], nodes[:, 1], 2.0)
    panels.insert(0, ("one-dimensional model", nodes, cells, phi1, eps1))
    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5))
    for col, (title, nodes, cells, phi, eps22) in enumerate(panels):
        tri = mtri.Triangulation(nodes[:, 0], nodes[:, 1], cells)
        for row, (values, name) in enumerate(((phi, "potential"), (eps22, "eps_22"))):
            ax = axes[row][col]
            m = ax.tricontourf(tri, values, levels=24, cmap="viridis")
            fig.colorbar(m, ax=ax, shrink=0.8, format="%.1e")
            ax.set_aspect("equal")
            ax.set_title(f"{title}: {name}", fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle("Truncated pyramid, h' = 2, F on the top face, top grounded, bottom a floating electrode")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "flexo_pyramid_fields.png"), dpi=120)
    plt.close(fig)


def tables(records):
    def fmt(v, spec=".6g"):
        return "—" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)

    print("### Cantilever: Y' against h'\n")
    circuits = [c for c in ("closed", "floating", "open") if series(records, "cantilever", "circuit", c)]
    sizes = sorted({r["h_prime"] for r in records if r["case"] == "cantilever"})
    print("| h' | " + " | ".join(f"Y' {c}" for c in circuits) + " | Euler-Bernoulli (open) |")
    print("|---:|" + "---:|" * (len(circuits) + 1))
    for h in sizes:
        cells = []
        reference = None
        for c in circuits:
            row = [r for r in series(records, "cantilever", "circuit", c) if r["h_prime"] == h]
            cells.append(fmt(row[0]["value"], ".6f") if row else "—")
            if c == "open" and row:
                reference = row[0]["reference"]
        print(f"| {h:g} | " + " | ".join(cells) + f" | {fmt(reference, '.6f')} |")
    for c in circuits:
        rows = series(records, "cantilever", "circuit", c)
        print(f"\nlog-log slope of |Y' - 1| between h' = {rows[-2]['h_prime']:g} and {rows[-1]['h_prime']:g}, {c}: "
              f"{slope(rows, lambda r: abs(r['value'] - 1)):.3f}")
    rows = series(records, "cantilever", "circuit", "open")
    if rows:
        print(f"Euler-Bernoulli (open) between the same sizes: {slope(rows, lambda r: r['reference'] - 1):.3f}")

    print("\n### Pyramid: e' against h'\n")
    sizes = sorted({r["h_prime"] for r in records if r["case"] == "pyramid"})
    print("| h' | e' rigid | e' flexible | one-dimensional model | rigid / model | flexible / model |")
    print("|---:|---:|---:|---:|---:|---:|")
    for h in sizes:
        rigid = [r for r in series(records, "pyramid", "support", "rigid") if r["h_prime"] == h]
        flexible = [r for r in series(records, "pyramid", "support", "flexible") if r["h_prime"] == h]
        ref = (rigid or flexible)[0]["reference"]
        rv = rigid[0]["value"] if rigid else float("nan")
        fv = flexible[0]["value"] if flexible else float("nan")
        print(f"| {h:g} | {fmt(rv, '.5f')} | {fmt(fv, '.5f')} | {fmt(ref, '.5f')} | {fmt(rv / ref, '.3f')} | {fmt(fv / ref, '.3f')} |")

    print("\n### Convergence\n")
    print("| quantity | spacing | nodes | unknowns | value | change | observed order | solve s | assembly s | factorization s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for key, setting, name in (("circuit", "open", "Y' (open beam, h' = 4)"), ("support", "rigid", "e' (rigid pyramid, h' = 2)")):
        rows = sorted([r for r in records if r["case"] == "convergence" and r.get(key) == setting], key=lambda r: -r["spacing"])
        changes = [None] + [abs(rows[i]["value"] - rows[i - 1]["value"]) for i in range(1, len(rows))]
        for i, r in enumerate(rows):
            order = None
            if i >= 2 and changes[i] and changes[i - 1]:
                order = math.log(changes[i - 1] / changes[i]) / math.log(rows[i - 1]["spacing"] / rows[i]["spacing"])
            print(f"| {name} | {r['spacing']:g} | {r['nodes']:.0f} | {r['unknowns']:.0f} | {r['value']:.6f} | {fmt(changes[i], '.2e')} | "
                  f"{fmt(order, '.2f')} | {r['solve_s']:.2f} | {fmt(r.get('assembly_s'), '.2f')} | "
                  f"{fmt(r.get('factorization_s'), '.2f')} |")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("bench")
    p.add_argument("figures")
    p.add_argument("--fields", default="build/demo/flexoelectric")
    a = p.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
    except ImportError:
        print("plot_flexo.py: needs python3-matplotlib", file=sys.stderr)
        return 3
    records, midlines = load(a.bench)
    os.makedirs(a.figures, exist_ok=True)
    cantilever_figure(records, a.figures)
    midlines_figure(midlines, a.figures)
    pyramid_figure(records, a.figures)
    convergence_figure(records, a.figures)
    fields_figure(a.fields, a.figures)
    tables(records)
    return 0


if __name__ == "__main__":
    sys.exit(main())
