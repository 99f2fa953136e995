#!/usr/bin/env bash
# The adhesion demo (demos/adhesion: the built-in vesicle forms + adhesion_axisymmetric.form,
# compiled at run time, added through the scene alone), made smaller here (441 nodes, eps 0.08):
#  * 1 and 2 MPI ranks give the same energy to 1e-9 (relative), and both converge;
#  * the energy with adhesion is below that of the same scene without the adhesion term
#    (model.energy = ["bending"], neither the adhesion form nor its constants).
#
#   test_adhesion_ranks.sh LMEFORM OUT_DIR
set -euo pipefail
lmeform=$1
out=$2
demo=$(cd "$(dirname "$0")/../../demos/adhesion" && pwd)
rm -rf "$out"
mkdir -p "$out"

fail() {
  echo "FAIL: $*"
  exit 1
}

# The demo scene, smaller: a coarser grid (spacing 0.04 on [0, 0.8]^2) and eps = 2 h.
small=(-e "s#\"adhesion_axisymmetric.form\"#\"$demo/adhesion_axisymmetric.form\"#"
       -e "s#^upper = .*#upper = [0.8, 0.8]#" -e "s#^spacing = [0-9.]*#spacing = 0.04#" -e "s#^eps = [0-9.]*#eps = 0.08#")
sed -e 's#^name = .*#name = "adhered"#' "${small[@]}" "$demo/adhered_vesicle.toml" > "$out/adhered.toml"
sed -e 's#^name = .*#name = "free"#' "${small[@]}" -e 's#, "[^"]*adhesion_axisymmetric.form"##' \
  -e 's#^energy = \["bending", "adhesion"\].*#energy = ["bending"]#' \
  -e '/^omega =\|^z_wall =\|^delta_over_eps =\|^repulsion =/d' "$demo/adhered_vesicle.toml" > "$out/free.toml"
grep -q '^energy = \["bending"\]$' "$out/free.toml" || fail "could not derive the scene without adhesion"
grep -q '^forms = .*adhesion_axisymmetric' "$out/free.toml" && fail "could not drop the adhesion form from the scene without adhesion"

"$lmeform" run "$out/adhered.toml" --json "$out/one.json" --output "$out/one" > "$out/one.log" 2>&1 ||
  { tail -20 "$out/one.log"; fail "1 rank: lmeform run failed (log: $out/one.log)"; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
mpirun -n 2 "$lmeform" run "$out/adhered.toml" --json "$out/two.json" --output "$out/two" > "$out/two.log" 2>&1 ||
  { tail -20 "$out/two.log"; fail "2 ranks: lmeform run failed (log: $out/two.log)"; }
"$lmeform" run "$out/free.toml" --json "$out/free.json" --output "$out/free" > "$out/free.log" 2>&1 ||
  { tail -20 "$out/free.log"; fail "without adhesion: lmeform run failed (log: $out/free.log)"; }

/usr/bin/python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
one, two, free = (json.load(open(f"{out}/{n}.json")) for n in ("one", "two", "free"))
for name, r in (("1 rank", one), ("2 ranks", two), ("without adhesion", free)):
    if not r["converged"]:
        print(f"FAIL: {name}: {r['status']}")
        sys.exit(1)
diff = abs(one["energy"] - two["energy"]) / abs(one["energy"])
print(f"adhered vesicle ({one['nodes']} nodes): 1 rank {one['energy']:.12f}, 2 ranks {two['energy']:.12f}, "
      f"relative difference {diff:.1e}")
print(f"without adhesion: {free['energy']:.12f} (adhesion lowers the energy by {free['energy'] - one['energy']:.6f})")
print(f"wall time: 1 rank {one['wall_s']:.1f} s, 2 ranks {two['wall_s']:.1f} s, without adhesion {free['wall_s']:.1f} s")
if not diff < 1e-9:
    print("FAIL: 1 and 2 ranks differ by more than 1e-9")
    sys.exit(1)
if not one["energy"] < free["energy"]:
    print("FAIL: the energy with adhesion is not below the energy without it")
    sys.exit(1)
print("PASS")
PY
