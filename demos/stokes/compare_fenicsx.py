#!/usr/bin/python3
"""Stokes: lmeform (LME, GLS) against FEniCSx (P2/P1 Taylor-Hood, P1/P1 stabilised).

    /usr/bin/python3 demos/stokes/compare_fenicsx.py BUILD_DIR

Reads BUILD_DIR/compare/stokes_fenicsx_only.json (demos/stokes/fenicsx_stokes.py) and, when present,
BUILD_DIR/bench/stokes.json (bench_stokes).  Of the lmeform records it keeps, per problem, the
uniform node sets with stabilization "gls" and the (gamma, C) pair that occurs most often.
Writes BUILD_DIR/compare/stokes_fenicsx.json (both codes, one record per run),
BUILD_DIR/compare/stokes_<problem>.png (2x2: u and p L2 error against unknowns and against wall
time) and BUILD_DIR/compare/stokes_fenicsx.md, and prints the Markdown table and the error per
second: for the finest run of each lmeform series, the wall time each FEniCSx element needs for the
same velocity L2 error (log-log interpolation along its mesh ladder) and lmeform's time over it,
with lmeform's time taken whole and without its setup (node set, LME basis, quadrature; FEniCSx's
times exclude its mesh and function space).
"""
import collections
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PROBLEM_ORDER = ["colliding_flow", "poiseuille", "manufactured"]


def num(x):
    """float or None (missing, null, NaN)."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(v) else v


def load(path):
    with open(path) as fh:
        data = json.load(fh)
    if isinstance(data, dict):  # tolerate {"records": [...]} or {"results": [...]}
        for key in ("records", "results", "runs"):
            if isinstance(data.get(key), list):
                return data[key]
        raise ValueError(f"{path}: expected a list of records")
    return data


def fenicsx_records(path):
    out = []
    for r in load(path):
        out.append({"code": "fenicsx", "element": r["element"], "problem": r["problem"],
                    "unknowns": int(r["unknowns"]), "error_u_l2": num(r.get("error_u_l2")),
                    "error_u_h1": num(r.get("error_u_h1")), "error_p_l2": num(r.get("error_p_l2")),
                    "wall_s": num(r.get("wall_s"))})
    return out


def lmeform_records(path):
    raw = load(path)
    out = []
    by_problem = collections.defaultdict(list)  # (problem, basis): the first- and second-order series apart
    for r in raw:
        if r.get("node_set", "uniform") == "uniform" and str(r.get("stabilization", "")).lower() == "gls":
            by_problem[(r["problem"], r.get("basis", "first"), num(r.get("support_tolerance")) or 1e-6,
                        r.get("solver", "mumps"))].append(r)
    if not by_problem:
        stabs = sorted({str(r.get("stabilization")) for r in raw})
        print(f"note: {path} has no uniform-node 'gls' records (stabilizations present: {stabs})")
    for (problem, basis, tol, solver), rows in by_problem.items():
        counts = collections.Counter((num(r.get("gamma")), num(r.get("C"))) for r in rows)
        (gamma, c), _ = max(counts.items(), key=lambda kv: (kv[1], -(kv[0][0] or 0)))
        label = ("LME gls" if basis == "first" else "2nd-order max-ent gls, consistent") + f" gamma={gamma:g}" + \
            (f" C={c}" if c is not None else "") + (f" support to {tol:g}" if tol != 1e-6 else "") + \
            (f", {solver}" if solver != "mumps" else "")
        kept = [r for r in rows if (num(r.get("gamma")), num(r.get("C"))) == (gamma, c)]
        if len(counts) > 1:
            print(f"note: {problem}: {len(counts)} (gamma, C) pairs among uniform gls runs; "
                  f"kept the most common, gamma={gamma:g} C={c}")
        # One run per grid: the same (gamma, C) recurs in several sweeps of bench_stokes; the
        # first record (the convergence ladder) is kept.
        per_grid = {}
        for r in kept:
            per_grid.setdefault(r["unknowns"], r)
        for r in sorted(per_grid.values(), key=lambda r: r["unknowns"]):
            wall = num(r.get("wall_s"))
            if wall is None:
                a, s = num(r.get("assembly_s")), num(r.get("solve_s"))
                wall = None if a is None or s is None else a + s
            out.append({"code": "lmeform", "element": label, "problem": problem,
                        "unknowns": int(r["unknowns"]), "error_u_l2": num(r.get("error_u_l2")),
                        "error_u_h1": num(r.get("error_u_h1")),
                        "error_p_l2": num(r.get("error_p_l2")), "wall_s": wall,
                        "setup_s": num(r.get("setup_s")), "matrix_nonzeros": r.get("matrix_nonzeros"),
                        "nodes": r.get("nodes")})
    return out


def rate(r0, r1, key):
    """Rate in h = -2 d log e / d log unknowns (2D)."""
    e0, e1 = r0.get(key), r1.get(key)
    if not e0 or not e1 or e0 <= 0 or e1 <= 0 or r1["unknowns"] == r0["unknowns"]:
        return None
    if max(e0, e1) < 1e-11:  # exact to round-off (Poiseuille with P2 velocities)
        return None
    return -2 * math.log(e1 / e0) / math.log(r1["unknowns"] / r0["unknowns"])


def series(records, problem):
    groups = collections.OrderedDict()
    for r in records:
        if r["problem"] == problem:
            groups.setdefault((r["code"], r["element"]), []).append(r)
    for rows in groups.values():
        rows.sort(key=lambda r: r["unknowns"])
    return groups


def fmt_e(x):
    return "-" if x is None else f"{x:.3e}"


def fmt_r(x):
    return "" if x is None else f" ({x:.2f})"


def table(records, problems):
    lines = ["| problem | code | element | unknowns | u L2 (rate) | u H1 (rate) | p L2 (rate) | wall s |",
             "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: |"]
    for problem in problems:
        for (code, element), rows in series(records, problem).items():
            prev = None
            for r in rows:
                ru = rate(prev, r, "error_u_l2") if prev else None
                rh = rate(prev, r, "error_u_h1") if prev else None
                rp = rate(prev, r, "error_p_l2") if prev else None
                wall = "-" if r["wall_s"] is None else f"{r['wall_s']:.4f}"
                lines.append(f"| {problem} | {code} | {element} | {r['unknowns']} | "
                             f"{fmt_e(r['error_u_l2'])}{fmt_r(ru)} | {fmt_e(r.get('error_u_h1'))}{fmt_r(rh)} | "
                             f"{fmt_e(r['error_p_l2'])}{fmt_r(rp)} | {wall} |")
                prev = r
    return "\n".join(lines)


def time_for_error(rows, error):
    """Wall time along a series (sorted by unknowns) to reach a velocity L2 error, by log-log
    interpolation between the two runs that bracket it; beyond the ladder, the last two runs
    extrapolated. Returns (seconds, extrapolated) or (None, False)."""
    pts = [(r["error_u_l2"], r["wall_s"]) for r in rows
           if r.get("error_u_l2") and r.get("wall_s") and r["error_u_l2"] > 1e-11 and r["wall_s"] > 0]
    if len(pts) < 2:
        return None, False
    for (e0, t0), (e1, t1) in zip(pts, pts[1:]):
        if min(e0, e1) <= error <= max(e0, e1) and e0 != e1:
            w = math.log(error / e0) / math.log(e1 / e0)
            return math.exp(math.log(t0) + w * math.log(t1 / t0)), False
    (e0, t0), (e1, t1) = (pts[0], pts[1]) if error > pts[0][0] else (pts[-2], pts[-1])
    if e0 == e1 or t0 == t1:
        return None, False
    w = math.log(error / e0) / math.log(e1 / e0)
    return math.exp(math.log(t0) + w * math.log(t1 / t0)), True


def error_per_second(records, problems):
    """The finest run of each lmeform series against each FEniCSx element at equal velocity error."""
    lines = ["| problem | lmeform series | unknowns | u L2 | wall s (without setup) | FEniCSx element | its time for that error | "
             "lmeform / FEniCSx time (without setup) |",
             "| --- | --- | ---: | ---: | ---: | --- | ---: | ---: |"]
    out = []
    for problem in problems:
        groups = series(records, problem)
        for (code, element), rows in groups.items():
            if code != "lmeform" or not rows:
                continue
            r = rows[-1]
            if not r.get("error_u_l2") or not r.get("wall_s"):
                continue
            solve_only = r["wall_s"] - (r.get("setup_s") or 0.0)
            for (fcode, felement), frows in groups.items():
                if fcode != "fenicsx":
                    continue
                t, extrapolated = time_for_error(frows, r["error_u_l2"])
                if t is None:
                    continue
                mark = " (extrapolated)" if extrapolated else ""
                lines.append(f"| {problem} | {element} | {r['unknowns']} | {r['error_u_l2']:.3e} | {r['wall_s']:.2f} ({solve_only:.2f}) | "
                             f"{felement} | {t:.3f}{mark} | {r['wall_s'] / t:.1f} ({solve_only / t:.1f}) |")
                out.append({"problem": problem, "lmeform": element, "unknowns": r["unknowns"], "error_u_l2": r["error_u_l2"],
                            "wall_s": r["wall_s"], "wall_without_setup_s": solve_only, "fenicsx": felement,
                            "fenicsx_wall_s": t, "extrapolated": extrapolated, "time_ratio": r["wall_s"] / t,
                            "time_ratio_without_setup": solve_only / t})
    return "\n".join(lines), out


STYLE = {"fenicsx": {"ls": "--", "marker": "s"}, "lmeform": {"ls": "-", "marker": "o"}}


def plot(records, problem, path):
    groups = series(records, problem)
    fig, axes = plt.subplots(2, 2, figsize=(11, 8.5))
    panels = [(0, 0, "unknowns", "error_u_l2", "velocity L2 error"),
              (0, 1, "unknowns", "error_p_l2", "pressure L2 error"),
              (1, 0, "wall_s", "error_u_l2", "velocity L2 error"),
              (1, 1, "wall_s", "error_p_l2", "pressure L2 error")]
    for i, j, xkey, ykey, ylabel in panels:
        ax = axes[i][j]
        for (code, element), rows in groups.items():
            # in refinement order, also against wall time (a timing outlier shows as a step back)
            pts = [(r[xkey], r[ykey]) for r in rows
                   if r.get(xkey) and r.get(ykey) and r[xkey] > 0 and r[ykey] > 0]
            if not pts:
                continue
            xs, ys = zip(*pts)
            ax.loglog(xs, ys, label=f"{code}: {element}", **STYLE.get(code, {}))
        ax.set_xlabel("unknowns" if xkey == "unknowns" else "wall time, assembly + solve [s]")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    if not handles:
        handles, labels = axes[0][1].get_legend_handles_labels()
    fig.suptitle(f"Stokes, {problem}", y=0.99)
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.96), ncol=2, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.89))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv):
    if len(argv) != 2:
        print(__doc__)
        return 2
    build = argv[1]
    cdir = os.path.join(build, "compare")
    fx_path = os.path.join(cdir, "stokes_fenicsx_only.json")
    lme_path = os.path.join(build, "bench", "stokes.json")
    if not os.path.exists(fx_path):
        print(f"error: {fx_path} not found; run demos/stokes/fenicsx_stokes.py --out {cdir} first",
              file=sys.stderr)
        return 1
    records = fenicsx_records(fx_path)
    if os.path.exists(lme_path):
        lme = lmeform_records(lme_path)
        print(f"read {len(records)} FEniCSx records from {fx_path} and {len(lme)} lmeform records "
              f"(uniform, gls) from {lme_path}")
        records += lme
    else:
        print(f"note: {lme_path} not found (bench_stokes not built or not run): "
              f"comparing FEniCSx results only")
    present = {r["problem"] for r in records}
    problems = [p for p in PROBLEM_ORDER if p in present] + sorted(present - set(PROBLEM_ORDER))

    out_json = os.path.join(cdir, "stokes_fenicsx.json")
    with open(out_json, "w") as fh:
        json.dump(records, fh, indent=1)
    pngs = []
    for problem in problems:
        png = os.path.join(cdir, f"stokes_{problem}.png")
        plot(records, problem, png)
        pngs.append(png)
    md = table(records, problems)
    eps_md, eps_records = error_per_second(records, problems)
    with open(os.path.join(cdir, "stokes_fenicsx.md"), "w") as fh:
        fh.write(md + "\n\n" + eps_md + "\n")
    with open(os.path.join(cdir, "stokes_error_per_second.json"), "w") as fh:
        json.dump(eps_records, fh, indent=1)
    print()
    print(md)
    print()
    print("Error per second: the wall time to the same velocity L2 error")
    print(eps_md)
    print(f"\nwrote {out_json}, {os.path.join(cdir, 'stokes_fenicsx.md')}")
    for png in pngs:
        print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
