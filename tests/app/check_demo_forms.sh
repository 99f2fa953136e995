#!/usr/bin/env bash
# `lmeform check` on every .form under demos/ (compiled at run time): each output in each declared
# dimension passes its finite-difference and Taylor checks, and a failure exits 1.
set -euo pipefail
lmeform=$1
out=$2
rm -rf "$out"
mkdir -p "$out"
export LMEFORM_CACHE_DIR="$out/cache"
root="$(cd "$(dirname "$0")/../.." && pwd)"
status=0
for form in "$root"/demos/*/*.form; do
  if "$lmeform" check "$form" --json "$out/$(basename "$form" .form).json" > "$out/$(basename "$form" .form).log" 2>&1; then
    echo "pass $form: $(grep -c '  pass' "$out/$(basename "$form" .form).log") checks"
  else
    cat "$out/$(basename "$form" .form).log"
    echo "FAIL: lmeform check $form"
    status=1
  fi
done
[ "$status" -eq 0 ] && echo "PASS"
exit "$status"
