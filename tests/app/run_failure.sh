#!/usr/bin/env bash
# A run whose second stage cannot be solved (eps below 2 h_min) must stop with exit code 2, say
# what failed, and still write the finished first stage: HDF5 + XDMF and the JSON, no temporaries.
set -euo pipefail
lmeform=$1
out=$2
rm -rf "$out"
mkdir -p "$out"
cat "$(dirname "$0")/tiny_scene.toml" - > "$out/scene.toml" <<TOML
[vesicle.adaptivity]
stages = [ { eps = 0.01, lloyd_iterations = 0 } ]
[output]
directory = "$out/result"
png = false
TOML
set +e
"$lmeform" run "$out/scene.toml" --json "$out/run.json" > "$out/log.txt" 2>&1
code=$?
set -e
cat "$out/log.txt"
fail() { echo "FAIL: $*"; exit 1; }
[ "$code" -eq 2 ] || fail "exit code $code, expected 2"
grep -q "status.*FAILED: stage 1: uniform grid" "$out/log.txt" || fail "the status line does not name the failed stage"
grep -q "under-resolved" "$out/log.txt" || fail "the message does not say why"
[ -s "$out/result/tiny.h5" ] || fail "the finished stage was not written"
[ -s "$out/result/tiny.xmf" ] || fail "no XDMF sidecar"
grep -q '"converged": false' "$out/run.json" || fail "the JSON does not record the failure"
grep -q '"status": "FAILED: stage 1' "$out/run.json" || fail "the JSON has no status"
if ls "$out"/result/*.tmp "$out"/*.tmp > /dev/null 2>&1; then fail "temporary files left behind"; fi
echo "PASS"
