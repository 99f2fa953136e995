#!/usr/bin/env bash
# `lmeform run` on a small vesicle whose start is a torus with a hole narrower than the interface:
# the phase field closes it. The run must say so (the progress line, the closing row, a warning on
# stderr, the JSON's topology keys and warnings); with [vesicle] topology_guard = true it must stop
# with exit code 2, naming the change, and list the stage as rejected.
set -euo pipefail
lmeform=$1
out=$2
rm -rf "$out"
mkdir -p "$out"
write_scene() {  # $1: name, $2: extra [vesicle] line
  cat > "$out/$1.toml" <<TOML
[scene]
name = "$1"
coordinates = "axisymmetric"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.2]
[nodes]
spacing = 0.06
[model]
forms = ["helfrich_axisymmetric", "area_axisymmetric", "volume_axisymmetric"]
[constants]
eps = 0.14
[constraints]
area = {}
volume = {}
[[dirichlet]]
boundary = ["r_max", "z_min", "z_max"]
unknown = "phi"
value = -1.0
[solver]
augmented_tolerance = 1e-2
[initial]
phi = "tanh((0.22 - sqrt((x[0] - 0.3)^2 + (x[1] - 0.6)^2)) / (sqrt(2) * eps))"
[vesicle]
radius = 0.35
reduced_volume = 0.9
$2
[output]
directory = "$out/$1"
TOML
}
fail() { echo "FAIL: $*"; exit 1; }

write_scene warned ""
"$lmeform" run "$out/warned.toml" --json "$out/warned.json" > "$out/warned.log" 2> "$out/warned.err" || fail "the warned run failed"
cat "$out/warned.log" "$out/warned.err"
grep -q "the membrane (phi = 0) at the start: 1 component, genus 1 (a torus)" "$out/warned.log" || fail "no start topology"
grep -q "the membrane (phi = 0) after stage 0: 1 component, genus 0 (a sphere)" "$out/warned.log" || fail "no stage topology"
grep -q "membrane (phi = 0) *1 component, genus 0 (a sphere), CHANGED from the start's 1 component, genus 1 (a torus)" "$out/warned.log" ||
  fail "no closing row"
grep -q "lmeform: warning: the membrane's topology changed at stage 0: 1 component, genus 1 (a torus) -> 1 component, genus 0 (a sphere)" \
  "$out/warned.err" || fail "no warning on stderr"
/usr/bin/python3 - "$out/warned.json" <<'PY' || fail "the JSON"
import json, sys
r = json.load(open(sys.argv[1]))
assert r["topology_start"]["genus"] == [1], r["topology_start"]
assert r["topology"] == {"components": 1, "closed": [True], "genus": [0], "summary": "1 component, genus 0 (a sphere)"}, r["topology"]
assert r["stages"][0]["topology"]["genus"] == [0] and r["stages"][0]["rejected"] is False, r["stages"][0]
assert len(r["warnings"]) == 1 and "topology changed at stage 0" in r["warnings"][0], r.get("warnings")
PY

write_scene guarded "topology_guard = true"
set +e
"$lmeform" run "$out/guarded.toml" --json "$out/guarded.json" > "$out/guarded.log" 2>&1
code=$?
set -e
cat "$out/guarded.log"
[ "$code" -eq 2 ] || fail "exit code $code with the guard, expected 2"
grep -q "status *FAILED: stage 0: the membrane's topology changed: 1 component, genus 1 (a torus) -> 1 component, genus 0 (a sphere); vesicle.topology_guard rejects the stage" \
  "$out/guarded.log" || fail "the status does not name the change"
[ -s "$out/guarded/guarded.h5" ] || fail "the rejected stage was not written"
/usr/bin/python3 - "$out/guarded.json" <<'PY' || fail "the guarded JSON"
import json, sys
r = json.load(open(sys.argv[1]))
assert r["converged"] is False and r["stages"][0]["rejected"] is True, r["stages"][0]
assert "warnings" not in r, r.get("warnings")
PY
echo "PASS"
