#!/usr/bin/env bash
# The 2D fracture studies of docs/fracture.md, one after the other (hours on 2 cores; make bench
# runs only the 1D study, gamma_convergence.py --quick): SENT and SENS force-displacement, surfing
# with AT2 and AT1 (and AT2 on nested grids, against FEniCSx on the same strip), the anisotropic crack at three orientations, SENT on nodes that follow the
# crack, SENT to complete failure (sent_fast.toml) and SENS at l = 0.015 on following nodes (40 equal steps,
# and steps of 2e-5 near the peak: sens_fine_steps.toml), and SENT and SENS at l = 0.0075 (sent_l0.0075.toml,
# sens_l0.0075.toml).
# Records go to BUILD/bench/fracture.json, figures next to it.
#   demos/fracture/run_study.sh [BUILD]
set -euo pipefail
build=${1:-build}
lmeform="$build/lmeform"
out="$build/bench"
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
/usr/bin/python3 "$here/gamma_convergence.py" "$lmeform" "$out"
for case in surfing surfing_at1 surfing_grids; do
  "$lmeform" run "$here/$case.toml" --output "$build/demo/fracture/$case"
  /usr/bin/python3 "$here/surfing.py" "$build/demo/fracture/$case" --out "$out" --case "$case"
done
# The same strip on linear elements (FEniCSx): the effective toughness Gc (1 + h/(2l)) the surfing
# records take as their reference, at h = l/2, l/4, l/8 (about 10 minutes), and the opening test.
source "$here/../../scripts/fenicsx-env.sh"
for h in 0.01 0.005 0.0025; do
  "$py" "$here/fenicsx_surfing.py" --h "$h" --out "$out/fenicsx_surfing_h$h.json"
  "$py" "$here/fenicsx_opening.py" --h "$h" --out "$out/fenicsx_opening_h$h.json"
done
for deg in 0 20 45; do
  rad=$(/usr/bin/python3 -c "import math; print(math.radians($deg))")
  "$lmeform" run "$here/anisotropic.toml" --set "theta0=$rad" --output "$build/demo/fracture/anisotropic_$deg"
  /usr/bin/python3 "$here/anisotropy.py" record "$build/demo/fracture/anisotropic_$deg" "$deg" "$out"
done
for case in sent sens; do
  "$lmeform" run "$here/$case.toml" --output "$build/demo/fracture/$case"
  /usr/bin/python3 "$here/force_displacement.py" "$build/demo/fracture/$case" "$case" "$out"
done
"$lmeform" run "$here/sent_adaptive.toml" --output "$build/demo/fracture/sent_adaptive"
/usr/bin/python3 "$here/adaptive_sent.py" "$build/demo/fracture/sent_adaptive" "$out" --fixed "$build/demo/fracture/sent" \
  --fenicsx "$here/fenicsx_fracture_sent_l0.015.json"
# SENT to complete failure on 2 ranks (compact support, over-relaxed alternation) and SENS at
# l = 0.015 on nodes that follow the crack; force records ("sent", "sens") with the FEniCSx peaks.
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun -n 2 "$lmeform" run "$here/sent_fast.toml" --output "$build/demo/fracture/sent_fast"
/usr/bin/python3 "$here/force_displacement.py" "$build/demo/fracture/sent_fast" sent "$out" --fenicsx "$here/fenicsx_fracture_sent_l0.015.json" --l 0.015 --h 0.0075
# The same on nested grids aligned with y = 0.5 (h = 0.00625 there).
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun -n 2 "$lmeform" run "$here/sent_grids.toml" --output "$build/demo/fracture/sent_grids"
/usr/bin/python3 "$here/force_displacement.py" "$build/demo/fracture/sent_grids" sent "$out" --fenicsx "$here/fenicsx_fracture_sent_l0.015.json" --l 0.015 --h 0.00625
"$lmeform" run "$here/sens_adaptive.toml" --output "$build/demo/fracture/sens_adaptive"
/usr/bin/python3 "$here/force_displacement.py" "$build/demo/fracture/sens_adaptive" sens "$out" --fenicsx "$here/fenicsx_fracture_sens_l0.015.json" --l 0.015 --h 0.006
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun -n 2 "$lmeform" run "$here/sens_fine_steps.toml" --output "$build/demo/fracture/sens_fine_steps"
/usr/bin/python3 "$here/force_displacement.py" "$build/demo/fracture/sens_fine_steps" sens "$out" --fenicsx "$here/fenicsx_fracture_sens_l0.015.json" --l 0.015 --h 0.006
# SENT at l = 0.0075 on nodes that follow the crack, against FEniCSx's run at that l.
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun -n 2 "$lmeform" run "$here/sent_l0.0075.toml" --output "$build/demo/fracture/sent_l0.0075"
/usr/bin/python3 "$here/force_displacement.py" "$build/demo/fracture/sent_l0.0075" sent "$out" --fenicsx "$here/fenicsx_fracture_sent_l0.0075.json" --l 0.0075 --h 0.003
# SENS at l = 0.0075 on nodes that follow the crack (a "sens" record at that l; no FEniCSx run at it).
# It stops at step 190, where the u Newton stagnates (docs/fracture.md): the record is made from the
# converged steps it kept on disk.
OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun -n 2 "$lmeform" run "$here/sens_l0.0075.toml" --output "$build/demo/fracture/sens_l0.0075" ||
  echo "sens_l0.0075 stopped before its last step; recording the steps it converged"
/usr/bin/python3 "$here/force_displacement.py" "$build/demo/fracture/sens_l0.0075" sens "$out" --l 0.0075 --h 0.003
