#!/usr/bin/env bash
# The discocyte of discocyte_resolved.toml (oblate start, v = 0.8) with the first- and the
# second-order max-ent basis ([nodes] basis = "first" | "second") on grids 2, 3 and 4 times finer
# than eps (resolution_factor; the uniform start grows with it: 6124, 13800, 24600 nodes), eps from
# 0.05 to 0.01; FINE=1 adds the fourth grid resolving eps = 0.005 (stages 0.0075, 0.005).
# Then basis_order_study.py prints the energy table, the eps-extrapolation and draws the figure.
#   demos/shapes/basis_order_study.sh [BUILD_DIR] [OUT_DIR]
# BASES="second" and FACTORS="3 4" select a subset; JOBS=2 runs two scenes at a time.
# Measured (one core each, two at a time): docs/results.md, "The second-order basis".
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${1:-build}
out=${2:-$build/demo/basis_order}
mkdir -p "$out"
run() {
  local basis=$1 factor=$2 count
  case $factor in 2) count=6124 ;; 3) count=13800 ;; 4) count=24600 ;; *) echo "factor $factor: one of 2 3 4" >&2; return 1 ;; esac
  local name="${basis}_${factor}${FINE:+_fine}"
  sed -e "s/^gamma = 0.5/gamma = 0.5\nbasis = \"$basis\"/" -e "s/^count = 6124 .*/count = $count/" \
      -e "s/^resolution_factor = 2.0 .*/resolution_factor = $factor.0/" -e 's/^png = true/png = false/' \
      -e "s#^directory = .*#directory = \"$out/$name\"#" "$here/discocyte_resolved.toml" > "$out/$name.toml"
  if [[ -n "${FINE:-}" ]]; then
    # The grid resolving 0.005 at factor 4 has 68421 nodes, above the default budget of 60000.
    sed -i -e 's/^  { eps = 0.01,  lloyd_iterations = 0 },/  { eps = 0.01,  lloyd_iterations = 0 },\n  { eps = 0.0075, resolve = 0.005 },\n  { eps = 0.005, lloyd_iterations = 0 },/' \
        -e 's/^lloyd_iterations = 20/lloyd_iterations = 20\nmax_nodes = 100000/' "$out/$name.toml"
  fi
  /usr/bin/time -v "$build/lmeform" run "$out/$name.toml" --json "$out/$name.json" > "$out/$name.log" 2>&1 || echo "$name failed: $out/$name.log"
}
jobs=0
for factor in ${FACTORS:-2 3 4}; do
  for basis in ${BASES:-first second}; do
    run "$basis" "$factor" &
    jobs=$((jobs + 1))
    if (( jobs % ${JOBS:-2} == 0 )); then wait; fi
  done
done
wait
/usr/bin/python3 "$here/basis_order_study.py" "$out"/*.json --png "$out/basis_order.png"
