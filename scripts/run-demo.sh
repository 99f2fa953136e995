#!/usr/bin/env bash
# The README demo: the discocyte vesicle (demos/discocyte.toml) with lmeform run, then the LME
# basis figures and consistency table.
set -euo pipefail
build=${1:-build}
out="$build/demo"
mkdir -p "$out"
echo "== lmeform run demos/discocyte.toml"
"$build/lmeform" run demos/discocyte.toml --output "$out/discocyte" --json "$out/discocyte.json"
echo
echo "== LME basis demo"
"$build/demos/lme_basis_demo" --out "$out"
/usr/bin/python3 demos/plot_lme_basis.py "$out"
echo "demo results in $out/ (discocyte.h5 + .xmf for ParaView, discocyte.png, lme_*.png)"
