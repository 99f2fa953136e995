#!/usr/bin/env bash
# Alternate minimization (the [staggered] table: u, then v, to 1e-4) against a monolithic Newton on
# (u, v) together (the same scene without [staggered]: the VI Newton of the minimization driver with
# the irreversibility bound) on a coarse single-edge-notched tension test: sent.toml with l = 0.03,
# the crack band at spacing 0.015 (l = 2h), 32 load steps to delta = 0.008. Prints per run: steps
# converged, increments cut, Newton iterations, seconds per step, the peak force and where.
#   demos/fracture/monolithic_vs_staggered.sh [BUILD]
set -euo pipefail
build=${1:-build}
lmeform="$build/lmeform"
here=$(cd "$(dirname "$0")" && pwd)
out="$build/demo/fracture/monolithic_vs_staggered"
rm -rf "$out"
mkdir -p "$out"
sed -e 's#spacing = 0.0075, width = 0.015#spacing = 0.015, width = 0.03#' \
    -e 's#^l = 0.015#l = 0.03#' \
    -e 's#^count = 125#count = 32#' \
    -e 's#^values = { delta = .*#ramp = { delta = [0.0, 0.008] }#' \
    -e 's#^name = "sent"#name = "sent_coarse"#' \
    "$here/sent.toml" > "$out/staggered.toml"
grep -q '^ramp = { delta = \[0.0, 0.008\] }$' "$out/staggered.toml" || { echo "could not make the coarse scene" >&2; exit 1; }
# The monolithic scene: the same without the [staggered] table.
awk '/^\[staggered\]/ {skip = 1; next} /^\[/ {skip = 0} !skip' "$out/staggered.toml" > "$out/monolithic.toml"
for run in staggered monolithic; do
  start=$(date +%s.%N)
  "$lmeform" run "$out/$run.toml" --output "$out/$run" > "$out/$run.log" 2>&1 || true
  end=$(date +%s.%N)
  echo "$run: $(grep -E '^status' "$out/$run.log" | cut -c1-160) ($(echo "$end - $start" | bc) s)"
done
/usr/bin/python3 - "$out" <<'PY'
import csv, sys
out = sys.argv[1]
print(f"{'run':12s} {'steps':>5s} {'cuts':>4s} {'Newton':>7s} {'Newton/step':>11s} {'s/step':>7s} {'peak force':>10s} {'at delta':>9s}")
for run in ("staggered", "monolithic"):
    try:
        rows = list(csv.DictReader(open(f"{out}/{run}/history.csv")))
    except FileNotFoundError:
        print(f"{run:12s} no history")
        continue
    steps = rows[1:]
    newton = sum(int(r["iterations"]) for r in steps)
    if run == "staggered":  # the staggered driver's own count: Newton steps of both groups
        newton = sum(int(float(r.get("u_newton", 0))) + int(float(r.get("v_newton", 0))) for r in steps)
    wall = float(rows[-1]["wall_s"]) - float(rows[0]["wall_s"])
    peak = max(rows, key=lambda r: float(r["force[1]"]) if "force[1]" in r else float(r["force"]))
    f = float(peak["force[1]"]) if "force[1]" in peak else float(peak["force"])
    print(f"{run:12s} {len(steps):5d} {sum(int(r['cuts']) for r in steps):4d} {newton:7d} {newton / max(1, len(steps)):11.1f} "
          f"{wall / max(1, len(steps)):7.2f} {f:10.4f} {float(peak['delta']):9.5f}")
PY
