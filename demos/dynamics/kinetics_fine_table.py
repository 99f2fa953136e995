#!/usr/bin/env python3
"""Prints the rows of the table of docs/kinetics.md section 3 from the fine kinetics runs: per
deflation time T the steps, E* at t* = T and at the end, V/V0 and the area drift at the end, the
node count, resets, wall time and time per step (from <name>_history.json and the run's --json).
    /usr/bin/python3 demos/dynamics/kinetics_fine_table.py build/demo 0.01 0.1 1
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


if __name__ == "__main__":
    main()
