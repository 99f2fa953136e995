#!/usr/bin/env python3
"""SENT on nodes that follow the crack (demos/fracture/sent_adaptive.toml) against the same model on
a band guessed in advance (sent.toml) and FEniCSx (fenicsx_fracture_sent_l0.015.json): force against
displacement, nodes per step, and the final nodes coloured by v. Appends a record (case
"sent_adaptive") to OUT_DIR/fracture.json and draws OUT_DIR/fracture_sent_adaptive.png.
    adaptive_sent.py ADAPTIVE_RUN_DIR OUT_DIR [--fixed FIXED_RUN_DIR] [--fenicsx JSON]
"""
import json
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from gamma_convergence import merge_records  # noqa: E402  (one writer of fracture.json's records)


def arg(name, default=None):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def curve(run):
    rows = json.loads((run / "history.json").read_text())["steps"]
    return rows, [r["constants"]["delta"] for r in rows], [r["quantities"]["force"] for r in rows]


def main():
    run, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    rows, delta, force = curve(run)
    i = max(range(len(force)), key=lambda j: force[j])
    nodes = [int(r["quantities"]["nodes"]) for r in rows]
    alternations = sum(r["quantities"].get("alternations", 0) for r in rows)
    record = {"case": "sent_adaptive", "model": "at2", "l": 0.015, "h_min": 0.006, "nodes": nodes[-1], "nodes_start": nodes[0],
              "steps": len(rows) - 1, "peak_force": force[i], "delta_at_peak": delta[i], "last_delta": delta[-1], "last_force": force[-1],
              "alternations": alternations, "wall_s": rows[-1]["wall_s"], "reference": None, "rel_error": None}
    fenicsx = arg("--fenicsx")
    ref = json.loads(pathlib.Path(fenicsx).read_text()) if fenicsx else None
    if ref:
        record["reference"] = ref["peak_force"]
        record["rel_error"] = (force[i] - ref["peak_force"]) / ref["peak_force"]
    print(f"sent_adaptive: {len(rows) - 1} steps to delta {delta[-1]:.5g}, nodes {nodes[0]} -> {nodes[-1]}, peak {force[i]:.4f} kN at "
          f"delta {delta[i]:.5g}, last force {force[-1]:.4f} kN, {alternations:.0f} alternations, wall {rows[-1]['wall_s']:.0f} s")
    merge_records(out / "fracture.json", [record], {"sent_adaptive"})
    try:
        import h5py
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    axes[0].plot(delta, force, label=f"lmeform, nodes following the crack ({nodes[0]}–{nodes[-1]} nodes)")
    fixed = arg("--fixed")
    if fixed and (pathlib.Path(fixed) / "history.json").exists():
        _, d2, f2 = curve(pathlib.Path(fixed))
        axes[0].plot(d2, f2, "--", label="lmeform, band along y = 0.5 (1104 nodes)")
    if ref:
        axes[0].plot(ref["delta"], ref["force"], ":", label="FEniCSx P1 (AT2, same split)")
    axes[0].set_xlabel("δ (mm)")
    axes[0].set_ylabel("force (kN/mm)")
    axes[0].legend(fontsize=7)
    axes[1].plot(delta, nodes, ".-")
    axes[1].set_xlabel("δ (mm)")
    axes[1].set_ylabel("nodes")
    last = sorted((run / "series").glob("*.h5"))[-1]
    with h5py.File(last, "r") as f:
        x = f["nodes"][:]
        v = f["fields"]["v"][:].ravel()
    sc = axes[2].scatter(x[:, 0], x[:, 1], c=v, s=2, cmap="viridis", vmin=0, vmax=1)
    axes[2].set_aspect("equal")
    axes[2].set_title(f"nodes and v at δ = {delta[-1]:.4g}", fontsize=9)
    fig.colorbar(sc, ax=axes[2], fraction=0.046)
    fig.tight_layout()
    path = out / "fracture_sent_adaptive.png"
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
