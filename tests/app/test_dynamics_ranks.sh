#!/usr/bin/env bash
# The oblate-relaxation demo (demos/dynamics/oblate_relaxation.toml) on a coarse box for a short
# run: 1 and 2 MPI ranks take the same steps and reach the same energy to 1e-9 (relative); the run
# writes its XDMF time series and history; --restart resumes from the checkpoint and ends where the
# uninterrupted run ends; --restart of a scene without [dynamics] is refused; [solver] monitor prints
# the Newton iterations of each step. The same with resets of the reference configuration (the
# carried quadrature points split over the ranks), resumed on 1 rank from a 2-rank checkpoint.
#
#   test_dynamics_ranks.sh LMEFORM OUT_DIR
set -euo pipefail
lmeform=$1
out=$2
demos=$(cd "$(dirname "$0")/../../demos" && pwd)
rm -rf "$out"
mkdir -p "$out"
fail() {
  echo "FAIL: $*"
  exit 1
}
sed -e 's/^upper = \[1.0, 1.6\]/upper = [1.0, 1.5]/' -e 's/^spacing = 0.025/spacing = 0.0625/' -e 's/^eps = 0.05/eps = 0.125/' \
    -e 's/0\.8)/0.75)/g' -e 's/^t_end = .*/t_end = 0.01/' -e 's/^dt = .*/dt = 1e-3/' -e 's/^output_every = .*/output_every = 4\ncheckpoint_every = 5/' \
    "$demos/dynamics/oblate_relaxation.toml" > "$out/oblate.toml"
grep -q '^spacing = 0.0625$' "$out/oblate.toml" || fail "could not make the smaller scene"

"$lmeform" run "$out/oblate.toml" --json "$out/one.json" --output "$out/one" > "$out/one.log" 2>&1 ||
  { tail -20 "$out/one.log"; fail "1 rank: lmeform run failed"; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
# The 2-rank run also prints its Newton iterations ([solver] monitor), which must not change them.
{ cat "$out/oblate.toml"; printf '\n[solver]\nmonitor = true\n'; } > "$out/oblate_monitor.toml"
mpirun -n 2 "$lmeform" run "$out/oblate_monitor.toml" --json "$out/two.json" --output "$out/two" > "$out/two.log" 2>&1 ||
  { tail -20 "$out/two.log"; fail "2 ranks: lmeform run failed"; }
grep -q "^ KKT    0  E" "$out/two.log" || fail "[solver] monitor printed no Newton iterations"
grep -q "^ KKT" "$out/one.log" && fail "Newton iterations printed without [solver] monitor"
for f in one/oblate_relaxation.xmf one/oblate_relaxation_history.json one/series/oblate_relaxation_000000.h5 \
         one/series/oblate_relaxation_000004.h5 one/oblate_relaxation_checkpoint.h5; do
  [ -s "$out/$f" ] || fail "missing output $f"
done
grep -q 'CollectionType="Temporal"' "$out/one/oblate_relaxation.xmf" || fail "the .xmf is no time series"
grep -q "closing\|total wall time" "$out/one.log" || fail "no closing table"
# Resume: keep the checkpoint of step 5 and the history, drop what came after, run on.
mkdir -p "$out/resumed"
cp "$out/one/oblate_relaxation_checkpoint.h5" "$out/resumed/"
"$lmeform" run "$out/oblate.toml" --output "$out/resumed" --restart --json "$out/resumed.json" > "$out/resumed.log" 2>&1 &&
  fail "--restart without the history was accepted"
grep -q "no checkpoint" "$out/resumed.log" || { cat "$out/resumed.log"; fail "no message for a missing history"; }
if "$lmeform" run "$demos/poiseuille.toml" --restart --output "$out/p" > "$out/p.log" 2>&1; then fail "--restart of a static scene was accepted"; fi
grep -q "has none" "$out/p.log" || { cat "$out/p.log"; fail "no message for --restart of a static scene"; }

/usr/bin/python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
one, two = (json.load(open(f"{out}/{n}.json")) for n in ("one", "two"))
ok = True
if one["steps"] != two["steps"]:
    print(f"FAIL: 1 rank took {one['steps']} steps, 2 ranks {two['steps']}"); ok = False
d = abs(one["energy"] - two["energy"]) / abs(one["energy"])
print(f"energy 1 rank {one['energy']:.12f}, 2 ranks {two['energy']:.12f}, relative difference {d:.2e}")
if d > 1e-9:
    print("FAIL: the energies differ"); ok = False
if not one["energy"] < one["energy_start"]:
    print("FAIL: the energy did not decrease"); ok = False
for name, drift in one["max_relative_drift"].items():
    print(f"drift of {name}: {drift:.2e}")
    if drift > 1e-10:
        print(f"FAIL: {name} drifts"); ok = False
sys.exit(0 if ok else 1)
PY
# Resets of the reference configuration every third step: the carried quadrature points are split
# over the ranks (each keeps its cells' points), and 1, 2 and 4 ranks still agree; a checkpoint written
# after a reset on 2 ranks resumes on 1 and ends where the uninterrupted run ends.
sed -e 's/^dt_max = .*/dt_max = 1e-3/' -e 's/^t_end = .*/t_end = 0.012/' -e 's/^output_every = .*/output_every = 5\nreset_every = 3/' \
    "$out/oblate.toml" > "$out/reset.toml"
grep -q '^reset_every = 3$' "$out/reset.toml" || fail "could not make the reset scene"
sed 's/^t_end = .*/t_end = 0.006/' "$out/reset.toml" > "$out/reset_half.toml"
"$lmeform" run "$out/reset.toml" --json "$out/reset_1.json" --output "$out/reset_1" > "$out/reset_1.log" 2>&1 ||
  { tail -20 "$out/reset_1.log"; fail "resets on 1 rank"; }
mpirun -n 2 "$lmeform" run "$out/reset.toml" --json "$out/reset_2.json" --output "$out/reset_2" > "$out/reset_2.log" 2>&1 ||
  { tail -20 "$out/reset_2.log"; fail "resets on 2 ranks"; }
mpirun -n 4 "$lmeform" run "$out/reset.toml" --json "$out/reset_4.json" --output "$out/reset_4" > "$out/reset_4.log" 2>&1 ||
  { tail -20 "$out/reset_4.log"; fail "resets on 4 ranks"; }
mpirun -n 2 "$lmeform" run "$out/reset_half.toml" --output "$out/reset_resumed" > "$out/reset_half.log" 2>&1 ||
  { tail -20 "$out/reset_half.log"; fail "the first half with resets on 2 ranks"; }
"$lmeform" run "$out/reset.toml" --output "$out/reset_resumed" --restart --json "$out/reset_resumed.json" > "$out/reset_resumed.log" 2>&1 ||
  { tail -20 "$out/reset_resumed.log"; fail "the 1-rank restart of a 2-rank checkpoint after a reset"; }
grep -q "resumed from .* at step 5, .* 1 resets" "$out/reset_resumed.log" || { head -5 "$out/reset_resumed.log"; fail "did not resume after the reset of step 3"; }
/usr/bin/python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
one, two, four, resumed = (json.load(open(f"{out}/{n}.json")) for n in ("reset_1", "reset_2", "reset_4", "reset_resumed"))
ok = True
for name, other in (("2 ranks", two), ("4 ranks", four), ("resumed on 1 rank", resumed)):
    d = abs(one["energy"] - other["energy"]) / abs(one["energy"])
    print(f"resets: energy 1 rank {one['energy']:.15f}, {name} {other['energy']:.15f}, relative difference {d:.2e}")
    if d > 1e-10 or one["steps"] != other["steps"]:
        print(f"FAIL: {name} ends elsewhere"); ok = False
sys.exit(0 if ok else 1)
PY
echo "PASS"
