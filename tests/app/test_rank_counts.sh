#!/usr/bin/env bash
# One scene, any number of ranks: a statics run (two stages of the tiny vesicle) on 1, 2, 4 and 8
# ranks (METIS and Hilbert partitions; 4 and 8 oversubscribe two cores), the same schedule's first stage
# on 2 ranks resumed on 1 from its checkpoint, and a dynamics run on 1 and
# 4 ranks reach the same energies to 1e-10 (relative); a dynamics run checkpointed on 2 ranks and
# resumed on 1 ends where the uninterrupted 1-rank run ends; a scene whose nodes and initial field
# come from the first run's output file gives the same energy on 1 and 2 ranks; more ranks than
# nodes, and a bad text node file on 2 ranks, are refused with a message.
#
#   test_rank_counts.sh LMEFORM OUT_DIR
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
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1

# Statics.
cat "$here/tiny_scene.toml" - > "$out/statics.toml" <<TOML
[vesicle.adaptivity]
stages = [ { eps = 0.12, f = 10.0 } ]
TOML
sed 's/^spacing = 0.06$/spacing = 0.06\npartition = "hilbert"/' "$out/statics.toml" > "$out/statics_hilbert.toml"
grep -q '^partition = "hilbert"' "$out/statics_hilbert.toml" || fail "could not make the Hilbert scene"
"$lmeform" run "$out/statics.toml" --json "$out/statics_1.json" --output "$out/s1" > "$out/statics_1.log" 2>&1 ||
  { tail -20 "$out/statics_1.log"; fail "statics on 1 rank"; }
for run in "2 statics_hilbert" "4 statics" "8 statics_hilbert"; do
  set -- $run
  mpirun -n "$1" "$lmeform" run "$out/$2.toml" --json "$out/statics_$1.json" --output "$out/s$1" > "$out/statics_$1.log" 2>&1 ||
    { tail -20 "$out/statics_$1.log"; fail "statics on $1 ranks"; }
done
# The schedule's first stage on 2 ranks, the second on 1 from its checkpoint.
mpirun -n 2 "$lmeform" run "$here/tiny_scene.toml" --output "$out/sr" > "$out/statics_first_2.log" 2>&1 ||
  { tail -20 "$out/statics_first_2.log"; fail "the first stage on 2 ranks"; }
"$lmeform" run "$out/statics.toml" --output "$out/sr" --restart --json "$out/statics_resumed.json" > "$out/statics_resumed.log" 2>&1 ||
  { tail -20 "$out/statics_resumed.log"; fail "the 1-rank restart of a 2-rank schedule checkpoint"; }
grep -q "resumed from $out/sr after stage 0" "$out/statics_resumed.log" || { cat "$out/statics_resumed.log"; fail "the schedule did not resume"; }

# The first run's nodes and field as a node file and an initial field (read collectively on 2
# ranks, a block of rows each): the converged vesicle read back, on 1 and 2 ranks.
sed -e '/^\[vesicle.initial\]/,$d' -e "s|^spacing = 0.06$|file = \"$out/s1/tiny.h5\"|" -e 's/^eps = 0.14$/eps = 0.12/' \
    "$here/tiny_scene.toml" > "$out/from_file.toml"
printf '[initial]\nphi = { file = "%s", field = "phi" }\n' "$out/s1/tiny.h5" >> "$out/from_file.toml"
grep -q '^file = ' "$out/from_file.toml" || fail "could not make the node-file scene"
"$lmeform" run "$out/from_file.toml" --json "$out/from_file_1.json" --output "$out/f1" > "$out/from_file_1.log" 2>&1 ||
  { tail -20 "$out/from_file_1.log"; fail "the node-file scene on 1 rank"; }
mpirun -n 2 "$lmeform" run "$out/from_file.toml" --json "$out/from_file_2.json" --output "$out/f2" > "$out/from_file_2.log" 2>&1 ||
  { tail -20 "$out/from_file_2.log"; fail "the node-file scene on 2 ranks"; }

# Dynamics: the oblate relaxation on a coarse box, 10 steps.
sed -e 's/^upper = \[1.0, 1.6\]/upper = [1.0, 1.5]/' -e 's/^spacing = 0.025/spacing = 0.0625/' -e 's/^eps = 0.05/eps = 0.125/' \
    -e 's/0\.8)/0.75)/g' -e 's/^t_end = .*/t_end = 0.01/' -e 's/^dt = .*/dt = 1e-3/' -e 's/^dt_max = .*/dt_max = 1e-3/' \
    -e 's/^output_every = .*/output_every = 5\ncheckpoint_every = 5/' \
    "$demos/dynamics/oblate_relaxation.toml" > "$out/dynamics.toml"
grep -q '^spacing = 0.0625$' "$out/dynamics.toml" || fail "could not make the smaller dynamics scene"
sed 's/^t_end = .*/t_end = 0.005/' "$out/dynamics.toml" > "$out/dynamics_half.toml"
"$lmeform" run "$out/dynamics.toml" --json "$out/dynamics_1.json" --output "$out/d1" > "$out/dynamics_1.log" 2>&1 ||
  { tail -20 "$out/dynamics_1.log"; fail "dynamics on 1 rank"; }
mpirun -n 4 "$lmeform" run "$out/dynamics.toml" --json "$out/dynamics_4.json" --output "$out/d4" > "$out/dynamics_4.log" 2>&1 ||
  { tail -20 "$out/dynamics_4.log"; fail "dynamics on 4 ranks"; }
# Half the run on 2 ranks, the rest on 1 from its checkpoint.
mpirun -n 2 "$lmeform" run "$out/dynamics_half.toml" --output "$out/resumed" > "$out/half_2.log" 2>&1 ||
  { tail -20 "$out/half_2.log"; fail "the first half on 2 ranks"; }
"$lmeform" run "$out/dynamics.toml" --output "$out/resumed" --restart --json "$out/resumed.json" > "$out/resumed_1.log" 2>&1 ||
  { tail -20 "$out/resumed_1.log"; fail "the 1-rank restart of a 2-rank checkpoint"; }

# More ranks than nodes.
cat > "$out/few.toml" <<TOML
[scene]
name = "few"
coordinates = "cartesian"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.0]
[nodes]
counts = [3, 3]
[model]
forms = ["$here/../../forms/poisson.form"]
energy = "heat"
[[dirichlet]]
boundary = ["hull"]
unknown = "T"
value = 0.0
TOML
if mpirun -n 12 "$lmeform" run "$out/few.toml" --output "$out/few" > "$out/few.log" 2>&1; then fail "12 ranks for 9 nodes ran"; fi
grep -q "12 MPI ranks for 9 nodes; every rank needs at least one node: run on at most 9 ranks" "$out/few.log" ||
  { cat "$out/few.log"; fail "no message for more ranks than nodes"; }
[ -e "$out/few/few.h5" ] && fail "a refused run wrote its fields"

# A text node file with a point outside the domain, on 2 ranks: rank 0 parses it, and every rank
# stops with its message (no rank left waiting).
printf '0.1, 0.1\n0.5, 0.5\n0.9, 0.2\n2.5, 7.0\n' > "$out/outside.txt"
sed "s|^counts = \[3, 3\]$|file = \"$out/outside.txt\"|" "$out/few.toml" > "$out/outside.toml"
grep -q '^file = ' "$out/outside.toml" || fail "could not make the bad node-file scene"
if timeout 120 mpirun -n 2 "$lmeform" run "$out/outside.toml" --output "$out/outside" > "$out/outside.log" 2>&1; then
  fail "a node file with a point outside the domain ran on 2 ranks"
fi
grep -q "key 'nodes.file'.*lies outside the domain" "$out/outside.log" || { cat "$out/outside.log"; fail "no message for the bad node file on 2 ranks"; }

/usr/bin/python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
ok = True
def close(a, b, what):
    global ok
    d = abs(a - b) / abs(b)
    print(f"{what}: {a:.14f} against {b:.14f}, relative difference {d:.1e}")
    if d > 1e-10:
        print(f"FAIL: {what} differs"); ok = False
one = json.load(open(f"{out}/statics_1.json"))
assert one["converged"] and len(one["stages"]) == 2
for p in (2, 4, 8):
    other = json.load(open(f"{out}/statics_{p}.json"))
    if not other["converged"]:
        print(f"FAIL: statics on {p} ranks did not converge"); ok = False
    for a, b in zip(other["stages"], one["stages"]):
        close(a["energy"], b["energy"], f"statics stage {b['stage']}, {p} ranks")
resumed = json.load(open(f"{out}/statics_resumed.json"))
if not resumed["converged"] or len(resumed["stages"]) != 2:
    print("FAIL: the resumed schedule did not finish both stages"); ok = False
for a, b in zip(resumed["stages"], one["stages"]):
    close(a["energy"], b["energy"], f"statics stage {b['stage']}, stage 0 on 2 ranks, resumed on 1")
f1, f2 = (json.load(open(f"{out}/from_file_{p}.json")) for p in (1, 2))
last = one["stages"][-1]
if not (f1["converged"] and f2["converged"]) or f1["nodes"] != last["nodes"] or f2["nodes"] != last["nodes"]:
    print(f"FAIL: the node-file runs: converged {f1['converged']} / {f2['converged']}, nodes {f1['nodes']} / {f2['nodes']} "
          f"(the file holds {last['nodes']})"); ok = False
close(f2["energy"], f1["energy"], "nodes and field from a file, 2 ranks")
# The field read back is the converged state on its own nodes: no Newton step, the same energy.
close(f1["energy"], last["energy"], "nodes and field from a file against the run that wrote them")
if f1["newton_iterations"] != 0 or f2["newton_iterations"] != 0:
    print(f"FAIL: the converged state read back took {f1['newton_iterations']} / {f2['newton_iterations']} Newton steps"); ok = False
d1, d4, resumed = (json.load(open(f"{out}/{n}.json")) for n in ("dynamics_1", "dynamics_4", "resumed"))
if d1["steps"] != d4["steps"] or d1["steps"] != resumed["steps"]:
    print(f"FAIL: steps 1 rank {d1['steps']}, 4 ranks {d4['steps']}, resumed {resumed['steps']}"); ok = False
close(d4["energy"], d1["energy"], "dynamics, 4 ranks")
close(resumed["energy"], d1["energy"], "dynamics, 2 ranks then 1 from the checkpoint")
sys.exit(0 if ok else 1)
PY
echo "PASS"
