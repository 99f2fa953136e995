#!/usr/bin/env python3
"""Energy of the vesicle schedule against eps for the first- and second-order basis on grids of
several resolution factors (the JSON files of `lmeform run --json`, named BASIS_FACTOR[_fine].json
by basis_order_study.sh).

Prints, per eps, the energy of every run; per basis and eps, the limit h -> 0 from the three
factors 2, 3, 4 (E_f = E_inf + C f^-p, p solved from the three values, when they converge
monotonically); and the fit E0 + a eps + b eps^2 of those limits (eps <= 0.02) against the sharp
energy. --png draws the energies against eps.

  basis_order_study.py RUN.json ... [--png FILE] [--sharp 9.12657]
"""
import argparse
import json
import math
import os
import sys
from collections import defaultdict


def read_run(path):
    name = os.path.splitext(os.path.basename(path))[0]
    parts = name.split("_")
    basis, factor = parts[0], int(parts[1])
    with open(path) as f:
        r = json.load(f)
    energies = {}
    for st in r.get("stages", []):
        if st.get("converged", True) is not False:
            energies[round(st["eps"], 6)] = (st["energy"], st["nodes"], st.get("wall_s"))
    return basis, factor, name, energies, r.get("wall_s")


def limit_in_h(values):
    """E_f = E_inf + C f^-p from the energies at factors 2, 3, 4; None unless monotone."""
    e2, e3, e4 = values[2], values[3], values[4]
    d1, d2 = e2 - e3, e3 - e4
    if d1 == 0 or d2 == 0 or (d1 > 0) != (d2 > 0) or abs(d2) >= abs(d1):
        return None
    target = d1 / d2

    def ratio(p):
        return (2 ** -p - 3 ** -p) / (3 ** -p - 4 ** -p)

    lo, hi = 0.05, 12.0
    if not (ratio(lo) <= target <= ratio(hi)):
        return None
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if ratio(mid) < target:
            lo = mid
        else:
            hi = mid
    p = 0.5 * (lo + hi)
    c = d2 / (3 ** -p - 4 ** -p)
    return e4 - c * 4 ** -p, p


def fit_quadratic(points):
    """Least squares E0 + a eps + b eps^2."""
    n = len(points)
    s = [[0.0] * 3 for _ in range(3)]
    t = [0.0] * 3
    for eps, e in points:
        row = [1.0, eps, eps * eps]
        for i in range(3):
            t[i] += row[i] * e
            for j in range(3):
                s[i][j] += row[i] * row[j]
    # Gaussian elimination on the 3x3 normal equations.
    for k in range(3):
        piv = max(range(k, 3), key=lambda i: abs(s[i][k]))
        s[k], s[piv] = s[piv], s[k]
        t[k], t[piv] = t[piv], t[k]
        for i in range(k + 1, 3):
            f = s[i][k] / s[k][k]
            for j in range(k, 3):
                s[i][j] -= f * s[k][j]
            t[i] -= f * t[k]
    c = [0.0] * 3
    for i in (2, 1, 0):
        c[i] = (t[i] - sum(s[i][j] * c[j] for j in range(i + 1, 3))) / s[i][i]
    residual = max(abs(c[0] + c[1] * eps + c[2] * eps * eps - e) for eps, e in points) if n else 0.0
    return c, residual


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--png")
    ap.add_argument("--sharp", type=float, default=9.12657, help="sharp-interface energy (seed, oblate v = 0.8)")
    args = ap.parse_args()

    runs = [read_run(p) for p in args.runs]
    runs.sort(key=lambda r: (r[0], r[1], r[2]))
    all_eps = sorted({eps for r in runs for eps in r[3]}, reverse=True)
    print("energy (relative to the sharp %.5f) per eps and run" % args.sharp)
    print("%8s" % "eps" + "".join("%22s" % r[2] for r in runs))
    for eps in all_eps:
        cells = []
        for r in runs:
            if eps in r[3]:
                e = r[3][eps][0]
                cells.append("%12.5f %+7.3f%%" % (e, 100 * (e - args.sharp) / args.sharp))
            else:
                cells.append("%22s" % "")
        print("%8.4f" % eps + "".join("%22s" % c for c in cells))
    print("wall s  " + "".join("%22s" % ("%.0f" % r[4] if r[4] else "") for r in runs))

    by_basis = defaultdict(dict)  # basis -> eps -> factor -> energy
    for basis, factor, _name, energies, _wall in runs:
        for eps, (e, _nodes, _w) in energies.items():
            by_basis[basis].setdefault(eps, {})[factor] = e
    limits = {}
    for basis, table in sorted(by_basis.items()):
        print(f"\n{basis}-order basis: limit h -> 0 from factors 2, 3, 4")
        pts = []
        for eps in sorted(table, reverse=True):
            values = table[eps]
            if all(f in values for f in (2, 3, 4)):
                lim = limit_in_h(values)
                if lim is None:
                    print(f"  eps {eps:.4f}: {values[2]:.5f} {values[3]:.5f} {values[4]:.5f}  not monotone: no limit")
                else:
                    print(f"  eps {eps:.4f}: {values[2]:.5f} {values[3]:.5f} {values[4]:.5f}  -> {lim[0]:.5f} "
                          f"({100 * (lim[0] - args.sharp) / args.sharp:+.3f} %), order {lim[1]:.2f} in h")
                    if eps <= 0.02 + 1e-12:
                        pts.append((eps, lim[0]))
        if len(pts) >= 3:
            c, res = fit_quadratic(pts)
            limits[basis] = (pts, c)
            print(f"  E0 + a eps + b eps^2 over eps = {', '.join('%g' % p[0] for p in pts)}: E0 = {c[0]:.5f} "
                  f"({100 * (c[0] - args.sharp) / args.sharp:+.3f} % from the sharp), a = {c[1]:.3f}, b = {c[2]:.1f}, "
                  f"residual {res:.1e}; at eps = 0.005: {c[0] + 0.005 * c[1] + 2.5e-5 * c[2]:.5f} "
                  f"({100 * (c[0] + 0.005 * c[1] + 2.5e-5 * c[2] - args.sharp) / args.sharp:+.3f} %)")

    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(7, 4.5))
        styles = {"first": "--", "second": "-"}
        fine_runs = {(b, f) for b, f, n, _e, _w in runs if "fine" in n}
        for basis, factor, name, energies, _w in runs:
            if "fine" not in name and (basis, factor) in fine_runs:
                continue  # the fine run repeats its stages
            eps = sorted(energies)
            ax.plot(eps, [100 * (energies[e][0] - args.sharp) / args.sharp for e in eps], styles.get(basis, ":"),
                    marker="o", ms=3, color={2: "tab:blue", 3: "tab:orange", 4: "tab:green"}.get(factor, "tab:red"), label=f"{basis} order, h = eps/{factor}" + (" (fine)" if "fine" in name else ""))
        for basis, (pts, _c) in limits.items():
            ax.plot([p[0] for p in pts], [100 * (p[1] - args.sharp) / args.sharp for p in pts], ":x", color="k" if basis == "second" else "grey",
                    label=f"{basis} order: limits h -> 0 (factors 2, 3, 4)")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("eps")
        ax.set_ylabel("E / E_sharp - 1 (%)")
        ax.set_xlim(0, 0.021)
        ax.set_ylim(0.0, 2.0)
        ax.set_title("discocyte v = 0.8: energy against eps, first- and second-order basis")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(args.png, dpi=120)
        print(f"\nwrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
