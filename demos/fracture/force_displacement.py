#!/usr/bin/env python3
"""Force-displacement of a load-stepped fracture run (SENT, SENS), optionally overlaid with a
FEniCSx reference run (demos/fracture/fenicsx_fracture.py JSON): the peak force, the displacement
at the peak, steps, wall time, and per step the alternations and the seconds of assembly and solve.
    force_displacement.py RUN_DIR CASE OUT_DIR [--fenicsx JSON] [--reference KN --cite TEXT] [--l 0.015 --h 0.0075]
Appends a record (case sent or sens; it replaces the record of the same case and l) to
OUT_DIR/fracture.json and draws OUT_DIR/fracture_CASE.png (fracture_CASE_lL.png for l other than 0.015).
"""
import json
import pathlib
import sys


def arg(name, default=None):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def main():
    run, case, out = pathlib.Path(sys.argv[1]), sys.argv[2], pathlib.Path(sys.argv[3])
    rows = json.loads((run / "history.json").read_text())["steps"]
    delta = [r["constants"]["delta"] for r in rows]
    force = [r["quantities"]["force"] for r in rows]
    i = max(range(len(force)), key=lambda j: force[j])
    alternations = [r["quantities"].get("alternations", 0) for r in rows]
    assembly = sum(r["quantities"].get("u_assembly_s", 0) + r["quantities"].get("v_assembly_s", 0) for r in rows)
    solve = sum(r["quantities"].get("u_solve_s", 0) + r["quantities"].get("v_solve_s", 0) for r in rows)
    wall = rows[-1]["wall_s"]
    print(f"{case}: {len(rows) - 1} steps to delta {delta[-1]:.5g}, peak force {force[i]:.4f} kN at delta {delta[i]:.5g} mm; "
          f"{sum(alternations):.0f} alternations (at most {max(alternations):.0f} in a step); assembly {assembly:.0f} s, solves {solve:.0f} s, "
          f"wall {wall:.0f} s")
    nodes = [r["quantities"]["nodes"] for r in rows if "nodes" in r["quantities"]]
    length = float(arg("--l", 0.015))
    record = {"case": case, "model": "at2", "l": length, "h_min": float(arg("--h", 0.0075)), "nodes": int(nodes[-1]) if nodes else None,
              "nodes_at_peak": int(nodes[i]) if nodes else None, "steps": len(rows) - 1, "peak_force": force[i],
              "delta_at_peak": delta[i], "last_delta": delta[-1], "alternations": sum(alternations), "assembly_s": assembly, "solve_s": solve,
              "wall_s": wall}
    fenicsx = arg("--fenicsx")
    ref = None
    if fenicsx:
        ref = json.loads(pathlib.Path(fenicsx).read_text())
        record["fenicsx_peak_force"] = ref["peak_force"]
        record["fenicsx_delta_at_peak"] = ref["delta_at_peak"]
        record["fenicsx_wall_s"] = ref["wall_s"]
    if arg("--reference"):
        record["reference"] = float(arg("--reference"))
        record["reference_source"] = arg("--cite", "")
        record["rel_error"] = abs(force[i] - record["reference"]) / record["reference"]
    out.mkdir(parents=True, exist_ok=True)
    path = out / "fracture.json"
    old = json.loads(path.read_text()) if path.exists() else {"records": []}
    old["records"] = [r for r in old["records"] if r.get("case") != case or r.get("l") != length] + [record]
    path.write_text(json.dumps(old, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        ax.plot(delta, force, "-", lw=1.5, label=f"lmeform (LME, l = {length:g}), peak {force[i]:.3f} kN")
        if ref:
            ax.plot(ref["delta"], ref["force"], "--", lw=1.2, label=f"FEniCSx P1 (l = {ref.get('l', 0.015)}), peak {ref['peak_force']:.3f} kN")
        ax.set_xlabel("imposed displacement (mm)")
        ax.set_ylabel("force (kN)")
        ax.set_title(case.upper())
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / (f"fracture_{case}.png" if length == 0.015 else f"fracture_{case}_l{length:g}.png"), dpi=120)
    except ImportError:
        pass


if __name__ == "__main__":
    main()
