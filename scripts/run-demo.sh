#!/usr/bin/env bash
# The README demo. Until the vesicle scene runs end to end, it shows the LME basis.
set -euo pipefail
build=${1:-build}
out="$build/demo"
mkdir -p "$out"
"$build/demos/lme_basis_demo" --out "$out"
/usr/bin/python3 demos/plot_lme_basis.py "$out"
echo "demo figures in $out/"
