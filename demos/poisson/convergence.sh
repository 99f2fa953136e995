#!/usr/bin/env bash
# Convergence of the manufactured Poisson problem (poisson_mms.form) under refinement, with no C++:
# `lmeform run` on a ladder of scenes derived from poisson_uniform.toml (spacings 0.1, 0.05, 0.025,
# 0.0125) and poisson_graded.toml (graded, warped node sets of 11^2 ... 81^2 nodes from
# graded_points.py), each for LME gamma 0.8 and 1.6 and with --json; then a table of L2 and H1 (semi-norm)
# errors and observed rates log(e_{k-1}/e_k) / log(h_{k-1}/h_k), with h = 1/(N_axis - 1) (the
# spacing of the uniform grid; the mean spacing of the graded one).
#
#   demos/poisson/convergence.sh BUILD_DIR [OUT_DIR] [--tabulate-only]
#
# --tabulate-only: no runs; the table and the figure from the JSON files already in OUT_DIR.
#
# Writes OUT_DIR (default BUILD_DIR/demo/poisson_convergence): the scenes, logs and JSON of every
# run, convergence.json (all numbers), convergence.md (the table) and convergence.png (error vs h,
# needs /usr/bin/python3 with matplotlib); the table and the figure are copied to
# demos/poisson/convergence.md and docs/figures/poisson_convergence.png. About two minutes on one core
# once the forms are compiled (the first run compiles them: ~40 s; LMEFORM_CACHE_DIR keeps them).
set -euo pipefail
tabulate_only=0
args=()
for a in "$@"; do
  if [[ $a == --tabulate-only ]]; then tabulate_only=1; else args+=("$a"); fi
done
if [[ ${#args[@]} -lt 1 || ${#args[@]} -gt 2 ]]; then
  echo "usage: $0 BUILD_DIR [OUT_DIR] [--tabulate-only]" >&2
  exit 1
fi
build=$(cd "${args[0]}" && pwd)
demo=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$demo/../.." && pwd)
out=${args[1]:-$build/demo/poisson_convergence}
lmeform=$build/lmeform
[[ -x $lmeform ]] || { echo "convergence.sh: $lmeform not found (build it first)" >&2; exit 1; }
mkdir -p "$out"
out=$(cd "$out" && pwd)

# One run: NAME, then sed expressions applied to the scene template SCENE.
run() {
  local name=$1 template=$2
  shift 2
  if [[ $tabulate_only == 1 ]]; then
    [[ -f $out/$name.json ]] || { echo "convergence.sh: --tabulate-only: $out/$name.json is missing" >&2; exit 1; }
    return
  fi
  sed -e "s#^name = .*#name = \"$name\"#" -e "s#\"poisson_mms.form\"#\"$demo/poisson_mms.form\"#" "$@" \
    "$demo/$template" > "$out/$name.toml"
  if ! "$lmeform" run "$out/$name.toml" --json "$out/$name.json" --output "$out/$name" > "$out/$name.log" 2>&1; then
    echo "convergence.sh: $name failed; the end of $out/$name.log:" >&2
    tail -5 "$out/$name.log" >&2
    exit 1
  fi
  /usr/bin/python3 -c 'import json, sys
j = json.load(open(sys.argv[1])); e = j["errors"][0]
print("  %-22s %6d nodes  L2 %.3e  H1 %.3e  (%.1f s)" % (sys.argv[2], j["nodes"], e["l2"], e["h1"], j["wall_s"]))' \
    "$out/$name.json" "$name"
}

runs=()
for gamma in 0.8 1.6; do
  for h in 0.1 0.05 0.025 0.0125; do
    name="uniform_g${gamma}_h$h"
    run "$name" poisson_uniform.toml -e "s#^spacing = [0-9.]*#spacing = $h#" -e "s#^gamma = [0-9.]*#gamma = $gamma#"
    runs+=("uniform gamma=$gamma:$(/usr/bin/python3 -c "print(round(1/$h) + 1)"):$out/$name.json")
  done
done
for n in 11 21 41 81; do
  [[ $tabulate_only == 1 ]] || /usr/bin/python3 "$demo/graded_points.py" "$n" "$out/graded_$n.txt"
done
for gamma in 0.8 1.6; do
  for n in 11 21 41 81; do
    name="graded_g${gamma}_n$n"
    run "$name" poisson_graded.toml -e "s#^file = .*#file = \"$out/graded_$n.txt\"#" -e "s#^gamma = [0-9.]*#gamma = $gamma#"
    runs+=("graded gamma=$gamma:$n:$out/$name.json")
  done
done

/usr/bin/python3 - "$out" "${runs[@]}" <<'PY'
import json, math, os, sys
out = sys.argv[1]
series = {}
for spec in sys.argv[2:]:
    label, n, path = spec.split(":", 2)
    j = json.load(open(path))
    assert j["converged"], (path, j["status"])
    e = j["errors"][0]
    series.setdefault(label, []).append({"n_axis": int(n), "h": 1.0 / (int(n) - 1), "nodes": j["nodes"],
                                         "h_min": j["h_min"], "l2": e["l2"], "h1": e["h1"], "wall_s": j["wall_s"]})
lines = ["| node set | nodes | h | L2 error | rate | H1 error | rate |", "|---|---:|---:|---:|---:|---:|---:|"]
for label, rows in series.items():
    for k, r in enumerate(rows):
        if k > 0:
            p = rows[k - 1]
            r["rate_l2"] = math.log(p["l2"] / r["l2"]) / math.log(p["h"] / r["h"])
            r["rate_h1"] = math.log(p["h1"] / r["h1"]) / math.log(p["h"] / r["h"])
        rl2 = f"{r['rate_l2']:.2f}" if k else "-"
        rh1 = f"{r['rate_h1']:.2f}" if k else "-"
        lines.append(f"| {label} | {r['nodes']} | {r['h']:.4g} | {r['l2']:.3e} | {rl2} | {r['h1']:.3e} | {rh1} |")
table = "\n".join(lines)
print()
print(table)
json.dump(series, open(os.path.join(out, "convergence.json"), "w"), indent=2)
with open(os.path.join(out, "convergence.md"), "w") as f:
    f.write("# Poisson manufactured solution: errors and rates\n\n"
            "Written by `demos/poisson/convergence.sh BUILD_DIR` (do not edit): `lmeform run` of\n"
            "`poisson_mms.form` (u = sin(pi x) sin(pi y) on the unit square, u exact on the boundary), L2 and\n"
            "H1 semi-norm errors from `[reference.solution]`, rates between consecutive rows;\n"
            "h = 1/(N_axis - 1).\n\n" + table + "\n")
try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    print("convergence.sh: no matplotlib, no figure", file=sys.stderr)
    sys.exit(0)
fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
for ax, norm, title in ((axes[0], "l2", "L2 error"), (axes[1], "h1", "H1 semi-norm error")):
    for (label, rows), marker in zip(series.items(), "osd^v"):
        ax.loglog([r["h"] for r in rows], [r[norm] for r in rows], marker + "-", label=label)
    h = [r["h"] for r in next(iter(series.values()))]
    for order, style in ((1, ":"), (2, "--"), (3, "-.")):
        ref = next(iter(series.values()))[-1][norm]
        ax.loglog(h, [ref * (x / h[-1]) ** order for x in h], "k" + style, lw=0.8, label=f"h^{order}")
    ax.set_xlabel("h")
    ax.set_xticks(h)
    ax.set_xticklabels([f"{x:g}" for x in h])
    ax.minorticks_off()
    ax.set_title(title)
    ax.grid(True, which="major", lw=0.3)
handles, labels = axes[0].get_legend_handles_labels()
fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
fig.suptitle("Poisson, manufactured solution sin(pi x) sin(pi y): LME (lmeform run)")
fig.tight_layout(rect=(0, 0.07, 1, 1))
fig.savefig(os.path.join(out, "convergence.png"), dpi=110)
PY
cp "$out/convergence.md" "$demo/convergence.md"
if [[ -f $out/convergence.png ]]; then
  mkdir -p "$root/docs/figures"
  cp "$out/convergence.png" "$root/docs/figures/poisson_convergence.png"
fi
echo
echo "wrote $out/convergence.{json,md,png}, demos/poisson/convergence.md, docs/figures/poisson_convergence.png"
