#!/usr/bin/env bash
# lmeform run on 1 and on 2 MPI ranks (METIS partition, zero-communication assembly, MUMPS) gives
# the same energies at every stage of a small adapted scene.
set -euo pipefail
lmeform=$1
out=$2
rm -rf "$out"
mkdir -p "$out"
cat "$(dirname "$0")/tiny_scene.toml" - > "$out/scene.toml" <<TOML
[vesicle.adaptivity]
stages = [ { eps = 0.12, f = 10.0 } ]
TOML
"$lmeform" run "$out/scene.toml" --json "$out/one.json" > "$out/one.log" 2>&1
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
mpirun -n 2 "$lmeform" run "$out/scene.toml" --json "$out/two.json" > "$out/two.log" 2>&1
/usr/bin/python3 - "$out/one.json" "$out/two.json" <<'PY'
import json, sys
one, two = (json.load(open(p)) for p in sys.argv[1:3])
assert one["converged"] and two["converged"], (one["status"], two["status"])
assert len(one["stages"]) == len(two["stages"]) == 2
for a, b in zip(one["stages"], two["stages"]):
    diff = abs(a["energy"] - b["energy"]) / abs(a["energy"])
    print(f"stage {a['stage']} ({a['grid']}): 1 rank {a['energy']:.12f}, 2 ranks {b['energy']:.12f}, relative difference {diff:.1e}")
    assert diff < 1e-9, "1 and 2 ranks differ"
print("PASS")
PY
