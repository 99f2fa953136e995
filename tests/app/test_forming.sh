#!/usr/bin/env bash
# Viscoplastic flow with moving nodes (docs/forming.md):
#  1. the Norton-Hoff form at m = 1 (data/viscoplastic_colliding.toml) solves the same problem as its
#     Newtonian limit written as a linear form (data/stokes_symmetric_colliding.toml): equal errors
#     against the exact colliding flow to 1e-8; and its velocity error is within 25 % of the
#     built-in stokes form's (demos/colliding_flow.toml, SUPG-like alpha = 0, same nodes);
#  2. a small frictionless billet (121 nodes, 10 steps to 25 % height reduction) keeps its volume
#     to 0.1 %, its radius on R0 sqrt(h0/h) to 1 % and its plate force on pi R^2 sigma_bar to 1 %;
#  3. the same run stopped after step 5 and continued with --restart ends equal to the
#     uninterrupted one (plate force and radius to 1e-10); a step that needs more sub-steps than
#     allowed stops the run (exit code 2) with only the steps before it on disk, and --restart with
#     a larger allowance continues; a sticking run restarted from a checkpoint written after a
#     redistribution of its nodes equals the whole run;
#  4. bad input gets its message before any solve: m <= 0, K <= 0, a plate that would run through
#     the billet, a plate on no boundary part, a plate whose velocity no Dirichlet entry prescribes.
#
#   test_forming.sh LMEFORM OUT_DIR
set -euo pipefail
lmeform=$1
out=$2
here=$(cd "$(dirname "$0")" && pwd)
demos=$(cd "$here/../../demos" && pwd)
rm -rf "$out"
mkdir -p "$out"
fail() {
  echo "FAIL: $*"
  exit 1
}

# 1. The Newtonian limit.
"$lmeform" run "$here/data/viscoplastic_colliding.toml" --json "$out/nh.json" --output "$out/nh" > "$out/nh.log" 2>&1 ||
  { tail -20 "$out/nh.log"; fail "viscoplastic m = 1: lmeform run failed"; }
"$lmeform" run "$here/data/stokes_symmetric_colliding.toml" --json "$out/lin.json" --output "$out/lin" > "$out/lin.log" 2>&1 ||
  { tail -20 "$out/lin.log"; fail "the linear Newtonian limit: lmeform run failed"; }
sed -e 's#^counts = .*#counts = [17, 17]#' -e 's#^alpha = 1.0.*#alpha = 0.0#' "$demos/colliding_flow.toml" > "$out/stokes.toml"
"$lmeform" run "$out/stokes.toml" --json "$out/stokes.json" --output "$out/stokes" > "$out/stokes.log" 2>&1 ||
  { tail -20 "$out/stokes.log"; fail "built-in stokes: lmeform run failed"; }

# 2. and 3. A small frictionless billet, whole and restarted.
sed -e 's#^spacing = .*#spacing = 0.05#' -e 's#^count = .*#count = 10#' -e 's#^time_step = .*#time_step = 0.0125#' \
  "$demos/forming/upsetting_frictionless.toml" > "$out/billet.toml"
grep -q '^count = 10$' "$out/billet.toml" || fail "could not make the small billet"
"$lmeform" run "$out/billet.toml" --output "$out/whole" > "$out/whole.log" 2>&1 || { tail -20 "$out/whole.log"; fail "billet: lmeform run failed"; }
sed -e 's#^count = 10$#count = 10\nuntil = 5#' "$out/billet.toml" > "$out/billet_part.toml"
"$lmeform" run "$out/billet_part.toml" --output "$out/parts" > "$out/part1.log" 2>&1 || { tail -20 "$out/part1.log"; fail "billet to step 5 failed"; }
grep -q "stopped after step 5" "$out/part1.log" || { tail -5 "$out/part1.log"; fail "the run did not stop after step 5"; }
"$lmeform" run "$out/billet.toml" --output "$out/parts" --restart > "$out/part2.log" 2>&1 || { tail -20 "$out/part2.log"; fail "--restart failed"; }
grep -q "resumed from" "$out/part2.log" || fail "the restarted run does not say where it resumed"

/usr/bin/python3 - "$out" <<'PY'
import csv, json, math, sys
out = sys.argv[1]
ok = True
def check(cond, what):
    global ok
    print(("ok   " if cond else "FAIL ") + what)
    ok = ok and cond

nh, lin, st = (json.load(open(f"{out}/{n}.json")) for n in ("nh", "lin", "stokes"))
err = lambda r, u: next(e for e in r["errors"] if e["unknown"] == u)
for a, b in (("v", "u"), ("p", "p")):
    for norm in ("l2", "h1"):
        x, y = err(nh, a)[norm], err(lin, b)[norm]
        check(abs(x - y) <= 1e-8 * abs(y), f"m = 1 equals the linear Newtonian form: {a} {norm} {x:.10e} vs {y:.10e}")
x, y = err(nh, "v")["l2"], err(st, "u")["l2"]
check(x <= 1.25 * y, f"m = 1 velocity L2 error {x:.4e} within 25 % of the built-in stokes form's {y:.4e}")

rows = list(csv.DictReader(open(f"{out}/whole/history.csv")))
K, m, R0, h0, V = 1.0, 0.2, 0.5, 0.5, 1.0
V0 = float(rows[0]["volume"])
worst_r = worst_v = worst_f = 0.0
for r in rows:
    h = float(r["extent_max[1]"]) - float(r["extent_min[1]"])
    R = float(r["extent_max[0]"])
    sigma = math.sqrt(3) * K * (math.sqrt(3) * V / h) ** m
    worst_r = max(worst_r, abs(R / (R0 * math.sqrt(h0 / h)) - 1))
    worst_v = max(worst_v, abs(float(r["volume"]) / V0 - 1))
    worst_f = max(worst_f, abs(-float(r["force"]) / (math.pi * R * R * sigma) - 1))
h_end = float(rows[-1]["extent_max[1]"])
check(len(rows) == 11 and abs(h_end - 0.375) < 1e-12, f"10 steps to h = 0.375 (25 % reduction): {len(rows) - 1} steps, h = {h_end}")
check(worst_v < 1e-3, f"volume kept to 0.1 %: worst {worst_v:.2e}")
check(worst_r < 1e-2, f"radius on R0 sqrt(h0/h) to 1 %: worst {worst_r:.2e}")
check(worst_f < 1e-2, f"plate force on pi R^2 sigma_bar to 1 %: worst {worst_f:.2e}")

whole = list(csv.DictReader(open(f"{out}/whole/history.csv")))[-1]
parts = list(csv.DictReader(open(f"{out}/parts/history.csv")))
check(len(parts) == 11 and parts[-1]["step"] == "10", f"the restarted history has steps 0..10: {len(parts)} rows")
for key in ("force", "extent_max[0]", "volume"):
    a, b = float(whole[key]), float(parts[-1][key])
    check(abs(a - b) <= 1e-10 * abs(a), f"restarted = uninterrupted at step 10: {key} {a:.15g} vs {b:.15g}")
sys.exit(0 if ok else 1)
PY

# A step that cannot be taken (more sub-steps than allowed) stops the run with the last step on disk,
# exit code 2, nothing of the failed step applied; --restart with a larger allowance continues.
sed -e 's#^count = 10$#count = 4#' -e 's#^time_step = .*#time_step = 0.05#' -e 's#^plates = #max_substeps = 1\nplates = #' \
  "$out/billet.toml" > "$out/cut.toml"
grep -q '^max_substeps = 1$' "$out/cut.toml" || fail "could not make the sub-step scene"
set +e
"$lmeform" run "$out/cut.toml" --output "$out/cut" > "$out/cut1.log" 2>&1
code=$?
set -e
[ "$code" = 2 ] || { tail -5 "$out/cut1.log"; fail "a failed step: exit code $code, expected 2"; }
grep -q "step 1 (time 0.05): more than 1 sub-steps (max_substeps).*step 0 is the last on disk" "$out/cut1.log" ||
  { grep status "$out/cut1.log"; fail "no message naming the failed step and the last one on disk"; }
[ "$(grep -c '' "$out/cut/history.csv")" = 2 ] || fail "the history holds more than step 0 after the failed step 1"
echo "ok   a step needing more sub-steps than allowed stops the run at step 0, exit code 2"
sed -e 's#^max_substeps = 1$#max_substeps = 4#' "$out/cut.toml" > "$out/cut_more.toml"
"$lmeform" run "$out/cut_more.toml" --output "$out/cut" --restart > "$out/cut2.log" 2>&1 || { tail -5 "$out/cut2.log"; fail "--restart after the failed step"; }
grep -q "resumed from .* at step 0" "$out/cut2.log" || fail "the restart did not resume from step 0"
[ "$(grep -c '' "$out/cut/history.csv")" = 6 ] || fail "the restarted run does not reach step 4 (history: header + steps 0..4)"
grep -qE "^step    4/4 .* substeps [2-4] " "$out/cut2.log" || { grep "^step" "$out/cut2.log" | cut -c1-80; fail "the restarted steps were not cut"; }
echo "ok   --restart with max_substeps = 4 continues to step 4, each step cut into sub-steps"

# A sticking billet whose nodes are redistributed (threshold lowered to 1.5: at steps 7 and 9), stopped
# after step 8 and restarted from a checkpoint on the redistributed nodes, ends equal to the whole run.
sed -e 's#^spacing = .*#spacing = 0.05#' -e 's#^count = .*#count = 10#' -e 's#^time_step = .*#time_step = 0.0125#' \
  -e 's#^plates = #redistribute_anisotropy = 1.5\nplates = #' "$demos/forming/upsetting_sticking.toml" > "$out/sticking.toml"
"$lmeform" run "$out/sticking.toml" --output "$out/sticking_whole" > "$out/sticking_whole.log" 2>&1 ||
  { tail -5 "$out/sticking_whole.log"; fail "the small sticking billet failed"; }
grep -q "redistributed the nodes" "$out/sticking_whole.log" || fail "the small sticking billet was not redistributed"
sed -e 's#^count = 10$#count = 10\nuntil = 8#' "$out/sticking.toml" > "$out/sticking_part.toml"
"$lmeform" run "$out/sticking_part.toml" --output "$out/sticking_parts" > "$out/sticking_part1.log" 2>&1 || fail "sticking to step 8"
"$lmeform" run "$out/sticking.toml" --output "$out/sticking_parts" --restart > "$out/sticking_part2.log" 2>&1 || fail "sticking --restart"
/usr/bin/python3 - "$out" <<'PY' || fail "restarted after a redistribution differs from the whole run"
import csv, sys
out = sys.argv[1]
whole = list(csv.DictReader(open(f"{out}/sticking_whole/history.csv")))[-1]
parts = list(csv.DictReader(open(f"{out}/sticking_parts/history.csv")))[-1]
differ = [k for k in whole if not k.endswith("_s") and whole[k] != parts[k]]  # clocks aside
print("      differing columns:", differ or "none")
sys.exit(1 if differ or whole["redistributions"] != "2" else 0)
PY
echo "ok   a sticking run restarted after a redistribution ends equal to the whole run (every column but the clocks)"

# 4. Bad input.
expect_error() {  # NAME MESSAGE ARGS...
  local name=$1 message=$2
  shift 2
  if "$lmeform" run "$@" --output "$out/bad_$name" > "$out/bad_$name.log" 2>&1; then fail "$name: the run was accepted"; fi
  grep -q -- "$message" "$out/bad_$name.log" || { cat "$out/bad_$name.log"; fail "$name: no message '$message'"; }
  ! grep -q "^step    1" "$out/bad_$name.log" || fail "$name: steps were taken before the refusal"
  echo "ok   bad input $name: $message"
}
expect_error m_zero "rate sensitivity m of the Norton-Hoff law lies in (0, 1]" "$out/billet.toml" --set m=0
expect_error k_negative "consistency K of the Norton-Hoff law must be positive" "$out/billet.toml" --set K=-1
sed -e 's#^time_step = .*#time_step = 0.1#' "$out/billet.toml" > "$out/through.toml"
expect_error through_the_billet "through the whole body" "$out/through.toml"
sed -e 's#part = "z_max", axis = 1#part = "z_top", axis = 1#' "$out/billet.toml" > "$out/no_part.toml"
expect_error no_part "plate part 'z_top' is no boundary part of the domain" "$out/no_part.toml"
sed -e 's#part = "z_max", axis = 1#part = "z_max", axis = 0#' "$out/billet.toml" > "$out/no_velocity.toml"
expect_error unheld_plate "prescribes v\[0\]" "$out/no_velocity.toml"
echo "PASS"
