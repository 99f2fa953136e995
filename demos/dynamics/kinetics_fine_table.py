#!/usr/bin/env python3
"""Prints the rows of the table of docs/kinetics.md section 3 from the fine kinetics runs: per
deflation time T the steps, E* at t* = T and at the end, V/V0 and the area drift at the end, the
node count, resets, wall time and time per step (from <name>_history.json and the run's --json).
    /usr/bin/python3 demos/dynamics/kinetics_fine_table.py build/demo 0.01 0.03 0.1
A run stopped by hand writes no history; its progress lines (the run's stdout) and series files
stand in for it (constraints relative to the start, two digits, as printed):
    /usr/bin/python3 demos/dynamics/kinetics_fine_table.py --rebuild-history build/demo/kinetics_fine_0.01 LOG
Then the phi = 0 contour's equator r, thickness on the axis and largest thickness at t* = T and at
the end of each run (the series files), and of the static equilibrium at v = 0.8.
"""
import json
import os
import sys


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    out = sys.argv[1]
    print("| T | steps (rejected) | t* reached | E* at t* = T | E* at the end | V/V0 | area drift | nodes | resets | wall | s per step |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for until in sys.argv[2:]:
        name = f"kinetics_fine_{until}"
        history_path = os.path.join(out, name, f"{name}_history.json")
        summary_path = os.path.join(out, f"{name}.json")
        if not os.path.isfile(history_path):
            print(f"| {until} | no history ({history_path}) |")
            continue
        history = json.load(open(history_path))
        steps = history["steps"]
        summary = json.load(open(summary_path)) if os.path.isfile(summary_path) else {}
        T = float(until)
        at_T = [s for s in steps if abs(s["t_star"] - T) < 1e-12 * max(1.0, T)]
        e_T = f"{at_T[0]['energy']:.4f}" if at_T else "not reached"
        first, last = steps[0], steps[-1]
        volume_ratio = last["constraints"][1] / first["constraints"][1]
        area_drift = max(abs(s["constraints"][0] / first["constraints"][0] - 1.0) for s in steps)
        nodes = [entry["nodes"] for entry in history["series"]]
        wall = last["wall_s"]
        per_step = (wall - first["wall_s"]) / max(1, last["step"])
        print(f"| {until} | {last['step']} ({sum(s['rejected'] for s in steps)}) | {last['t_star']:.4g} | {e_T} | "
              f"{last['energy']:.4f} | {volume_ratio:.5f} | {area_drift:.1e} | {nodes[0]} / {nodes[-1]} | "
              f"{last['resets']} | {wall:.0f} s | {per_step:.1f} s |"
              + (f" status: {summary.get('status', '')}" if summary else ""))


def rebuild_history(folder, log_path):
    import glob
    import re

    import h5py

    name = os.path.basename(os.path.normpath(folder))
    pattern = re.compile(r"^step\s+(\d+)\s+t\* (\S+)\s+dt\* (\S+)\s+E (\S+)\s+Newton\s+(\d+)\s+rejected (\d+)\s+"
                         r"resets (\d+)\s+area (\S+)\s+volume (\S+)\s+det F (\S+)\s+(\S+) s")
    steps = []
    for line in open(log_path):
        m = pattern.match(line)
        if m:
            steps.append({"step": int(m[1]), "t_star": float(m[2]), "dt_star": float(m[3]), "energy": float(m[4]),
                          "newton_iterations": int(m[5]), "rejected": int(m[6]), "resets": int(m[7]),
                          "constraints": [1.0 + float(m[8]), 1.0 + float(m[9])], "min_jacobian": float(m[10]),
                          "wall_s": float(m[11])})
    series = []
    for path in sorted(glob.glob(os.path.join(folder, "series", "*.h5"))):
        with h5py.File(path, "r") as f:
            series.append({"file": os.path.relpath(path, folder), "time": float(f.attrs["t_star"]),
                           "nodes": int(f["nodes"].shape[0])})
    history = {"method": "vti", "scene": name, "constraints": ["area", "volume"], "steps": steps, "series": series,
               "rebuilt_from_log": os.path.abspath(log_path)}
    with open(os.path.join(folder, f"{name}_history.json"), "w") as f:
        json.dump(history, f, indent=1)
    print(f"{name}: {len(steps)} steps, {len(series)} series files from {log_path}")


def shapes():
    out = sys.argv[1]
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
    import matplotlib
    matplotlib.use("Agg")
    import plot_dynamics

    for until in sys.argv[2:]:
        name = f"kinetics_fine_{until}"
        folder = os.path.join(out, name)
        history_path = os.path.join(folder, f"{name}_history.json")
        if not os.path.isfile(history_path):
            continue
        series = json.load(open(history_path))["series"]
        picks = [entry for entry in series if abs(entry["time"] - float(until)) < 1e-12 * max(1.0, float(until))]
        picks.append(series[-1])
        for entry in picks:
            nodes, cells, phi, _ = plot_dynamics.load_snapshot(os.path.join(folder, entry["file"]))
            plot_dynamics.print_axisymmetric_profile(f"T = {until}, t* = {entry['time']:.4g} ({entry['nodes']} nodes)",
                                                     nodes, cells, phi)
    for name in ("kinetics_fine_equilibrium", "kinetics_fine_start"):
        path = os.path.join(out, name, f"{name}.h5")
        if os.path.isfile(path):
            nodes, cells, phi, _ = plot_dynamics.load_snapshot(path)
            plot_dynamics.print_axisymmetric_profile(name, nodes, cells, phi)


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--rebuild-history":
        rebuild_history(sys.argv[2], sys.argv[3])
    else:
        main()
        shapes()
