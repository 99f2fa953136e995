#!/usr/bin/env bash
# Reproduces rows of the seed's Table 1 (discocyte, uniform grids) with lmeform run and writes
# a Markdown table of energies and differences to docs/results_table1.md.
#   demos/reproduce_table1.sh [BUILD_DIR] [ROWS...]   rows as SPACING:EPS, default the O1 row
set -euo pipefail
build=${1:-build}
shift || true
rows=("$@")
[ ${#rows[@]} -eq 0 ] && rows=("0.024:0.05" "0.024:0.04")
declare -A published=(["0.024:0.05"]=9.71279 ["0.024:0.04"]=9.59056 ["0.017:0.05"]=9.72137 ["0.017:0.04"]=9.59446
                      ["0.017:0.03"]=9.43775 ["0.012:0.05"]=9.72671 ["0.012:0.04"]=9.59553 ["0.012:0.03"]=9.43483
                      ["0.012:0.02"]=9.29532)
out=$build/table1
mkdir -p "$out"
table="| grid spacing | eps | nodes | energy (lmeform) | Table 1 | difference | sharp-interface error | wall s |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n"
for row in "${rows[@]}"; do
  h=${row%%:*}; eps=${row##*:}
  scene=$out/discocyte_h${h}_eps${eps}.toml
  sed -e "s/^spacing = .*/spacing = $h/" -e "s/^eps = .*/eps = $eps/" \
      -e "s|^directory = .*|directory = \"$out/h${h}_eps${eps}\"|" \
      -e "s/^quadrature_points = .*/quadrature_points = 6\nresolution_factor = 1.6   # Table 1 itself uses eps = 1.67 h/" \
      demos/discocyte.toml > "$scene"
  "$build/lmeform" run "$scene" --json "$out/h${h}_eps${eps}.json" > "$out/h${h}_eps${eps}.log"
  read -r nodes energy wall < <(/usr/bin/python3 -c "import json,sys; d=json.load(open('$out/h${h}_eps${eps}.json')); print(d['nodes'], d['energy'], d['wall_s'])")
  ref=${published[$row]:-}
  diff=$( [ -n "$ref" ] && /usr/bin/python3 -c "print(f'{100*($energy-$ref)/$ref:+.3f} %')" || echo "-")
  sharp=$(/usr/bin/python3 -c "print(f'{100*($energy-9.12657)/9.12657:+.2f} %')")
  table+="| $h | $eps | $nodes | $(printf %.5f "$energy") | ${ref:--} | $diff | $sharp | $(printf %.0f "$wall") |\n"
  echo "h $h eps $eps: E = $energy (Table 1: ${ref:--})"
done
{
  echo "# Table 1 rows (discocyte, uniform grids)"
  echo
  echo "Regenerate: \`demos/reproduce_table1.sh build 0.024:0.05 0.024:0.04\` (after \`make build\`)."
  echo "The seed's grids are not exactly uniform (O1: 6124 nodes, mean h = 0.024); ours are uniform grids of"
  echo "the given spacing on [0, 1.5] x [0, 2], gamma = 0.8, 6-point rule per Delaunay triangle."
  echo
  printf '%b' "$table"
} > docs/results_table1.md
cat docs/results_table1.md
