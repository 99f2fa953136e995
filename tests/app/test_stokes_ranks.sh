#!/usr/bin/env bash
# The colliding-flow demo (demos/colliding_flow.toml, built-in forms/stokes.form) on a smaller grid
# (17 x 17 nodes): 1 and 2 MPI ranks give the same errors of u and p to 1e-9 (relative), the
# unstabilized run (--set C=0) has a pressure error over 100 times the stabilized one, and an
# unknown double-dash option is refused rather than passed to PETSc.
#
#   test_stokes_ranks.sh LMEFORM OUT_DIR
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
sed -e 's#^counts = .*#counts = [17, 17]#' "$demos/colliding_flow.toml" > "$out/colliding.toml"
grep -q '^counts = \[17, 17\]$' "$out/colliding.toml" || fail "could not make the smaller scene"

"$lmeform" run "$out/colliding.toml" --json "$out/one.json" --output "$out/one" > "$out/one.log" 2>&1 ||
  { tail -20 "$out/one.log"; fail "1 rank: lmeform run failed"; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
mpirun -n 2 "$lmeform" run "$out/colliding.toml" --json "$out/two.json" --output "$out/two" > "$out/two.log" 2>&1 ||
  { tail -20 "$out/two.log"; fail "2 ranks: lmeform run failed"; }
"$lmeform" run "$out/colliding.toml" --set C=0 --json "$out/none.json" --output "$out/none" > "$out/none.log" 2>&1 ||
  { tail -20 "$out/none.log"; fail "unstabilized: lmeform run failed"; }
if "$lmeform" run "$out/colliding.toml" --sett C=0 > "$out/typo.log" 2>&1; then fail "--sett was accepted"; fi
grep -q "unknown option '--sett'" "$out/typo.log" || { cat "$out/typo.log"; fail "no message for --sett"; }

/usr/bin/python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
one, two, none = (json.load(open(f"{out}/{n}.json")) for n in ("one", "two", "none"))
err = lambda r, u: next(e for e in r["errors"] if e["unknown"] == u)
ok = True
for u in ("u", "p"):
    for norm in ("l2", "h1"):
        a, b = err(one, u)[norm], err(two, u)[norm]
        d = abs(a - b) / abs(a)
        print(f"{u} {norm}: 1 rank {a:.12e}, 2 ranks {b:.12e}, relative difference {d:.1e}")
        ok = ok and d < 1e-9
ratio = err(none, "p")["l2"] / err(one, "p")["l2"]
print(f"pressure L2 error: unstabilized {err(none, 'p')['l2']:.3e}, GLS {err(one, 'p')['l2']:.3e} (ratio {ratio:.0f})")
ok = ok and ratio > 100 and one["converged"] and two["converged"]
sys.exit(0 if ok else 1)
PY
