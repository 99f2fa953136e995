#!/usr/bin/env bash
# Solids: the cantilever with lmeform (bench_solids, LME) against FEniCSx 0.5 (P1 and P2 Lagrange).
#   demos/solids/compare.sh [BUILD_DIR] [--quick]
# 1. installs python3-dolfinx and python3-matplotlib (Debian 12 packages) when missing;
# 2. runs bench_solids --out BUILD_DIR/bench (every solids case; the cantilever rows are compared);
# 3. demos/solids/fenicsx_cantilever.py --out BUILD_DIR/compare (serial, MUMPS LU);
# 4. demos/solids/compare_solids.py BUILD_DIR: BUILD_DIR/compare/solids_compare.json,
#    solids_cantilever.png (errors against unknowns and against wall time) and a Markdown table.
set -euo pipefail
build=${1:-build}
quick=()
[ "${2:-}" = "--quick" ] && quick=(--quick)
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source "$here/../../scripts/fenicsx-env.sh"

mkdir -p "$build/bench" "$build/compare"
bench=$(find "$build" -type f -name bench_solids -perm -u+x 2>/dev/null | head -n 1 || true)
if [ -n "$bench" ]; then
  echo "== $bench ${quick[*]} --out $build/bench"
  "$bench" "${quick[@]}" --out "$build/bench"
else
  echo "== bench_solids not found under $build (not built yet): FEniCSx side only"
fi
echo "== fenicsx_cantilever.py ${quick[*]} --out $build/compare"
"$py" "$here/fenicsx_cantilever.py" "${quick[@]}" --out "$build/compare"
echo "== compare_solids.py $build"
"$py" "$here/compare_solids.py" "$build"
