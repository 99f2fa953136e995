#!/usr/bin/env bash
# The 2D fracture studies of docs/fracture.md, one after the other (hours on 2 cores; make bench
# runs only the 1D study, gamma_convergence.py --quick): SENT and SENS force-displacement, surfing
# with AT2 and AT1, the anisotropic crack at three orientations, SENT on nodes that follow the
# crack. Records go to BUILD/bench/fracture.json, figures next to it.
#   demos/fracture/run_study.sh [BUILD]
set -euo pipefail
build=${1:-build}
lmeform="$build/lmeform"
out="$build/bench"
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
/usr/bin/python3 "$here/gamma_convergence.py" "$lmeform" "$out"
for case in surfing surfing_at1; do
  "$lmeform" run "$here/$case.toml" --output "$build/demo/fracture/$case"
  /usr/bin/python3 "$here/surfing.py" "$build/demo/fracture/$case" --out "$out" --case "$case"
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
