#!/usr/bin/env bash
# The adhesion demo (demos/adhesion) against its limits and its bad inputs:
#  * omega = 0: the energy equals that of the same scene without the adhesion term (relative 1e-10);
#  * a bound vesicle (R = 0.3, v = 0.9, k = 1, omega = 12, eps = 0.02): the meridian curvature of
#    the phi = 0 contour at the contact line (demos/adhesion/adhesion_common.py) within 10 % of
#    Seifert-Lipowsky's sqrt(2 w / kappa), w = 0.5148 omega, kappa = k / 4 (measured: 1.006; docs/adhesion.md);
#  * omega < 0, a wall cutting the initial vesicle and a scene without z_wall are refused before any
#    solve, with their messages (the form's `require` lines, the missing constant named).
#
#   test_adhesion_validation.sh LMEFORM OUT_DIR
set -euo pipefail
lmeform=$1
out=$2
demo=$(cd "$(dirname "$0")/../../demos/adhesion" && pwd)
python=/usr/bin/python3
rm -rf "$out"
mkdir -p "$out"

fail() {
  echo "FAIL: $*"
  exit 1
}

"$python" -c "import numpy, matplotlib, h5py" 2> /dev/null || { echo "SKIP: $python lacks numpy, matplotlib or h5py"; exit 77; }

# Scenes from the demo's (adhesion_common.make_scene): small ones for omega = 0 and the bad inputs.
"$python" - "$demo" "$out" <<'PY'
import sys
sys.path.insert(0, sys.argv[1])
import adhesion_common as ac
out = sys.argv[2]
small = dict(eps=0.06, radius=0.3, reduced_volume=0.9)
ac.make_scene(f"{out}/zero.toml", "zero", omega=0.0, **small)
ac.make_scene(f"{out}/free.toml", "free", omega=0.0, adhesion=False, **small)
ac.make_scene(f"{out}/bound.toml", "bound", omega=12.0, eps=0.02)
ac.make_scene(f"{out}/negative.toml", "negative", omega=-1.0, **small)
text = open(f"{out}/zero.toml").read()
open(f"{out}/cut.toml", "w").write(text.replace("z_wall = 0.0", "z_wall = 0.2").replace('name = "zero"', 'name = "cut"'))
open(f"{out}/nowall.toml", "w").write("\n".join(l for l in text.splitlines() if not l.startswith("z_wall")).replace('name = "zero"', 'name = "nowall"'))
PY
grep -q '^z_wall = 0.2' "$out/cut.toml" || fail "could not derive the scene with the wall through the vesicle"
grep -q '^z_wall' "$out/nowall.toml" && fail "could not derive the scene without z_wall"

for name in zero free bound; do
  "$lmeform" run "$out/$name.toml" --json "$out/$name.json" --output "$out/$name" > "$out/$name.log" 2>&1 ||
    { tail -20 "$out/$name.log"; fail "$name: lmeform run failed (log: $out/$name.log)"; }
done

"$python" - "$demo" "$out" <<'PY'
import json, sys
sys.path.insert(0, sys.argv[1])
import adhesion_common as ac
out = sys.argv[2]
zero, free, bound = (json.load(open(f"{out}/{n}.json")) for n in ("zero", "free", "bound"))
for name, r in (("omega = 0", zero), ("without adhesion", free), ("bound", bound)):
    if not r["converged"]:
        print(f"FAIL: {name}: {r['status']}")
        sys.exit(1)
diff = abs(zero["energy"] - free["energy"]) / abs(free["energy"])
print(f"omega = 0: {zero['energy']:.15f}, without the adhesion term: {free['energy']:.15f}, relative difference {diff:.1e}")
if not diff < 1e-10:
    print("FAIL: omega = 0 does not give the free vesicle's energy")
    sys.exit(1)
g = ac.contact_geometry(ac.membrane_contour(f"{out}/bound/bound.h5"), 0.02)
theory = ac.contact_curvature_theory(12.0, 1.0)
ratio = g["curvature"] / theory
print(f"bound vesicle ({bound['nodes']} nodes, {bound['wall_s']:.1f} s): contact curvature {g['curvature']:.4f}, "
      f"theory {theory:.4f}, ratio {ratio:.4f}")
if not abs(ratio - 1.0) < 0.10:
    print("FAIL: the contact curvature is not within 10 % of sqrt(2 w / kappa)")
    sys.exit(1)
PY

refused() {  # scene, a fixed string the message must contain
  local name=$1 message=$2
  if "$lmeform" run "$out/$name.toml" --output "$out/$name" > "$out/$name.log" 2>&1; then
    fail "$name: the scene was accepted"
  fi
  grep -qF -- "$message" "$out/$name.log" || { cat "$out/$name.log"; fail "$name: the message lacks '$message'"; }
  grep -q "KKT\|  AL " "$out/$name.log" && fail "$name: refused only after a solve started"
  echo "$name: refused: $(grep -F -- "$message" "$out/$name.log" | head -1)"
}
refused negative "the adhesion strength omega (the depth of the potential well) must be >= 0"
refused cut "the wall z = z_wall cuts the initial vesicle"
refused nowall "missing key 'constants.z_wall'"
echo PASS
