#!/usr/bin/env bash
# Bad input is refused before any work, with a message naming the file, the line or key and the
# reason: nodes outside the domain, unwritable outputs, constants the forms do not have, a missing
# constant, an unknown output, an expression that does not compile.
set -euo pipefail
lmeform=$1
out=$2
rm -rf "$out"
mkdir -p "$out"
export LMEFORM_CACHE_DIR="$out/cache"
fail() { echo "FAIL: $*"; exit 1; }

# expect_error NAME SCENE_TEXT PATTERN... : lmeform run exits 1 and stderr matches every pattern.
expect_error() {
  local name=$1 text=$2
  shift 2
  printf '%s\n' "$text" > "$out/$name.toml"
  set +e
  "$lmeform" run "$out/$name.toml" --output "$out/$name-result" > "$out/$name.out" 2> "$out/$name.err"
  local code=$?
  set -e
  [ "$code" -eq 1 ] || { cat "$out/$name.out" "$out/$name.err"; fail "$name: exit code $code, expected 1"; }
  for pattern in "$@"; do
    grep -q -- "$pattern" "$out/$name.err" || { cat "$out/$name.err"; fail "$name: the message lacks '$pattern'"; }
  done
  grep -q "== solve" "$out/$name.out" && fail "$name: the run started before the error"
  echo "ok   $name: $(head -c 300 "$out/$name.err" | tr '\n' ' ')"
}

heat='[scene]
name = "heat"
coordinates = "cartesian"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.0]
[model]
forms = ["poisson"]
[[dirichlet]]
boundary = ["hull"]
unknown = "T"
value = 0.0'

printf '0.1, 0.1\n# a comment\n0.5, 0.5\n2.5, 7.0\n' > "$out/outside.txt"
expect_error nodes_outside "$heat
[nodes]
file = \"outside.txt\"" "outside.txt:4" "lies outside the domain" "nodes.file"

expect_error unknown_constant "$heat
[nodes]
spacing = 0.25
[constants]
kapa = 1.0" "key 'constants.kapa'" "no form of the problem has a constant 'kapa'"

expect_error unknown_output "${heat/forms = \[\"poisson\"\]/forms = [\"poisson\"]
energy = \"haet\"}
[nodes]
spacing = 0.25" "key 'model.energy'" "did you mean 'heat'"

expect_error missing_constant '[scene]
name = "bending"
coordinates = "cartesian"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.0]
[nodes]
spacing = 0.25
[model]
forms = ["helfrich"]' "missing key 'constants.eps'" "helfrich"

expect_error did_you_mean_constant '[scene]
name = "bending"
coordinates = "cartesian"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.0]
[nodes]
spacing = 0.25
[model]
forms = ["helfrich"]
[constants]
eps = 0.5
kk = 2.0' "did you mean 'k'" "the forms' constants: k, eps, C0"

expect_error bad_expression "$heat
[nodes]
spacing = 0.25
[initial]
T = \"sin(pi*y[0])\"" "key 'initial.T'" "does not compile"

expect_error bad_dirichlet_part "${heat/boundary = \[\"hull\"\]/boundary = [\"x_mni\"]}
[nodes]
spacing = 0.25" "key 'dirichlet\[0\].boundary'" "did you mean 'x_min'"

# Outputs that cannot be written are refused before the run.
printf '%s\n[nodes]\nspacing = 0.25\n' "$heat" > "$out/good.toml"
set +e
"$lmeform" run "$out/good.toml" --json "$out/no/such/folder/run.json" --output "$out/good" > "$out/json.out" 2> "$out/json.err"
code=$?
set -e
[ "$code" -eq 1 ] || fail "an unwritable --json: exit code $code"
grep -q "does not exist" "$out/json.err" || { cat "$out/json.err"; fail "the --json message does not say why"; }
grep -q "== solve" "$out/json.out" && fail "the run started before the --json check"
echo "ok   unwritable --json: $(cat "$out/json.err")"
touch "$out/a_file"
set +e
"$lmeform" run "$out/good.toml" --output "$out/a_file/result" > "$out/dir.out" 2> "$out/dir.err"
code=$?
set -e
[ "$code" -eq 1 ] || fail "an unwritable output directory: exit code $code"
grep -q "cannot be created or written" "$out/dir.err" || { cat "$out/dir.err"; fail "the output-directory message does not say why"; }
echo "ok   unwritable output directory: $(cat "$out/dir.err")"
# A vesicle's area target scheduled beyond what the box can hold (demos/dynamics/area_overfill.toml,
# ten times the area of a circle at eps = 0.08): refused before the first time step.
demos=$(cd "$(dirname "$0")/../../demos" && pwd)
set +e
"$lmeform" run "$demos/dynamics/area_overfill.toml" --output "$out/overfill" > "$out/overfill.out" 2> "$out/overfill.err"
code=$?
set -e
[ "$code" -eq 1 ] || { tail -3 "$out/overfill.out"; fail "an over-filling area schedule: exit code $code, expected 1"; }
grep -q "dynamics.schedule.A0': the schedule takes the area target to A0 = 15.6.*more membrane than the domain can hold" "$out/overfill.err" ||
  { cat "$out/overfill.err"; fail "the over-filling schedule's message"; }
[ ! -e "$out/overfill/history.json" ] || fail "the over-filling run wrote a history"
echo "ok   over-filling area schedule: $(cat "$out/overfill.err")"
echo "PASS"
