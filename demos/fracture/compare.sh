#!/usr/bin/env bash
# Fracture: single-edge-notched tension and shear with lmeform (LME) against FEniCSx (P1/P1, the same
# AT2 model, split, notch field and alternate minimization; demos/fracture/fenicsx_fracture.py).
#   demos/fracture/compare.sh [BUILD_DIR] [--quick]
# Default: l = 0.015 (sent.toml, sens.toml; hours for lmeform, about 20 minutes for FEniCSx).
# --quick: l = 0.03, the bands at spacing 0.015 (sens_coarse.toml and sent.toml made as coarse),
# FEniCSx with --l 0.03.
# 1. installs python3-dolfinx and python3-matplotlib (Debian 12 packages) when missing;
# 2. runs FEniCSx and lmeform on both cases into BUILD_DIR/compare/fracture/;
# 3. force_displacement.py overlays the curves (BUILD_DIR/compare/fracture_CASE.png) and writes the
#    records (peak force and where, wall time, alternations) to BUILD_DIR/compare/fracture.json;
#    the unknowns of each run are printed.
set -euo pipefail
build=${1:-build}
quick=0
[ "${2:-}" = "--quick" ] && quick=1
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source "$here/../../scripts/fenicsx-env.sh"

out="$build/compare/fracture"
mkdir -p "$out"
if [ "$quick" = 1 ]; then
  l=0.03
  h=0.015
  sed -e 's#spacing = 0.0075, width = 0.015#spacing = 0.015, width = 0.03#' -e 's#^l = 0.015#l = 0.03#' \
      -e 's#- 0.0075, 0)/l#- 0.015, 0)/l#' -e 's#^count = 125#count = 32#' \
      -e 's#^values = { delta = .*#ramp = { delta = [0.0, 0.008] }#' -e 's#^name = "sent"#name = "sent_coarse"#' \
      "$here/sent.toml" > "$out/sent.toml"
  grep -q '^ramp = { delta = \[0.0, 0.008\] }$' "$out/sent.toml" || { echo "could not make the coarse SENT scene" >&2; exit 1; }
  cp "$here/sens_coarse.toml" "$out/sens.toml"
else
  l=0.015
  h=0.0075
  cp "$here/sent.toml" "$out/sent.toml"
  cp "$here/sens.toml" "$out/sens.toml"
fi

for case in sent sens; do
  echo "== FEniCSx $case, l = $l"
  "$py" "$here/fenicsx_fracture.py" --case "$case" --l "$l" --out "$out"
  echo "== lmeform $case, l = $l"
  "$build/lmeform" run "$out/$case.toml" --output "$out/lmeform_$case" --json "$out/lmeform_$case.json" > "$out/lmeform_$case.log" 2>&1 ||
    { tail -20 "$out/lmeform_$case.log"; echo "lmeform run $out/$case.toml failed" >&2; exit 1; }
  "$py" "$here/force_displacement.py" "$out/lmeform_$case" "$case" "$build/compare" \
    --fenicsx "$out/fenicsx_fracture_${case}_l${l}.json" --l "$l" --h "$h"
  "$py" - "$out" "$case" "$l" <<'PY'
import glob, json, sys
import h5py
out, case, l = sys.argv[1], sys.argv[2], sys.argv[3]
f = json.load(open(f"{out}/fenicsx_fracture_{case}_l{l}.json"))
m = json.load(open(f"{out}/lmeform_{case}.json"))
field = [p for p in glob.glob(f"{out}/lmeform_{case}/*.h5") if not p.endswith("_checkpoint.h5")][0]
nodes = h5py.File(field, "r")["nodes"].shape[0]
print(f"{case}: FEniCSx {f['discretization']['unknowns']} unknowns, peak {f['peak_force']:.4f} kN at {f['delta_at_peak']:.5g} mm, "
      f"{f['wall_s']:.0f} s; lmeform {3 * nodes} unknowns ({nodes} nodes), {m['wall_s']:.0f} s")
PY
done
