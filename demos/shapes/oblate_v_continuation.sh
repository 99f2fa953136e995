#!/usr/bin/env bash
# Continuation in the reduced volume at eps = 0.05 (docs/shapes.md): one-stage runs of
# oblate_v06_torus.toml's first stage on its uniform 6124-node grid at v = 0.8 (oblate start), then
# 0.7 and 0.6, each from the previous run's phase field, with [vesicle] topology_guard = true. Stops
# at the first run the guard rejects. About 20 s per run.
#   demos/shapes/oblate_v_continuation.sh [BUILD_DIR] [OUT_DIR]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${1:-build}
out=$(mkdir -p "${2:-$build/demo/oblate_v_continuation}" && cd "${2:-$build/demo/oblate_v_continuation}" && pwd)
previous=""
for v in ${VOLUMES:-0.8 0.7 0.6}; do
  scene="$out/v$v.toml"
  sed -e "s/^reduced_volume = 0.6/reduced_volume = $v/" -e '/^\[vesicle.adaptivity\]/,/^\]/d' \
      -e "s/^name = .*/name = \"v$v\"/" -e "s#^directory = .*#directory = \"$out/v$v\"#" \
      -e 's/^resolution_factor = 2.0 .*/&\ntopology_guard = true/' "$here/oblate_v06_torus.toml" > "$scene"
  if [[ -n "$previous" ]]; then
    sed -i -e '/^\[vesicle.initial\]/,/^center/d' "$scene"
    printf '\n[initial]\nphi = { file = "%s", field = "phi" }\n' "$previous" >> "$scene"
  fi
  status=0
  "$build/lmeform" run "$scene" --json "$out/v$v.json" > "$out/v$v.log" 2>&1 || status=$?
  /usr/bin/python3 - "$out/v$v.json" "$v" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print(f"v = {sys.argv[2]}  E = {r['energy']:.5f}  membrane: {r['topology']['summary']}  ({r['status']})")
PY
  [[ $status -eq 0 ]] || break
  previous="$out/v$v/v$v.h5"
done
