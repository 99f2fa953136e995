#!/usr/bin/python3
"""Vesicle kinetics under an increase of membrane area (seed Sec. 3.6, Paper B Fig. 7).

The area constraint's target A0 grows by a factor 1 + GROWTH over t* in [0, T] at fixed volume
([dynamics.schedule] A0 = { rate = GROWTH/T, until = T }), then the vesicle relaxes at the new area
until t* = T_END_FACTOR * T. Variants of the dynamics scenes (demos/dynamics/oblate_relaxation.toml):

* "circle": Cartesian 2D, a circle of radius 0.25 in the unit box (no-slip walls), its radius
  perturbed by small modes 2..10 (fixed pseudo-random phases: a perfect circle on a uniform grid has
  only the grid's 4-fold imperfection to buckle from);
* "sphere": axisymmetric, a sphere of radius 0.4 in [0, 1] x [0, 1.6], perturbed alike in its polar
  angle (even and odd Legendre-like modes cos(m theta)).

Per run it records the energy against t*, steps, time per step and wall time, and counts the
protrusions of the phi = 0 contour: the local maxima of its distance from the vesicle's centroid
along the contour whose prominence (over the neighbouring minima) exceeds PROMINENCE * R0.

    /usr/bin/python3 demos/dynamics/area_increase.py [--lmeform build/lmeform] [--only circle_fast ...]
        [--plots-only] [--figures docs/figures]

Writes the scenes, logs and runs under build/kinetics/area_increase/, the summary
build/kinetics/area_increase.json and the figures kinetics_area_*.png.
"""
import argparse
import json
import math
import os
import random
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "build", "kinetics", "area_increase")
GROWTH = 0.3            # A0 grows by 30 %
T_END_FACTOR = 2.0      # relax for as long as the area grew
PROMINENCE = 0.06       # a protrusion rises at least 6 % of R0 above its neighbouring dips (0.015 in 2D: the
                        # piecewise-linear contour wiggles by about h/2 = 0.01 at the node scale)
RUN_TIMEOUT_S = 14 * 60

# name -> geometry and the time T (t*) over which A0 grows by GROWTH
CASES = {
    "circle_fast":   dict(geometry="circle", T=0.003),
    "circle_medium": dict(geometry="circle", T=0.03),
    "circle_slow":   dict(geometry="circle", T=0.3),
    "sphere_fast":   dict(geometry="sphere", T=0.003),
    "sphere_medium": dict(geometry="sphere", T=0.03),
    "sphere_slow":   dict(geometry="sphere", T=0.3),
}

GEOMETRY = {
    # uniform nodes: eps/h = 2 as in oblate_relaxation.toml; eps/R0 = 0.16 (2D), 0.125 (sphere)
    # max_steps keeps a run near 10 minutes on one core (measured: about 1.3 s per step in 2D)
    "circle": dict(R0=0.25, centre=(0.5, 0.5), eps=0.04, spacing=0.02, lower=(0.0, 0.0), upper=(1.0, 1.0),
                   max_steps=400),
    "sphere": dict(R0=0.4, centre=(0.0, 0.8), eps=0.05, spacing=0.025, lower=(0.0, 0.0), upper=(1.0, 1.6),
                   max_steps=200),
}


def perturbation(geometry):
    """sum_m a_m cos(m theta - p_m) as an expression in c = cos(theta), s = sin(theta) (Chebyshev
    T_m(c) and s U_{m-1}(c) written out by recursion), theta the polar angle about the centre."""
    rng = random.Random(20261204)
    modes = range(2, 11)
    amplitude = 0.004
    cx, cy = GEOMETRY[geometry]["centre"]
    rr = f"sqrt((x[0] - {cx})^2 + (x[1] - {cy})^2 + 1e-14)"
    c = f"((x[{0 if geometry == 'circle' else 1}] - {cx if geometry == 'circle' else cy})/{rr})"
    s = f"((x[{1 if geometry == 'circle' else 0}] - {cy if geometry == 'circle' else cx})/{rr})"
    # Chebyshev polynomials as coefficient lists in c
    T = [[1.0], [0.0, 1.0]]
    U = [[1.0], [0.0, 2.0]]
    for m in range(2, 11):
        T.append([2 * a for a in [0.0] + T[m - 1]])
        for i, a in enumerate(T[m - 2]):
            T[m][i] -= a
        U.append([2 * a for a in [0.0] + U[m - 1]])
        for i, a in enumerate(U[m - 2]):
            U[m][i] -= a
    cos_poly = [0.0] * 12
    sin_poly = [0.0] * 12
    for m in modes:
        phase = rng.uniform(0, 2 * math.pi)
        if geometry == "sphere":
            phase = 0.0 if rng.random() < 0.5 else math.pi   # axisymmetric: even in r -> only cos
        for i, a in enumerate(T[m]):
            cos_poly[i] += amplitude * math.cos(phase) * a
        for i, a in enumerate(U[m - 1]):
            sin_poly[i] += amplitude * math.sin(phase) * a

    def horner(coefficients):
        while coefficients and abs(coefficients[-1]) < 1e-15:
            coefficients = coefficients[:-1]
        if not coefficients:
            return "0"
        text = f"({coefficients[-1]:.12g})"
        for a in reversed(coefficients[:-1]):
            text = f"({a:.12g} + {c}*{text})"
        return text

    terms = horner(cos_poly)
    if any(abs(a) > 1e-15 for a in sin_poly):
        terms += f" + {s}*{horner(sin_poly)}"
    return rr, terms


def scene_text(name, case):
    g = GEOMETRY[case["geometry"]]
    T = case["T"]
    rr, noise = perturbation(case["geometry"])
    R0 = g["R0"]
    phi = f"tanh(({R0}*(1 + {noise}) - {rr}) / (sqrt(2)*eps))"
    axisym = case["geometry"] == "sphere"
    forms = (["helfrich_lagrangian_axisymmetric", "area_lagrangian_axisymmetric",
              "volume_lagrangian_axisymmetric", "dissipation_axisymmetric"] if axisym else
             ["helfrich_lagrangian", "area_lagrangian", "volume_lagrangian", "dissipation"])
    walls = '["r_max", "z_min", "z_max"]' if axisym else '["x_min", "x_max", "y_min", "y_max"]'
    axis = ('\n[[dirichlet]]\nboundary = ["axis"]\nunknown = "y"\ncomponents = [0]\nvalue = 0.0\n'
            if axisym else "")
    t_end = T_END_FACTOR * T
    return f"""# Written by demos/dynamics/area_increase.py: A0 grows by {GROWTH:.0%} over t* = {T} at fixed volume,
# then the vesicle relaxes to t* = {t_end}.
[scene]
name = "{name}"
description = "Area increase by {GROWTH:.0%} over t* = {T} at fixed volume ({case['geometry']})"
coordinates = "{'axisymmetric' if axisym else 'cartesian'}"

[domain]
lower = [{g['lower'][0]}, {g['lower'][1]}]
upper = [{g['upper'][0]}, {g['upper'][1]}]

[nodes]
spacing = {g['spacing']}
gamma = 0.8
quadrature_points = 6

[model]
forms = [{', '.join(f'"{f}"' for f in forms)}]
energy = "bending"

[constants]
k = 1.0
eps = {g['eps']}
C0 = 0.0
mu = 1.0
lambda = 0.0

[constraints]
area = "initial"
volume = "initial"

[coefficients]
phi = "{phi}"

[qdata]
phi0 = {{ field = "phi", jet = "value" }}
gphi0 = {{ field = "phi", jet = "gradient" }}
hphi0 = {{ field = "phi", jet = "hessian" }}

[initial]
y = "x[0]*e(0) + x[1]*e(1)"

[[dirichlet]]
boundary = {walls}
unknown = "y"
value = "x[0]*e(0) + x[1]*e(1)"
{axis}
[dynamics]
method = "vti"
dissipation = "dissipation"
time_unit = {R0 ** 3:.6g}          # mu R0^3 / k
t_end = {t_end}
dt = {T / 200:.6g}
dt_max = {T / 10:.6g}
output_every = 10
energy_decrement = 2.0
min_jacobian = 0.05
reset_distortion = 4.0
max_steps = {g['max_steps']}
report_times = [{T / 3:.6g}, {2 * T / 3:.6g}, {T}]

[dynamics.schedule]
A0 = {{ rate = {GROWTH / T:.12g}, until = {T} }}

[output]
directory = "{os.path.join(OUT, name)}"
"""


def run(lmeform, name, case, gate=None):
    while gate and os.path.exists(gate):   # another lmeform job holds the core
        time.sleep(5)
    os.makedirs(OUT, exist_ok=True)
    scene = os.path.join(OUT, name + ".toml")
    with open(scene, "w") as f:
        f.write(scene_text(name, case))
    log = os.path.join(OUT, name + ".log")
    start = time.time()
    with open(log, "w") as f:
        try:
            rc = subprocess.run([lmeform, "run", scene], stdout=f, stderr=subprocess.STDOUT,
                                timeout=RUN_TIMEOUT_S).returncode
        except subprocess.TimeoutExpired:
            rc = "timeout"
    wall = time.time() - start
    print(f"{name}: exit {rc}, {wall:.0f} s", flush=True)
    return {"exit": rc, "wall_s_measured": wall}


def load_snapshot(path):
    import h5py
    import numpy as np
    with h5py.File(path, "r") as f:
        return (np.asarray(f["nodes"][...], float), np.asarray(f["cells"][...], np.int64),
                np.asarray(f["fields/phi"][...], float))


def contours(nodes, cells, phi, axisym):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    import numpy as np
    if axisym:   # mirror r -> -r so that the contour closes
        off = np.flatnonzero(nodes[:, 0] != 0.0)
        index = np.arange(len(nodes))
        index[off] = len(nodes) + np.arange(off.size)
        nodes = np.vstack([nodes, nodes[off] * [-1.0, 1.0]])
        cells = np.vstack([cells, index[cells][:, ::-1]])
        phi = np.concatenate([phi, phi[off]])
    fig = plt.figure()
    cs = plt.tricontour(mtri.Triangulation(nodes[:, 0], nodes[:, 1], cells), phi, levels=[0.0])
    paths = [p for p in cs.allsegs[0] if len(p) > 3]
    plt.close(fig)
    return paths


def count_protrusions(paths, R0):
    """The protrusions of a membrane: the local maxima of its distance from the centroid as a
    function of the polar angle (the largest distance in each of 180 angular bins, so that the
    contour need not come in one ordered piece: tricontour splits it where the deformed cells
    overlap), counted when they rise PROMINENCE * R0 above both neighbouring minima (cyclic)."""
    import numpy as np
    points = np.vstack(paths)
    centre = points.mean(axis=0)
    rel = points - centre
    angle = np.arctan2(rel[:, 1], rel[:, 0])
    distance = np.linalg.norm(rel, axis=1)
    bins = 180
    index = ((angle + np.pi) / (2 * np.pi) * bins).astype(int) % bins
    d = np.full(bins, np.nan)
    for b, value in zip(index, distance):
        d[b] = value if np.isnan(d[b]) else max(d[b], value)
    filled = np.flatnonzero(~np.isnan(d))
    if filled.size < 8:
        return 0
    grid = np.arange(bins)
    d = np.interp(grid, filled, d[filled], period=bins)
    k = 1   # smooth over three bins (6 degrees)
    d = np.convolve(np.concatenate([d[-k:], d, d[:k]]), np.ones(2 * k + 1) / (2 * k + 1), "valid")
    n = bins
    count = 0
    for i in range(n):
        if d[i] >= d[(i - 1) % n] and d[i] > d[(i + 1) % n]:
            dips = []
            for step in (-1, 1):
                low = d[i]
                j = i
                for _ in range(n):
                    j = (j + step) % n
                    if d[j] > d[i]:
                        break
                    low = min(low, d[j])
                dips.append(low)
            if d[i] - max(dips) > PROMINENCE * R0:
                count += 1
    return count


def analyse(name, case, record):
    import numpy as np
    folder = os.path.join(OUT, name)
    history_path = os.path.join(folder, name + "_history.json")
    if not os.path.isfile(history_path):
        record["error"] = "no history"
        return record
    h = json.load(open(history_path))
    steps = h["steps"]
    g = GEOMETRY[case["geometry"]]
    axisym = case["geometry"] == "sphere"
    record.update(
        T=case["T"], t_end=T_END_FACTOR * case["T"], geometry=case["geometry"], eps=g["eps"],
        spacing=g["spacing"], R0=g["R0"], growth=GROWTH,
        t_reached=steps[-1]["t_star"], steps=len(steps) - 1,
        rejected=sum(s["rejected"] for s in steps), resets=steps[-1]["resets"],
        wall_s=steps[-1]["wall_s"],
        s_per_step=steps[-1]["wall_s"] / max(len(steps) - 1, 1),
        energy_start=steps[0]["energy"], energy_end=steps[-1]["energy"],
        energy_max=max(s["energy"] for s in steps),
        t_energy_max=steps[int(np.argmax([s["energy"] for s in steps]))]["t_star"],
        area_ratio_end=steps[-1]["constraints"][0] / steps[0]["constraints"][0],
        volume_ratio_end=steps[-1]["constraints"][1] / steps[0]["constraints"][1],
        topology_end=steps[-1].get("topology", {}).get("summary"),
        min_det_F=min(s["min_jacobian"] for s in steps),
        times=[s["t_star"] for s in steps], energies=[s["energy"] for s in steps])
    shapes = []
    for entry in h["series"]:
        nodes, cells, phi = load_snapshot(os.path.join(folder, entry["file"]))
        paths = contours(nodes, cells, phi, axisym)
        shapes.append(dict(time=entry["time"], file=entry["file"], contour_pieces=len(paths),
                           protrusions=count_protrusions(paths, g["R0"]) if paths else 0))
    record["shapes"] = shapes
    for key, t in (("at_T", case["T"]), ("at_end", steps[-1]["t_star"])):
        best = min(shapes, key=lambda s: abs(s["time"] - t))
        record[f"protrusions_{key}"] = best["protrusions"]
        record[f"protrusions_{key}_time"] = best["time"]
    record["protrusions_max"] = max(s["protrusions"] for s in shapes)
    return record


def figures(records, figdir):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    import numpy as np
    os.makedirs(figdir, exist_ok=True)
    for geometry in ("circle", "sphere"):
        names = [n for n in CASES if CASES[n]["geometry"] == geometry and "times" in records.get(n, {})]
        if not names:
            continue
        fig, ax = plt.subplots(figsize=(6, 4))
        for n in names:
            r = records[n]
            ax.plot(np.array(r["times"]) / r["T"], r["energies"], label=f"{n.split('_')[1]}: T = {r['T']}")
        ax.set_xlabel("t* / T  (A0 grows by 30 % over t* in [0, T])")
        ax.set_ylabel("E*")
        ax.set_title(f"area increase, {geometry}")
        ax.legend()
        fig.tight_layout()
        fig.savefig(os.path.join(figdir, f"kinetics_area_{geometry}_energy.png"), dpi=130)
        plt.close(fig)
        # snapshots: per rate the start, T/3, 2T/3, T and the end
        fig, axes = plt.subplots(len(names), 5, figsize=(12, 2.6 * len(names)), squeeze=False)
        for row, n in enumerate(names):
            r = records[n]
            wanted = [0.0, r["T"] / 3, 2 * r["T"] / 3, r["T"], r["t_reached"]]
            for col, t in enumerate(wanted):
                s = min(r["shapes"], key=lambda s: abs(s["time"] - t))
                nodes, cells, phi = load_snapshot(os.path.join(OUT, n, s["file"]))
                ax = axes[row][col]
                for p in contours(nodes, cells, phi, geometry == "sphere"):
                    ax.plot(p[:, 0], p[:, 1], "k-", lw=1)
                ax.set_aspect("equal")
                g = GEOMETRY[geometry]
                if geometry == "sphere":
                    ax.set_xlim(-0.75, 0.75), ax.set_ylim(0.1, 1.5)
                else:
                    ax.set_xlim(0.1, 0.9), ax.set_ylim(0.1, 0.9)
                ax.set_xticks([]), ax.set_yticks([])
                ax.set_title(f"{n.split('_')[1]} t*={s['time']:.3g}\n{s['protrusions']} protrusions", fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(figdir, f"kinetics_area_{geometry}_snapshots.png"), dpi=110)
        plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lmeform", default=os.path.join(ROOT, "build", "lmeform"))
    parser.add_argument("--only", nargs="*", default=list(CASES))
    parser.add_argument("--plots-only", action="store_true")
    parser.add_argument("--wait-while", default=None, help="before each run, wait while this file exists")
    parser.add_argument("--figures", default=os.path.join(ROOT, "docs", "figures"))
    parser.add_argument("--overfill", action="store_true",
                        help="only measure and draw the run of demos/dynamics/area_overfill.toml")
    parser.add_argument("--adhesion", nargs="?", const=os.path.join(ROOT, "build", "demo", "adhesion_dynamics"),
                        metavar="RUN_FOLDER", help="only print the measures of the adhesion_dynamics run")
    args = parser.parse_args()
    if args.adhesion:
        adhesion(args.adhesion)
        return
    if args.overfill:
        overfill(args.figures)
        return
    unknown = [n for n in args.only if n not in CASES]
    if unknown:
        sys.exit(f"area_increase.py: unknown case(s) {unknown}; known: {list(CASES)}")
    summary_path = os.path.join(ROOT, "build", "kinetics", "area_increase.json")
    records = json.load(open(summary_path)) if os.path.isfile(summary_path) else {}
    for name in args.only:
        record = records.get(name, {}) if args.plots_only else run(args.lmeform, name, CASES[name], args.wait_while)
        records[name] = analyse(name, CASES[name], dict(record))
        os.makedirs(os.path.dirname(summary_path), exist_ok=True)
        with open(summary_path, "w") as f:
            json.dump(records, f, indent=1)
        r = records[name]
        if "steps" in r:
            print(f"{name}: {r['steps']} steps, t* {r['t_reached']:.4g}/{r['t_end']}, E {r['energy_start']:.4f} -> "
                  f"max {r['energy_max']:.4f} -> {r['energy_end']:.4f}, protrusions at T {r['protrusions_at_T']}, "
                  f"end {r['protrusions_at_end']}, max {r['protrusions_max']}, {r['s_per_step']:.2f} s/step, "
                  f"wall {r['wall_s']:.0f} s", flush=True)
    figures(records, args.figures)
    print_tables(records)


def overfill(figdir):
    """Measures and draws the run of demos/dynamics/area_overfill.toml (the bad-input case of
    docs/kinetics.md): per picked series file the energy, the area over its start value and the
    length and number of pieces of the phi = 0 contour."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    import numpy as np
    folder = os.path.join(ROOT, "build", "kinetics", "area_overfill")
    h = json.load(open(os.path.join(folder, "area_overfill_history.json")))
    steps = h["steps"]
    fig, axes = plt.subplots(1, 3, figsize=(12, 4.2))
    picks = [h["series"][0], h["series"][len(h["series"]) // 2], h["series"][-1]]
    for ax, entry in zip(axes, picks):
        nodes, cells, phi = load_snapshot(os.path.join(folder, entry["file"]))
        paths = contours(nodes, cells, phi, False)
        length = sum(np.sum(np.linalg.norm(np.diff(q, axis=0), axis=1)) for q in paths)
        step = min(steps, key=lambda s: abs(s["t_star"] - entry["time"]))
        ratio = step["constraints"][0] / steps[0]["constraints"][0]
        print(f"t* {entry['time']:.4g}: E {step['energy']:.1f}, A/A(0) {ratio:.3f}, phi = 0 contour {length:.3f} long "
              f"in {len(paths)} piece(s)")
        ax.tricontourf(mtri.Triangulation(nodes[:, 0], nodes[:, 1], cells), phi, levels=20, cmap="coolwarm")
        for q in paths:
            ax.plot(q[:, 0], q[:, 1], "k", lw=1)
        ax.set_aspect("equal")
        ax.set_title(f"t* = {entry['time']:.3g}, A/A(0) = {ratio:.2f}")
    i = max(range(len(steps)), key=lambda i: steps[i]["energy"])
    print(f"largest E {steps[i]['energy']:.1f} at t* {steps[i]['t_star']:.4g}, A/A(0) "
          f"{steps[i]['constraints'][0] / steps[0]['constraints'][0]:.3f}")
    fig.tight_layout()
    fig.savefig(os.path.join(figdir, "kinetics_area_overfill.png"), dpi=100)


def adhesion(folder):
    """Measures of demos/adhesion/adhesion_dynamics.toml's run (docs/kinetics.md): per series file
    (every other one, and the last) the energy, the lowest point of the phi = 0 contour above the
    wall z = 0 (in eps = 0.05), the contact radius (the largest r of the contour within 0.005 of its
    lowest z), the top of the contour and min det F at that step, as markdown rows."""
    import numpy as np
    h = json.load(open(os.path.join(folder, "adhesion_dynamics_history.json")))
    steps = h["steps"]
    print("| t* | step | E* (bending + adhesion) | lowest φ = 0 above the wall | contact radius | top z | min det F |")
    print("|---|---|---|---|---|---|---|")
    series = h["series"][::2] + ([h["series"][-1]] if (len(h["series"]) - 1) % 2 else [])
    for entry in series:
        nodes, cells, phi = load_snapshot(os.path.join(folder, entry["file"]))
        points = np.vstack(contours(nodes, cells, phi, False))
        lowest = points[:, 1].min()
        contact = np.abs(points[points[:, 1] < lowest + 0.005][:, 0]).max()
        step = min(steps, key=lambda s: abs(s["t_star"] - entry["time"]))
        print(f"| {entry['time']:.3g} | {step['step']} | {step['energy']:.4f} | {lowest:.4f} ({lowest / 0.05:.2f} ε) | "
              f"{contact:.3f} | {points[:, 1].max():.3f} | {step['min_jacobian']:.3f} |")


def print_tables(records):
    """The markdown rows of docs/kinetics.md, one per run."""
    for name in CASES:
        r = records.get(name, {})
        if "steps" not in r:
            continue
        start = min(r["shapes"], key=lambda s: s["time"])["protrusions"]
        at_T = r["energies"][min(range(len(r["times"])), key=lambda i: abs(r["times"][i] - r["T"]))]
        print(f"| {name.split('_')[1]} | {r['T']} | {r['steps']} ({r['rejected']}) | {r['t_reached']:.4g} of {r['t_end']:.4g} | "
              f"{r['energy_start']:.3f} → {at_T:.2f} ({r['energy_max']:.2f}) → {r['energy_end']:.2f} | "
              f"{start} → {r['protrusions_at_T']} / {r['protrusions_at_end']} | {r['s_per_step']:.2f} | {r['wall_s']:.0f} s |")


if __name__ == "__main__":
    main()
