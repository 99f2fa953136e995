#!/usr/bin/env bash
# Stokes: lmeform (bench_stokes, LME + GLS) against FEniCSx 0.5 (P2/P1 Taylor-Hood, P1/P1 stabilised).
#   demos/stokes/compare.sh [BUILD_DIR] [--quick]
# 1. installs python3-dolfinx and python3-matplotlib (Debian 12 packages) when missing;
# 2. runs bench_stokes --out BUILD_DIR/bench if it is built (any executable named bench_stokes
#    under BUILD_DIR), otherwise says so and goes on with FEniCSx alone;
# 3. demos/stokes/fenicsx_stokes.py --out BUILD_DIR/compare (serial, MUMPS LU);
# 4. demos/stokes/compare_fenicsx.py BUILD_DIR: BUILD_DIR/compare/stokes_fenicsx.json,
#    stokes_<problem>.png (error vs unknowns and vs wall time) and a Markdown table.
# --quick caps the FEniCSx meshes at ~10,000 unknowns and is passed on to bench_stokes.
set -euo pipefail
build=${1:-build}
quick=()
[ "${2:-}" = "--quick" ] && quick=(--quick)
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source "$here/../../scripts/fenicsx-env.sh"

mkdir -p "$build/bench" "$build/compare"
bench=$(find "$build" -type f -name bench_stokes -perm -u+x 2>/dev/null | head -n 1 || true)
if [ -n "$bench" ]; then
  echo "== $bench ${quick[*]} --out $build/bench"
  "$bench" "${quick[@]}" --out "$build/bench"
else
  echo "== bench_stokes not found under $build (not built yet): FEniCSx side only"
fi

echo "== fenicsx_stokes.py ${quick[*]} --out $build/compare"
"$py" "$here/fenicsx_stokes.py" "${quick[@]}" --out "$build/compare"

echo "== compare_fenicsx.py $build"
"$py" "$here/compare_fenicsx.py" "$build"
