#!/usr/bin/env bash
# Regenerates docs/kinetics.md section 3 (deflation at eps/R0 = 0.01): the static start at v = 0.9
# and the static discocyte at v = 0.8 at eps = 0.004 on interface-resolving grids (about 4.5 minutes
# each), the deflation v 0.9 -> 0.8 over t* = T for T = 0.01, 0.03, 0.1, each followed by
# relaxation at fixed volume until max_steps = 24 (15-20 minutes each), the tables and the plots.
# One rank, one run at a time. Run from the repository root.
#   demos/dynamics/run_fine_study.sh [lmeform-binary] [output-dir]
#   RATES="0.1" demos/dynamics/run_fine_study.sh ...     other deflation times
set -euo pipefail
lmeform=${1:-build/lmeform}
out=${2:-build/demo}
python=/usr/bin/python3
mkdir -p "$out" docs/figures

"$lmeform" run demos/dynamics/kinetics_fine_start.toml --output "$out/kinetics_fine_start" --json "$out/kinetics_fine_start.json"
"$lmeform" run demos/dynamics/kinetics_fine_equilibrium.toml --output "$out/kinetics_fine_equilibrium" --json "$out/kinetics_fine_equilibrium.json"

histories=()
labels=()
for until in ${RATES:-0.01 0.03 0.1}; do
  rate=$($python -c "print(-1.0 / 9.0 / $until)")
  dt=$($python -c "print(min(1e-3, $until / 50))")
  name=kinetics_fine_$until
  scene=$out/$name.toml
  sed -e "s/^V0 = .*/V0 = { rate = $rate, until = $until }/" -e "s/^report_times = .*/report_times = [$until]/" \
      -e "s/^dt = .*/dt = $dt/" -e "s/^name = .*/name = \"$name\"/" \
      -e "s#^directory = .*#directory = \"$out/$name\"#" \
      -e "s#\"../../build/demo/kinetics_fine_start/#\"$PWD/$out/kinetics_fine_start/#g" \
      demos/dynamics/kinetics_fine_deflation.toml > "$scene"
  "$lmeform" run "$scene" --json "$out/$name.json"
  histories+=("$out/$name/${name}_history.json")
  labels+=("deflation over t* = $until")
done
$python scripts/plot_dynamics.py "${histories[0]}" --out docs/figures/kinetics_fine --compare "${histories[@]:1}" \
  --labels "${labels[@]}" --mirror --snapshots 4 --max-energy-shapes \
  --equilibrium "$out/kinetics_fine_equilibrium/kinetics_fine_equilibrium.h5" \
  --reference-energy "$($python -c "import json; print(json.load(open('$out/kinetics_fine_equilibrium.json'))['energy'])")"
$python demos/dynamics/kinetics_fine_table.py "$out" ${RATES:-0.01 0.03 0.1}
