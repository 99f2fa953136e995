#!/usr/bin/env bash
# Basis-order study of docs/convergence_measurements.md: first-order (LME) against second-order
# max-ent basis (scene key nodes.basis) on
#   helfrich   - the Table 1 discocyte on uniform CVTs at fixed eps (demos/convergence/helfrich_table1.toml),
#                node ladder x gamma (0.5, 0.8) x basis, energy against the seed's finest grid O7;
#   discocyte  - the adaptive eps = 0.04 -> 0.01 schedule of demos/discocyte.toml (demos/convergence/discocyte_basis.toml)
#                per basis and gamma, energy per stage against the sharp-interface energy;
#   stokes     - the colliding flow (demos/convergence/colliding_flow.toml), uniform 9^2 .. 129^2 per basis,
#                6 and 12 quadrature points per cell, u / p L2 and u H1 errors and rates.
# Usage (from anywhere; one run at a time, serial):
#   demos/convergence/basis_study.sh BUILD_DIR [helfrich|discocyte|stokes|all]   (default all)
# Environment knobs (defaults are the measured ladders):
#   HELFRICH_EPS="0.05"  HELFRICH_COUNTS="1600 3100 6124 12271 24597"  HELFRICH_GAMMAS="0.5 0.8"
#   DISCOCYTE_RUNS="second:0.5 first:0.5 second:0.8 first:0.8"  (basis:gamma)
#   DISCOCYTE_SCENE=discocyte_basis (full schedule to O13) | discocyte_o12 (O12 only, continued to eps 0.01)
#   STOKES_COUNTS="9 17 33 65 129"  STOKES_QUADS="6 12" (points per Delaunay triangle; one ladder each)
# Results: BUILD_DIR/demo/convergence/<study>/ (scenes, logs, JSON); the tables go to stdout.
set -euo pipefail
build=${1:?usage: basis_study.sh BUILD_DIR [helfrich|discocyte|stokes|all]}
which=${2:-all}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
build=$(cd "$build" && pwd)
lmeform="$build/lmeform"
py=/usr/bin/python3
out_root="$build/demo/convergence"
mkdir -p "$out_root"

# The seed's finest grid (O7, 296,344 nodes) per eps: the converged energy at fixed eps.
declare -A o7=([0.05]=9.73989 [0.04]=9.60053 [0.03]=9.43437 [0.02]=9.28326)

run() {  # scene json log
  if ! "$lmeform" run "$1" --output "${2%.json}" --json "$2" > "$3" 2>&1; then
    echo "FAILED: $lmeform run $1 (log $3):" >&2
    grep -iE "error|infeasible|refused|fail" "$3" | head -5 >&2 || tail -5 "$3" >&2
    return 1
  fi
}

helfrich() {
  local eps=${HELFRICH_EPS:-0.05}
  local counts=${HELFRICH_COUNTS:-1600 3100 6124 12271 24597}
  local gammas=${HELFRICH_GAMMAS:-0.5 0.8}
  local out="$out_root/helfrich"; mkdir -p "$out"
  local ref=${o7[$eps]:-}
  echo "== helfrich: eps $eps, counts $counts, gamma $gammas (reference O7 = ${ref:-none})"
  for g in $gammas; do for b in first second; do for n in $counts; do
    local tag="eps${eps}_g${g}_${b}_n${n}"
    # resolution_factor 1.0: the coarse rungs (h > eps/1.6) are allowed for the study
    sed -e "s/^count = .*/count = $n/" -e "s/^gamma = .*/gamma = $g/" -e "s/^basis = .*/basis = \"$b\"/" \
        -e "s/^eps = .*/eps = $eps/" -e "s/^resolution_factor = .*/resolution_factor = 1.0/" \
        "$here/helfrich_table1.toml" > "$out/$tag.toml"
    echo "   $tag"
    run "$out/$tag.toml" "$out/$tag.json" "$out/$tag.log" || true
  done; done; done
  "$py" - "$out" "$eps" "${ref:-nan}" "$counts" "$gammas" <<'PY'
import json, math, os, sys
out, eps, ref, counts, gammas = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4].split(), sys.argv[5].split()
print(f"\n| gamma | basis | nodes | h_min | energy | rel. to O7 ({ref}) | rate vs h | AL+KKT | wall s |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
for g in gammas:
    for b in ("first", "second"):
        prev = None
        for n in counts:
            f = f"{out}/eps{eps}_g{g}_{b}_n{n}.json"
            if not os.path.exists(f):
                print(f"| {g} | {b} | {n} | | FAILED (see {f[:-5]}.log) | | | | |"); prev = None; continue
            d = json.load(open(f))
            e, h = d["energy"], d["h_min"]
            err = (e - ref) / ref
            rate = ""
            if prev and abs(err) > 0 and abs(prev[1]) > 0:
                rate = f"{math.log(abs(prev[1]) / abs(err)) / math.log(prev[0] / h):.2f}"
            print(f"| {g} | {b} | {d['nodes']} | {h:.4f} | {e:.5f} | {100*err:+.3f} % | {rate} | "
                  f"{d['augmented_iterations']}+{d['newton_iterations']} | {d['wall_s']:.1f} |")
            prev = (h, err)
PY
}

discocyte() {
  local runs=${DISCOCYTE_RUNS:-second:0.5 first:0.5 second:0.8 first:0.8}
  local scene=${DISCOCYTE_SCENE:-discocyte_basis}
  local out="$out_root/discocyte"; mkdir -p "$out"
  echo "== discocyte (demos/convergence/$scene.toml): $runs"
  local tags=()
  for r in $runs; do
    local b=${r%%:*} g=${r##*:}
    local tag="${b}_g${g}"
    [ "$scene" != discocyte_basis ] && tag="${scene#discocyte_}_$tag"
    sed -e "s/^gamma = .*/gamma = $g/" -e "s/^basis = .*/basis = \"$b\"/" -e "s/^png = .*/png = false/" \
        "$here/$scene.toml" > "$out/$tag.toml"
    echo "   $tag"
    run "$out/$tag.toml" "$out/$tag.json" "$out/$tag.log" || true
    tags+=("$tag")
  done
  "$py" - "$out" "${tags[@]}" <<'PY'
import json, os, sys
out, tags = sys.argv[1], sys.argv[2:]
o7 = {0.04: 9.60053, 0.03: 9.43437, 0.025: 9.35488, 0.02: 9.28326, 0.015: 9.22399, 0.01: 9.18627}  # seed's finest grid
print("\n| run | stage | grid | nodes | eps | h_min | energy | rel. to O7 at this eps | rel. to sharp 9.12657 | AL+KKT | stage wall s |")
print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for t in tags:
    f = f"{out}/{t}.json"
    if not os.path.exists(f):
        # no JSON: the stages that ran are in the log's closing table (stage grid nodes eps h_min energy err AL+KKT times)
        rows, on = [], False
        for line in open(f"{out}/{t}.log"):
            if line.startswith("stage "): on = True; continue
            if on and line[:1].isdigit():
                w = line.split(); k = w.index("6124") if "6124" in w else 2
                grid = " ".join(w[1:k]); n, eps, hmin, e = w[k], float(w[k+1]), float(w[k+2]), float(w[k+3])
                ref = o7.get(round(eps, 4))
                dref = f"{100*(e-ref)/ref:+.3f} %" if ref else ""
                wall = sum(float(x) for x in w[k+6:k+10])
                print(f"| {t} | {w[0]} | {grid} | {n} | {eps} | {hmin:.4f} | {e:.5f} | {dref} | {w[k+4]} | {w[k+5]} | {wall:.1f} |")
            elif on and not line.strip(): break
        msg = [l for l in open(f"{out}/{t}.log") if l.startswith("status")]
        print(f"| {t} | FAILED | {msg[0].split('FAILED:')[1].strip()[:160] if msg else 'see log'} | | | | | | | | |"); continue
    d = json.load(open(f))
    for s in d["stages"]:
        ref = o7.get(round(s['eps'], 4))
        dref = f"{100*(s['energy']-ref)/ref:+.3f} %" if ref else ""
        print(f"| {t} | {s['stage']} | {s['grid']}{' (branch)' if s.get('branch') else ''} | {s['nodes']} | {s['eps']} | "
              f"{s['h_min']:.4f} | {s['energy']:.5f} | {dref} | {100*s['relative_error_sharp']:+.3f} % | "
              f"{s['augmented_iterations']}+{s['newton_iterations']} | {s['wall_s']:.1f} |")
    st = d["status"] if d["status"] == "converged" else d["status"][:200]
    print(f"| {t} | total | {st} | | | | | | | | {d['wall_s']:.1f} |")
PY
}

stokes() {
  local counts=${STOKES_COUNTS:-9 17 33 65 129}
  local quads=${STOKES_QUADS:-6 12}
  local out="$out_root/stokes"; mkdir -p "$out"
  echo "== stokes colliding flow: counts $counts, gamma 1.0, quadrature points $quads"
  for q in $quads; do for b in first second; do for n in $counts; do
    local tag="${b}_q${q}_n${n}"
    sed -e "s/^counts = .*/counts = [$n, $n]/" -e "s/^basis = .*/basis = \"$b\"/" \
        -e "s/^quadrature_points = .*/quadrature_points = $q/" \
        "$here/colliding_flow.toml" > "$out/$tag.toml"
    echo "   $tag"
    run "$out/$tag.toml" "$out/$tag.json" "$out/$tag.log" || true
  done; done; done
  "$py" - "$out" "$counts" "$quads" <<'PY'
import json, math, os, sys
out, counts, quads = sys.argv[1], sys.argv[2].split(), sys.argv[3].split()
print("\n| points/cell | basis | nodes | unknowns | h | u L2 | rate | u H1 | rate | p L2 | rate | setup s | solve s | wall s |")
print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for q in quads:
    for b in ("first", "second"):
        prev = None
        for n in counts:
            f = f"{out}/{b}_q{q}_n{n}.json"
            if not os.path.exists(f):
                print(f"| {q} | {b} | {int(n)**2} | FAILED | | | | | | | | | | |"); prev = None; continue
            d = json.load(open(f))
            e = {x["unknown"]: x for x in d["errors"]}
            h = 2.0 / (int(n) - 1)
            vals = (e["u"]["l2"], e["u"]["h1"], e["p"]["l2"])
            rates = ["", "", ""]
            if prev:
                rates = [f"{math.log(p / v) / math.log(prev[0] / h):.2f}" for p, v in zip(prev[1], vals)]
            print(f"| {q} | {b} | {d['nodes']} | {3*d['nodes']} | {h:.4f} | {vals[0]:.3e} | {rates[0]} | {vals[1]:.3e} | {rates[1]} | "
                  f"{vals[2]:.3e} | {rates[2]} | {d['setup_s']:.2f} | {d['solve_s']:.2f} | {d['wall_s']:.2f} |")
            prev = (h, vals)
PY
}

case $which in
  helfrich) helfrich ;;
  discocyte) discocyte ;;
  stokes) stokes ;;
  all) stokes; helfrich; discocyte ;;
  *) echo "unknown study '$which' (helfrich, discocyte, stokes, all)" >&2; exit 2 ;;
esac
