#!/usr/bin/env bash
# Regenerates the Stokes results of docs/stokes.md from a built tree:
#  * the colliding flow on 25 x 25 nodes (1250 velocity dofs, as seed Fig. 5.1) with and without
#    stabilization, and the picture of both pressure fields (docs/figures/stokes_pressure.png);
#  * bench_stokes (full ladders) and its plots (docs/figures/stokes_convergence.png,
#    stokes_sensitivity.png) and tables (BUILD/bench/stokes_tables.md).
#   bash demos/stokes/run_study.sh [BUILD_DIR]
set -euo pipefail
build=${1:-build}
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
figures="$root/docs/figures"
out="$build/stokes_study"
mkdir -p "$out" "$figures" "$build/bench"
sed -e 's#^counts = .*#counts = [25, 25]#' "$root/demos/colliding_flow.toml" > "$out/colliding_25.toml"
"$build/lmeform" run "$out/colliding_25.toml" --output "$out/gls" --json "$out/gls.json"
"$build/lmeform" run "$out/colliding_25.toml" --set C=0 --output "$out/none" --json "$out/none.json"
/usr/bin/python3 "$here/plot_pressure.py" "$out/none/colliding_flow.h5" "$out/gls/colliding_flow.h5" "$figures/stokes_pressure.png"
bench=$(find "$build" -name bench_stokes -type f -executable | head -1)
"$bench" --out "$build/bench"
/usr/bin/python3 "$here/plot_convergence.py" "$build/bench/stokes.json" "$figures" > "$build/bench/stokes_tables.md"
echo "tables: $build/bench/stokes_tables.md"
