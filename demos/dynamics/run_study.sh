#!/usr/bin/env bash
# Regenerates the dynamics results of docs/dynamics.md: the oblate relaxation (VTI, adaptive dt) and
# its static equilibrium on the same grid, the kinetics of deflation at three rates, seed Table 3.3
# in form (bench_dynamics, full mode), and the plots. Run from the repository root after `make build`.
#   demos/dynamics/run_study.sh [build-dir]             (about 90 minutes on one core)
#   demos/dynamics/run_study.sh build --prolate         also the prolate after C0 R0 = 10 (hours, two ranks)
#   demos/dynamics/run_study.sh build --stomatocyte     also the stomatocyte -> discocyte (about 30 minutes, two ranks)
set -euo pipefail
build=${1:-build}
options=" ${*:2} "
for option in "${@:2}"; do
  [[ "$option" == --prolate || "$option" == --stomatocyte ]] || { echo "run_study.sh: unknown option '$option' (--prolate, --stomatocyte)" >&2; exit 2; }
done
lmeform=$build/lmeform
out=$build/demo
mkdir -p "$out" docs/figures
python=/usr/bin/python3

"$lmeform" run demos/dynamics/oblate_relaxation.toml --json "$out/oblate_relaxation.json"
"$lmeform" run demos/dynamics/oblate_equilibrium.toml --json "$out/oblate_equilibrium.json"
reference=$($python -c "import json; print(json.load(open('$out/oblate_equilibrium.json'))['energy'])")
$python scripts/plot_dynamics.py "$out/oblate_relaxation/oblate_relaxation_history.json" --out docs/figures/oblate_relaxation \
  --reference-energy "$reference" --mirror --snapshots 4

# The same relaxation to t* = 40, and the static solve on grids refined twice (its converged value).
sed -e 's/^t_end = .*/t_end = 40.0/' -e 's/^dt_max = .*/dt_max = 2.0/' -e 's/^name = .*/name = "oblate_relaxation_long"/' \
    -e "s#^directory = .*#directory = \"$out/oblate_relaxation_long\"#" demos/dynamics/oblate_relaxation.toml > "$out/oblate_relaxation_long.toml"
"$lmeform" run "$out/oblate_relaxation_long.toml" --json "$out/oblate_relaxation_long.json"
for spacing in 0.0125 0.00625; do
  sed -e "s/^spacing = .*/spacing = $spacing/" -e "s/^name = .*/name = \"oblate_equilibrium_$spacing\"/" \
      -e "s#^directory = .*#directory = \"$out/oblate_equilibrium_$spacing\"#" demos/dynamics/oblate_equilibrium.toml > "$out/oblate_equilibrium_$spacing.toml"
  "$lmeform" run "$out/oblate_equilibrium_$spacing.toml" --json "$out/oblate_equilibrium_$spacing.json"
done
converged=$($python -c "import json; print(json.load(open('$out/oblate_equilibrium_0.00625.json'))['energy'])")
$python scripts/plot_dynamics.py "$out/oblate_relaxation_long/oblate_relaxation_long_history.json" --out docs/figures/oblate_relaxation_long \
  --reference-energy "$converged" --mirror --snapshots 4

# Kinetics: v = 0.9 -> 0.8 over t* = 0.001 ... 10, then relaxation at fixed volume (eps = 0.025 on
# an adapted grid), and the static equilibrium at v = 0.8 they relax to.
"$lmeform" run demos/dynamics/kinetics_start.toml --json "$out/kinetics_start.json"
"$lmeform" run demos/dynamics/kinetics_equilibrium.toml --json "$out/kinetics_equilibrium.json"
histories=()
labels=()
for until in 0.001 0.01 0.1 1 10; do
  rate=$($python -c "print(-1.0 / 9.0 / $until)")
  dt=$($python -c "print(min(1e-3, $until / 50))")
  scene=$out/kinetics_$until.toml
  sed -e "s/^V0 = .*/V0 = { rate = $rate, until = $until }/" -e "s/^report_times = .*/report_times = [$until]/" \
      -e "s/^dt = .*/dt = $dt/" -e "s/^name = .*/name = \"kinetics_$until\"/" \
      -e "s#^directory = .*#directory = \"$out/kinetics_$until\"#" \
      -e "s#\"../../build/demo/#\"$PWD/$out/#g" demos/dynamics/kinetics_deflation.toml > "$scene"
  "$lmeform" run "$scene" --json "$out/kinetics_$until.json"
  histories+=("$out/kinetics_$until/kinetics_${until}_history.json")
  labels+=("deflation over t* = $until")
done
$python scripts/plot_dynamics.py "${histories[0]}" --out docs/figures/kinetics --compare "${histories[@]:1}" \
  --labels "${labels[@]}" --mirror --snapshots 4 --max-energy-shapes \
  --equilibrium "$out/kinetics_equilibrium/kinetics_equilibrium.h5" \
  --reference-energy "$($python -c "import json; print(json.load(open('$out/kinetics_equilibrium.json'))['energy'])")"

"$build"/tests/app/bench_dynamics --out "$build/bench"
"$build"/tests/app/bench_dynamics --out "$build/bench" -window 0.3 0.4

# The prolate v = 0.8 after a jump of spontaneous curvature to C0 R0 = 10: its static start at
# eps = 0.01 on an adapted grid, then the dynamics with resets and re-meshes to the budded shape.
if [[ "$options" == *" --prolate "* ]]; then
  mpirun -n 2 "$lmeform" run demos/dynamics/prolate_start.toml --json "$out/prolate_start.json"
  mpirun -n 2 "$lmeform" run demos/dynamics/prolate_c0_jump.toml --json "$out/prolate_c0_jump.json"
  $python scripts/plot_dynamics.py "$out/prolate_c0_jump/prolate_c0_jump_history.json" --out docs/figures/prolate_eps01 \
    --snapshots 4 --mirror
fi

# The stomatocyte at v = 0.6 squeezed along its axis past the barrier and let go; the static
# stomatocyte it starts from and the static discocyte it should reach.
if [[ "$options" == *" --stomatocyte "* ]]; then
  "$lmeform" run demos/dynamics/stomatocyte_start.toml --output "$out/stomatocyte_start" --json "$out/stomatocyte_start.json"
  "$lmeform" run demos/dynamics/discocyte_v06.toml --output "$out/discocyte_v06" --json "$out/discocyte_v06.json"
  sed -e "s#\"../../build/demo/#\"$PWD/$out/#g" -e "s#^directory = .*#directory = \"$out/stomatocyte_discocyte\"#" \
      -e "s#axial_trap_lagrangian_axisymmetric.form#$PWD/demos/dynamics/axial_trap_lagrangian_axisymmetric.form#" \
      demos/dynamics/stomatocyte_discocyte.toml > "$out/stomatocyte_discocyte.toml"
  mpirun -n 2 "$lmeform" run "$out/stomatocyte_discocyte.toml" --json "$out/stomatocyte_discocyte.json"
  $python scripts/plot_dynamics.py "$out/stomatocyte_discocyte/stomatocyte_discocyte_history.json" \
    --out docs/figures/stomatocyte_discocyte --snapshots 5 --mirror \
    --equilibrium "$out/discocyte_v06/discocyte_v06.h5" \
    --reference-energy "$($python -c "import json; print(json.load(open('$out/discocyte_v06.json'))['energy'])")"
fi
