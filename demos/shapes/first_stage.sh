#!/usr/bin/env bash
# The first constrained solve from ellipsoid starts (uniform CVT of 6124 nodes, eps = 0.04, the
# discocyte demo's settings otherwise) with both starts of the minimizer: [solver] start = "kkt"
# (the default) and "augmented" (the augmented Lagrangian first, round 1's only choice).
# Prints one line per run: branch, v, start, iterations, energy, wall time; JSON per run in OUT.
#   demos/shapes/first_stage.sh [BUILD_DIR] [OUT_DIR]
# CASES="oblate:0.7 prolate:0.7" and STARTS="augmented" select a subset.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${1:-build}
out=${2:-$build/demo/first_stage}
mkdir -p "$out"
for case in ${CASES:-oblate:0.8 oblate:0.9 prolate:0.9 oblate:0.7 prolate:0.7}; do
  branch=${case%%:*} v=${case##*:}
  for start in ${STARTS:-kkt augmented}; do
    scene="$out/${branch}_${v}_${start}.toml"
    sed -e "s/^reduced_volume = 0.8/reduced_volume = $v/" -e "s/^shape = \"ellipsoid\"/shape = \"$branch\"/" \
        -e '/^semi_axes/d' -e '/^\[vesicle.adaptivity\]/,/^\]/d' -e '/^\[reference\]/,/^energy/d' \
        -e "s/^penalty = 1e-3/start = \"$start\"\npenalty = 1e-3/" \
        -e "s#^directory = .*#directory = \"$out/${branch}_${v}_${start}\"#" "$here/../discocyte.toml" > "$scene"
    "$build/lmeform" run "$scene" --json "$out/${branch}_${v}_${start}.json" > "$out/${branch}_${v}_${start}.log" 2>&1 || true
    /usr/bin/python3 - "$out/${branch}_${v}_${start}.json" "$branch" "$v" "$start" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
st = r["stages"][0] if "stages" in r else r
print(f"{sys.argv[2]:8s} v {sys.argv[3]}  start {sys.argv[4]:9s}  AL {st.get('augmented_iterations')}  KKT {st.get('newton_iterations')}"
      f"  E {st.get('energy')}  {st.get('wall_s', r.get('wall_s'))} s  converged {st.get('converged', r.get('converged'))}")
PY
  done
done
