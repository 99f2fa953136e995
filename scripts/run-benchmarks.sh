#!/usr/bin/env bash
# Runs every registered benchmark (build/benchmarks.txt) in quick mode; JSON goes to BUILD/bench/.
set -euo pipefail
build=${1:-build}
out="$build/bench"
mkdir -p "$out"
status=0
while IFS= read -r exe; do
  [ -z "$exe" ] && continue
  echo "== $(basename "$exe")"
  if ! "$exe" --quick --out "$out"; then
    echo "benchmark $(basename "$exe") failed" >&2
    status=1
  fi
done < "$build/benchmarks.txt"
# Scene-level studies (python drivers of lmeform run), quick mode.
lmeform_exe="$build/lmeform"
if [ -x "$lmeform_exe" ]; then
  echo "== fracture: Gamma-convergence in 1D (demos/fracture/gamma_convergence.py)"
  if ! /usr/bin/python3 demos/fracture/gamma_convergence.py "$lmeform_exe" "$out" --quick; then
    echo "benchmark fracture gamma_convergence failed" >&2
    status=1
  fi
  echo "== fracture: the opened band's energy (demos/fracture/opening_study.py, about 30 s)"
  if ! /usr/bin/python3 demos/fracture/opening_study.py "$lmeform_exe" "$out"; then
    echo "benchmark fracture opening_study failed" >&2
    status=1
  fi
  echo "== forming: upsetting of a viscoplastic billet (demos/forming/forming_study.py)"
  if ! /usr/bin/python3 demos/forming/forming_study.py --lmeform "$lmeform_exe" --json "$out/forming.json" --work "$build/forming" --quick; then
    echo "benchmark forming failed" >&2
    status=1
  fi
fi
# The scaling study: 1, 2, 4 and 8 ranks (oversubscribed beyond the cores), quick sizes.
if [ -x "$build/tests/assembly_bench/bench_scaling" ]; then
  echo "== scaling: memory and setup per rank (scripts/scaling_study.py)"
  if ! /usr/bin/python3 scripts/scaling_study.py --build "$build" --quick; then
    echo "benchmark scaling failed" >&2
    status=1
  fi
fi
echo "benchmark results in $out/:"
ls -1 "$out"
exit $status
