#!/usr/bin/env python3
"""Gamma-convergence checks of the fracture forms in 1D (docs/fracture.md).

1. The optimal profile: the half-bar scenes profile_{at1,at2,fourth}.toml on spacings h/l = 1 ... 1/8;
   the surface energy against the closed form (Gc/2 for AT1 and AT2, 3 Gc/8 for the fourth order
   with a free slope at the crack) and the profile against its closed form at 16 probes in [0, 4 l].
2. The homogeneous bar: the bar pulled without a crack; the peak force (the critical stress, cross
   section 1) against its closed form.
Writes records to OUT/fracture.json (merged with the records of the other fracture scripts) and
OUT/fracture_profiles.png.
    gamma_convergence.py LMEFORM OUT [--quick]
"""
import json
import math
import pathlib
import re
import subprocess
import sys
import tempfile
import time

HERE = pathlib.Path(__file__).resolve().parent
L_CHAR = 0.05   # l of the profile scenes
GC = 1.0
E_BAR = 1.0     # lambda + 2 mu of the scenes


def profile_exact(model, x):
    s = x / L_CHAR
    if model == "at2":
        return 1 - math.exp(-s)
    if model == "at1":
        return 1 - (1 - s / 2) ** 2 if s < 2 else 1.0
    return 1 - (1 + s / 2) * math.exp(-s)


ENERGY_EXACT = {"at1": GC / 2, "at2": GC / 2, "fourth": 3 * GC / 8}
# critical stress of the homogeneous bar (k -> 0)
SIGMA_C = {"at2": 9 / 16 * math.sqrt(E_BAR * GC / (3 * L_CHAR)),
           "fourth": 9 / 16 * math.sqrt(E_BAR * GC / (6 * L_CHAR)),
           "at1": math.sqrt(3 * E_BAR * GC / (8 * L_CHAR))}
STRAIN_C = {"at2": math.sqrt(GC / (3 * L_CHAR * E_BAR)), "fourth": math.sqrt(GC / (6 * L_CHAR * E_BAR)),
            "at1": math.sqrt(3 * GC / (8 * L_CHAR * E_BAR))}


def run(lmeform, scene_text, workdir, name):
    scene = workdir / f"{name}.toml"
    scene.write_text(scene_text)
    out = workdir / name
    figures = workdir / f"{name}.json"
    t0 = time.perf_counter()
    proc = subprocess.run([lmeform, "run", str(scene), "--output", str(out), "--json", str(figures)], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"{name}: lmeform run failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return json.loads(figures.read_text()), wall, out


def profile_scene(model, spacing):
    text = (HERE / f"profile_{model}.toml").read_text()
    text = re.sub(r"^spacing = [0-9.e-]+", f"spacing = {spacing!r}", text, flags=re.M)
    probes = [L_CHAR * k / 4 for k in range(1, 17)]
    text = text.replace("[quantities]\n", "[quantities]\n" + "".join(f"p{k} = {{ probe = [{x!r}], field = \"v\" }}\n" for k, x in enumerate(probes)))
    return text, probes


def bar_scene(model, steps):
    form = {"at1": "fracture_at1", "at2": "fracture_at2", "fourth": "fracture_fourth"}[model]
    basis = 'basis = "second"\n' if model == "fourth" else ""
    bounds = 'v = { lower = 0.0, upper = "previous" }' if model != "at1" else 'v = { lower = 0.0, upper = "previous" }'
    # AT1 snaps back at its elastic limit: the ramp ends just past it, in steps of 0.25 % of it
    delta_max = (1.02 if model == "at1" else 1.6) * STRAIN_C[model]
    return f"""[scene]
name = "bar_{model}"
coordinates = "cartesian"
[domain]
lower = [0.0]
upper = [1.0]
[nodes]
spacing = 0.05
{basis}[model]
forms = ["{form}"]
[constants]
lambda = 0.0
mu = 0.5
Gc = {GC}
l = {L_CHAR}
k = 1e-9
[parameters]
delta = 0.0
[initial]
v = 1.0
[[dirichlet]]
boundary = ["x_min"]
unknown = "u"
value = 0.0
[[dirichlet]]
boundary = ["x_max"]
unknown = "u"
value = "delta"
[bounds]
{bounds}
[staggered]
groups = [["u"], ["v"]]
tolerance = 1e-10
max_iterations = 2000
[steps]
count = {steps}
ramp = {{ delta = [0.0, {delta_max!r}] }}
[quantities]
force = {{ reaction = "x_max", unknown = "u" }}
""", delta_max


def main():
    lmeform, out = sys.argv[1], pathlib.Path(sys.argv[2])
    quick = "--quick" in sys.argv
    out.mkdir(parents=True, exist_ok=True)
    records = []
    ladders = [1.0, 0.5, 0.25, 0.125] if not quick else [0.5, 0.25]
    curves = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = pathlib.Path(tmp)
        print(f"{'model':8s} {'h/l':>7s} {'nodes':>6s} {'energy':>12s} {'exact':>8s} {'rel.err':>9s} {'profile err':>11s} {'wall s':>7s}")
        for model in ("at1", "at2", "fourth"):
            for ratio in ladders:
                text, probes = profile_scene(model, ratio * L_CHAR)
                fig, wall, _ = run(lmeform, text, work, f"profile_{model}_{ratio}")
                q = fig["quantities"]
                energy = q["dissipated"]
                values = [q[f"p{k}"] for k in range(len(probes))]
                err = max(abs(v - profile_exact(model, x)) for v, x in zip(values, probes))
                rel = abs(energy - ENERGY_EXACT[model]) / ENERGY_EXACT[model]
                nodes = fig.get("nodes", int(round(1 / (ratio * L_CHAR))) + 1)
                print(f"{model:8s} {ratio:7.4f} {nodes:6d} {energy:12.8f} {ENERGY_EXACT[model]:8.4f} {rel:9.2e} {err:11.2e} {wall:7.2f}")
                records.append({"case": f"profile_{model}", "model": model, "l": L_CHAR, "h_min": ratio * L_CHAR, "h_over_l": ratio,
                                "nodes": nodes, "steps": 0, "dissipated": energy, "reference": ENERGY_EXACT[model], "rel_error": rel,
                                "profile_max_error": err, "wall_s": wall})
                curves[(model, ratio)] = (probes, values)
        print(f"\n{'model':8s} {'steps':>6s} {'peak force':>11s} {'exact':>9s} {'rel.err':>9s} {'wall s':>7s}")
        for model in ("at1", "at2", "fourth"):
            steps = (408 if model == "at1" else 160) if not quick else (204 if model == "at1" else 80)
            text, delta_max = bar_scene(model, steps)
            fig, wall, outdir = run(lmeform, text, work, f"bar_{model}")
            history = json.loads((outdir / "history.json").read_text())
            rows = history["steps"] if isinstance(history, dict) else history
            forces = [r["quantities"]["force"] for r in rows]
            i = max(range(len(forces)), key=lambda j: forces[j])
            peak = forces[i]
            # the parabola through the largest sample and its neighbours (the sampled peak's error is O(step^2))
            if 0 < i < len(forces) - 1:
                f0, f1, f2 = forces[i - 1], forces[i], forces[i + 1]
                denom = f0 - 2 * f1 + f2
                if denom < 0 and f2 > 0.9 * f1:   # a smooth maximum (AT2, fourth order), not a snap-back (AT1)
                    peak = f1 - (f2 - f0) ** 2 / (8 * denom)
            rel = abs(peak - SIGMA_C[model]) / SIGMA_C[model]
            print(f"{model:8s} {steps:6d} {peak:11.6f} {SIGMA_C[model]:9.6f} {rel:9.2e} {wall:7.2f}")
            records.append({"case": "homogeneous_bar", "model": model, "l": L_CHAR, "h_min": 0.05, "nodes": 21, "steps": steps,
                            "peak_force": peak, "reference": SIGMA_C[model], "rel_error": rel, "wall_s": wall})
    merge_records(out / "fracture.json", records, {"profile_at1", "profile_at2", "profile_fourth", "homogeneous_bar"})
    plot(curves, out / "fracture_profiles.png", ladders)


def merge_records(path, records, cases):
    old = json.loads(path.read_text()) if path.exists() else {"records": []}
    kept = [r for r in old.get("records", []) if r.get("case") not in cases]
    path.write_text(json.dumps({"records": kept + records}, indent=1))
    print(f"wrote {path}")


def plot(curves, path, ladders):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, model in zip(axes, ("at1", "at2", "fourth")):
        xs = [L_CHAR * k / 200 for k in range(0, 801)]
        ax.plot([x / L_CHAR for x in xs], [profile_exact(model, x) for x in xs], "k-", lw=1, label="closed form")
        for ratio in ladders:
            probes, values = curves[(model, ratio)]
            ax.plot([x / L_CHAR for x in probes], values, "o", ms=3, label=f"h/l = {ratio:g}")
        ax.set_title({"at1": "AT1", "at2": "AT2", "fourth": "fourth order (free slope)"}[model])
        ax.set_xlabel("x / l")
        ax.set_ylabel("v")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
