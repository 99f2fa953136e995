#!/usr/bin/python3
"""The cantilever: lmeform (LME) against FEniCSx (P1, P2) on the same problem.

    /usr/bin/python3 demos/solids/compare_solids.py BUILD_DIR

Reads BUILD_DIR/bench/solids.json (bench_solids; its "cantilever" records) and
BUILD_DIR/compare/solids_fenicsx.json (fenicsx_cantilever.py). The lmeform energy-norm error is
(2 * energy_error)^(1/2), energy_error being the scene's quantity 1/2 int (e - e_ex):C:(e - e_ex).
Times: lmeform's whole run (scene, nodes, LME basis, quadrature, assembly, solve), FEniCSx's
total_s (mesh, spaces, assembly, solve; its forms compiled before).
Writes BUILD_DIR/compare/solids_compare.json (one record per run of either code),
BUILD_DIR/compare/solids_cantilever.png (tip error, L2 and energy errors against unknowns and
against wall time) and BUILD_DIR/compare/solids_compare.md, and prints the Markdown table.
"""
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def rate(prev, cur, key):
    if prev is None or not prev[key] or not cur[key]:
        return None
    return -2 * math.log(cur[key] / prev[key]) / math.log(cur["unknowns"] / prev["unknowns"])


def main(build):
    records = []
    bench = os.path.join(build, "bench", "solids.json")
    if os.path.exists(bench):
        for r in json.load(open(bench)):
            if r["case"] != "cantilever":
                continue
            errors = r.get("error_u", {})
            records.append({"code": "lmeform", "element": "LME (gamma 0.8)", "unknowns": int(2 * r["nodes"]),
                            "value": r["value"], "reference": r["reference"], "rel_error": r["rel_error"],
                            "error_l2": errors.get("l2"), "error_energy": math.sqrt(2 * r["quantities"]["energy_error"]),
                            "wall_s": r["wall_s"]})
    fenicsx = os.path.join(build, "compare", "solids_fenicsx.json")
    if os.path.exists(fenicsx):
        for r in json.load(open(fenicsx)):
            records.append({"code": "fenicsx", "element": r["element"], "unknowns": r["unknowns"], "value": r["value"],
                            "reference": r["reference"], "rel_error": r["rel_error"], "error_l2": r["error_l2"],
                            "error_energy": r["error_energy"], "wall_s": r["total_s"]})
    if not records:
        print("no records: run bench_solids and fenicsx_cantilever.py first", file=sys.stderr)
        return 1
    out = os.path.join(build, "compare")
    os.makedirs(out, exist_ok=True)
    json.dump(records, open(os.path.join(out, "solids_compare.json"), "w"), indent=1)
    series = {}
    for r in records:
        series.setdefault((r["code"], r["element"]), []).append(r)
    lines = ["| code | basis | unknowns | tip deflection | rel. error | L2 error | rate | energy error | rate | wall s |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for (code, element), rs in series.items():
        rs.sort(key=lambda r: r["unknowns"])
        prev = None
        for r in rs:
            f = lambda v: "–" if v is None else f"{v:.2f}"
            lines.append(f"| {code} | {element} | {r['unknowns']} | {r['value']:.6f} | {r['rel_error']:.2e} | {r['error_l2']:.2e} | "
                         f"{f(rate(prev, r, 'error_l2'))} | {r['error_energy']:.2e} | {f(rate(prev, r, 'error_energy'))} | {r['wall_s']:.3f} |")
            prev = r
    table = "\n".join(lines) + "\n"
    open(os.path.join(out, "solids_compare.md"), "w").write(table)
    print(table)
    fig, axes = plt.subplots(2, 3, figsize=(14, 8))
    for (code, element), rs in series.items():
        label = f"{code} {element}"
        for col, key in enumerate(["rel_error", "error_l2", "error_energy"]):
            axes[0][col].loglog([r["unknowns"] for r in rs], [r[key] for r in rs], "o-", label=label)
            axes[1][col].loglog([r["wall_s"] for r in rs], [r[key] for r in rs], "o-", label=label)
    for col, title in enumerate(["tip deflection, relative error", "L2 error of u", "energy-norm error"]):
        axes[0][col].set_title(title)
        axes[0][col].set_xlabel("unknowns")
        axes[1][col].set_xlabel("wall time [s] (set-up, assembly, solve)")
    axes[0][0].legend(fontsize=8)
    fig.suptitle("Timoshenko-Goodier cantilever (plane stress): lmeform vs FEniCSx")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "solids_cantilever.png"), dpi=110)
    print(f"wrote {out}/solids_compare.json, solids_compare.md, solids_cantilever.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "build"))
