#!/usr/bin/env python3
"""Upsetting of a viscoplastic billet between two plates (seed Sec. 5.2): runs the scenes of this
folder, checks them against the exact homogeneous compression (frictionless) and the slab-method
estimate (sticking), measures pressure oscillations with and without stabilization, and writes
build/bench/forming.json and the figures of docs/forming.md.

  /usr/bin/python3 demos/forming/forming_study.py [--lmeform build/lmeform] [--quick]
      [--json build/bench/forming.json] [--figures docs/figures]

--quick runs the seed-size billet only (CI time); the default adds a finer node set.
"""
import argparse
import csv
import json
import math
import os
import pathlib
import re
import subprocess
import sys
import time
import tomllib

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent


def flow_stress(K, m, rate):
    """Norton-Hoff flow stress sqrt(3) K (sqrt(3) rate)^m (viscoplastic.inc)."""
    return math.sqrt(3.0) * K * (math.sqrt(3.0) * rate) ** m


def variant(scene, name, out_dir, spacing=None, constants=None, count=None, dirichlet_top=None):
    """A copy of a scene with another name, output folder, spacing or constants."""
    text = (HERE / scene).read_text()
    text = re.sub(r'^name = ".*"', f'name = "{name}"', text, count=1, flags=re.M)
    text = re.sub(r'^directory = ".*"', f'directory = "{out_dir}"', text, count=1, flags=re.M)
    if spacing is not None:
        text = re.sub(r'^spacing = [0-9.e-]+', f'spacing = {spacing}', text, count=1, flags=re.M)
    if count is not None:
        text = re.sub(r'^count = [0-9]+', f'count = {count}', text, count=1, flags=re.M)
        dt = 0.25 / count
        text = re.sub(r'^time_step = [0-9.e-]+', f'time_step = {dt}', text, count=1, flags=re.M)
    for key, value in (constants or {}).items():
        text = re.sub(rf'^{key} = [0-9.e-]+', f'{key} = {value}', text, count=1, flags=re.M)
    path = pathlib.Path(out_dir) / f"{name}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def run(lmeform, scene):
    t0 = time.time()
    proc = subprocess.run([lmeform, "run", str(scene)], capture_output=True, text=True)
    wall = time.time() - t0
    if proc.returncode not in (0, 2):  # 2: stopped early, with its converged steps on disk
        sys.stderr.write(proc.stdout[-3000:] + proc.stderr[-3000:])
        raise SystemExit(f"lmeform failed on {scene}")
    status = next((l for l in proc.stdout.splitlines() if l.startswith("status")), "status ?")
    return wall, status.split(None, 1)[1].strip()


def history(out_dir):
    with open(pathlib.Path(out_dir) / "history.csv") as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def hull_points(points):
    """The convex hull of 2D points, counter-clockwise (monotone chain)."""
    pts = sorted(set(map(tuple, points)))
    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def hull_volume(points):
    """Volume of revolution (about r = 0) of the convex hull of (r, z) points: 2 pi times the
    hull's first moment of area (Pappus). The run's `volume` quantity integrates over its background
    cells, which drop the hull's slivers (flow.sliver_tolerance): this is the body's own."""
    hull = hull_points(points)
    moment = sum((x0 + x1) * (x0 * y1 - x1 * y0) for (x0, y0), (x1, y1) in zip(hull, hull[1:] + hull[:1]))
    return 2 * math.pi * abs(moment) / 6


def hull_area(points):
    """Area of the convex hull of 2D points (plane strain: the body's own area)."""
    hull = hull_points(points)
    return abs(sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(hull, hull[1:] + hull[:1]))) / 2


def series_volumes(out_dir, name, plane=False):
    """The hull volume (plane: area) of every step written in the run's series, by step."""
    import h5py
    volumes = {}
    for path in (pathlib.Path(out_dir) / "series").glob(f"{name}_*.h5"):
        found = re.findall(r"_(\d+)\.h5$", path.name)
        if not found or "checkpoint" in path.name:
            continue
        with h5py.File(path) as f:
            pts = f["nodes"][:].tolist()
            volumes[int(f.attrs["step"])] = hull_area(pts) if plane else hull_volume(pts)
    return volumes


def settings(scene):
    s = tomllib.loads(pathlib.Path(scene).read_text())
    c = s["constants"]
    lower, upper = s["domain"]["lower"], s["domain"]["upper"]
    return dict(K=c["K"], m=c["m"], R0=upper[0] - lower[0], h0=upper[1] - lower[1], V=1.0, dt=s["flow"]["time_step"],
                count=s["flow"]["count"])


def analyse(scene, rows, friction, volumes=None):
    """Per-step errors of a run against the exact homogeneous compression / the slab estimate.
    `volumes`: the hull volume by step (else the run's integrated volume)."""
    p = settings(scene)
    out = []
    for r in rows:
        if "volume" not in r and "area" in r:
            r = dict(r, volume=r["area"])
        if volumes and int(r["step"]) in volumes:
            r = dict(r, volume=volumes[int(r["step"])])
        if not out:
            V0 = r["volume"]
        h = r["extent_max[1]"] - r["extent_min[1]"]
        R = r["extent_max[0]"]
        rate = p["V"] / h
        sigma = flow_stress(p["K"], p["m"], rate)
        force = -r["force"]
        R_mean = math.sqrt(r["volume"] / (math.pi * h))  # the radius of a cylinder of the same volume
        if friction == "plane_strain":  # frictionless, plane strain: per unit depth
            R_exact = p["R0"] * p["h0"] / h
            reference = R * 2 / math.sqrt(3) * flow_stress(p["K"], p["m"], 2 / math.sqrt(3) * rate)
        elif friction == "frictionless":
            R_exact = p["R0"] * math.sqrt(p["h0"] / h)
            reference = math.pi * R ** 2 * sigma
        else:
            R_exact = float("nan")
            reference = math.pi * R_mean ** 2 * sigma * (1 + 2 * 1.0 * R_mean / (3 * math.sqrt(3) * 2 * h))
        out.append(dict(step=int(r["step"]), h=h, R=R, R_mean=R_mean, force=force, reference=reference,
                        radius_error=abs(R / R_exact - 1) if friction != "sticking" else float("nan"),
                        volume_error=abs(r["volume"] / V0 - 1), force_error=abs(force / reference - 1),
                        contact=r.get("contact_nodes_z_max", float("nan")), anisotropy=r.get("anisotropy", float("nan")),
                        spacing_ratio=r.get("spacing_ratio", float("nan")), rebuild_s=r["rebuild_s"], assembly_s=r["assembly_s"],
                        solve_s=r["solve_s"], iterations=r["iterations"], substeps=r["substeps"]))
    return out


def pressure_oscillation(h5_path, sigma):
    """Node-to-node pressure oscillation: the RMS over interior nodes of p_a minus the mean of its
    Delaunay neighbours, in units of the flow stress sigma. A smooth pressure gives O(h^2 |p''|);
    the checkerboard modes of an unstable equal-order pair give O(|p|). Also the spread
    (max - min) / sigma."""
    import h5py
    import numpy as np
    with h5py.File(h5_path) as f:
        x = f["nodes"][:]
        cells = f["cells"][:]
        p = f["fields/p"][:].ravel() if "fields" in f else f["p"][:].ravel()
    nbrs = [set() for _ in range(len(x))]
    edges = {}
    for c in cells:
        for i in c:
            nbrs[i].update(int(j) for j in c if j != i)
        for a, b in ((c[0], c[1]), (c[1], c[2]), (c[2], c[0])):
            key = (min(a, b), max(a, b))
            edges[key] = edges.get(key, 0) + 1
    boundary = {i for (a, b), n in edges.items() if n == 1 for i in (a, b)}
    d = [p[a] - np.mean([p[b] for b in nbrs[a]]) for a in range(len(x)) if a not in boundary and nbrs[a]]
    return float(np.sqrt(np.mean(np.square(d))) / sigma), float((p.max() - p.min()) / sigma)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lmeform", default=str(ROOT / "build" / "lmeform"))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", default=str(ROOT / "build" / "bench" / "forming.json"))
    ap.add_argument("--figures", default="")
    ap.add_argument("--work", default=str(ROOT / "build" / "forming"))
    ap.add_argument("--figures-only", action="store_true", help="redraw the figures from the runs of --work and --json")
    args = ap.parse_args()
    work = pathlib.Path(args.work)
    if args.figures_only:
        runs = []
        for rec in json.load(open(args.json))["records"]:
            friction = "plane_strain" if rec["case"] == "upsetting_plane_strain" else rec["friction"]
            name = f"{rec['case']}_{friction}_{rec['label'].replace(' ', '_')}"
            out = work / name
            steps = analyse(out / f"{name}.toml", history(out), friction, series_volumes(out, name, plane=friction == "plane_strain"))
            runs.append((rec, steps, out, name))
        figures(runs, pathlib.Path(args.figures or "docs/figures"))
        return
    # (case, friction, scene, spacing, constants, label); "plane_strain" selects the plane-strain references
    cases = [("upsetting", "frictionless", "upsetting_frictionless.toml", 0.025, {}, "seed size"),
             ("upsetting_plane_strain", "plane_strain", "upsetting_plane_strain.toml", 0.025, {}, "seed size"),
             ("upsetting", "sticking", "upsetting_sticking.toml", 0.025, {}, "seed size"),
             ("upsetting_unstabilized", "sticking", "upsetting_sticking.toml", 0.025, {"C": 0.0}, "unstabilized")]
    if not args.quick:
        cases += [("upsetting", "frictionless", "upsetting_frictionless.toml", 0.0125, {}, "fine"),
                  ("upsetting", "sticking", "upsetting_sticking.toml", 0.0125, {}, "fine")]
    records, runs = [], []
    for case, friction, scene, spacing, constants, label in cases:
        name = f"{case}_{friction}_{label.replace(' ', '_')}"
        out = work / name
        path = variant(scene, name, out, spacing=spacing, constants=constants)
        wall, status = run(args.lmeform, path)
        rows = history(out)
        steps = analyse(path, rows, friction, series_volumes(out, name, plane=friction == "plane_strain"))
        last = steps[-1]
        p = settings(path)
        sigma0 = flow_stress(p["K"], p["m"], p["V"] / p["h0"])
        osc0, spread0 = pressure_oscillation(out / "series" / f"{name}_000000.h5", sigma0)
        osc, spread = pressure_oscillation(out / f"{name}.h5", flow_stress(p["K"], p["m"], p["V"] / last["h"]))
        nodes = int(round((p["R0"] / spacing + 1) * (p["h0"] / spacing + 1)))
        rec = dict(case=case, friction="frictionless" if friction == "plane_strain" else friction, label=label,
                   nodes=nodes, steps=last["step"], height_ratio=last["h"] / p["h0"],
                   radius_error=max(s["radius_error"] for s in steps) if friction != "sticking" else None,
                   volume_error=max(s["volume_error"] for s in steps), force=last["force"], force_reference=last["reference"],
                   force_error_max=max(s["force_error"] for s in steps), pressure_oscillation_start=osc0,
                   pressure_spread_start=spread0, pressure_oscillation=osc, pressure_spread=spread,
                   redistributions=int(rows[-1].get("redistributions", 0)), nodes_end=int(rows[-1].get("nodes", nodes)),
                   contact_nodes_end=int(rows[-1].get("contact_nodes_z_max", rows[-1].get("contact_nodes_y_max", 0))),
                   newton_mean=sum(s["iterations"] for s in steps) / len(steps),  # of the solve that closes each step
                   stabilization_C=constants.get("C", 0.1), status=status,
                   rebuild_s_per_step=sum(s["rebuild_s"] for s in steps) / len(steps),
                   assembly_s_per_step=sum(s["assembly_s"] for s in steps) / len(steps),
                   solve_s_per_step=sum(s["solve_s"] for s in steps) / len(steps), wall_s=wall)
        records.append(rec)
        runs.append((rec, steps, out, name))
        print(f"{name:32s} nodes {nodes:5d} steps {rec['steps']:3d} h/h0 {rec['height_ratio']:.3f} "
              f"radius_err {rec['radius_error'] if rec['radius_error'] is not None else float('nan'):.2e} "
              f"volume_err {rec['volume_error']:.2e} force {rec['force']:.4f} ref {rec['force_reference']:.4f} "
              f"(max err {rec['force_error_max']:.2e}) p_osc start {osc0:.2e} end {osc:.2e} spread {spread0:.2e}/{spread:.2e} "
              f"per step: rebuild {rec['rebuild_s_per_step']:.3f} s assembly {rec['assembly_s_per_step']:.3f} s "
              f"solve {rec['solve_s_per_step']:.3f} s  wall {wall:.1f} s  [{status}]", flush=True)
    os.makedirs(os.path.dirname(args.json), exist_ok=True)
    tmp = args.json + ".tmp"
    with open(tmp, "w") as f:
        json.dump({"benchmark": "forming", "records": records}, f, indent=1)
    os.replace(tmp, args.json)
    print(f"wrote {args.json}")
    if args.figures:
        figures(runs, pathlib.Path(args.figures))


def figures(runs, folder):
    import h5py
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    folder.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for rec, steps, out, name in runs:
        red = [1 - s["h"] / steps[0]["h"] for s in steps]
        ax[0].plot(red, [s["force"] for s in steps], label=f"{rec['friction']}{' plane strain' if 'plane' in rec['case'] else ''} ({rec['label']}, {rec['nodes']} nodes)")
        if rec["label"] == "seed size" and rec["case"] == "upsetting":
            ax[0].plot(red, [s["reference"] for s in steps], "k--" if rec["friction"] == "frictionless" else "k:", lw=1,
                       label="pi R^2 sigma_bar (exact)" if rec["friction"] == "frictionless" else "slab estimate, m = 1")
        ax[1].semilogy(red, [max(s["volume_error"], 1e-16) for s in steps], label=f"{name}")
    ax[0].set_xlabel("height reduction 1 - h/h0")
    ax[0].set_ylabel("plate force")
    ax[0].legend(fontsize=7)
    ax[1].set_xlabel("height reduction 1 - h/h0")
    ax[1].set_ylabel("|V/V0 - 1|")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(folder / "forming_force.png", dpi=110)
    plt.close(fig)
    # The free surface (the hull of the nodes away from the axis) at five stages, frictionless and sticking.
    fig, ax = plt.subplots(1, 1, figsize=(6, 4))
    for tag, style in (("upsetting_frictionless_seed_size", "--"), ("upsetting_sticking_seed_size", "-")):
        match = [r for r in runs if r[3] == tag]
        if not match:
            continue
        rec, steps, out, name = match[0]
        for k in (0, 25, 50, 75, 100):
            path = out / "series" / f"{name}_{k:06d}.h5"
            if not path.exists():
                continue
            with h5py.File(path) as f:
                x = f["nodes"][:]
            outline = hull_points(x.tolist())
            prof = [(z, r) for r, z in outline + outline[:1]]
            ax.plot([r for z, r in prof], [z for z, r in prof], style, lw=1, label=f"{rec['friction']} step {k}")
    ax.set_xlabel("r")
    ax.set_ylabel("z (mid-plane z = 0)")
    ax.set_title("outline of the half billet (the hull of its nodes)", fontsize=9)
    ax.set_aspect("equal")
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(folder / "forming_profiles.png", dpi=110)
    plt.close(fig)
    # Pressure at four stages of the sticking run and the unstabilized one (seed Fig. 5.3 b-e).
    for tag in ("upsetting_sticking_seed_size", "upsetting_unstabilized_sticking_unstabilized"):
        match = [r for r in runs if r[3] == tag]
        if not match:
            continue
        rec, steps, out, name = match[0]
        files = sorted((out / "series").glob(f"{name}_*.h5"), key=lambda p: int(re.findall(r"_(\d+)\.h5$", p.name)[0]) if re.findall(r"_(\d+)\.h5$", p.name) else -1)
        series = [p for p in files if re.findall(r"_(\d+)\.h5$", p.name)]
        if not series:
            continue
        picks = [series[int(round(k * (len(series) - 1) / 3))] for k in range(4)]
        fig, axes = plt.subplots(1, 5, figsize=(17, 3.6))
        for ax_, path in zip(axes[:4], picks):
            with h5py.File(path) as f:
                x = f["nodes"][:]
                cells = f["cells"][:]
                p = f["fields/p"][:].ravel() if "fields" in f else f["p"][:].ravel()
                step = int(f.attrs["step"])
            tri = mtri.Triangulation(x[:, 0], x[:, 1], cells)
            im = ax_.tripcolor(tri, p, shading="gouraud", cmap="viridis")
            ax_.set_aspect("equal")
            ax_.set_title(f"p, step {step}", fontsize=9)
            fig.colorbar(im, ax=ax_, shrink=0.7)
        with h5py.File(picks[-1]) as f:
            x = f["nodes"][:]
            cells = f["cells"][:]
            v = f["fields/v"][:] if "fields" in f else f["v"][:]
        tri = mtri.Triangulation(x[:, 0], x[:, 1], cells)
        im = axes[4].tripcolor(tri, v.reshape(-1, 2)[:, 1], shading="gouraud", cmap="coolwarm")
        axes[4].set_aspect("equal")
        axes[4].set_title("v_z, last step", fontsize=9)
        fig.colorbar(im, ax=axes[4], shrink=0.7)
        fig.tight_layout()
        fig.savefig(folder / f"forming_{tag}.png", dpi=110)
        plt.close(fig)


if __name__ == "__main__":
    main()
