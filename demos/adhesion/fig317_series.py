#!/usr/bin/python3
"""The seed's Fig. 3.17 series: v = 0.85, R = 0.3, k = 1, eps = 0.03 (spacing 0.015), omega growing:
the shapes (one panel, build/adhesion/fig317_series.png) and the adhesion length (the contact radius
r_c of adhesion_common.contact_geometry; the bound fraction of the area too), in
build/adhesion/fig317_series.json.

  /usr/bin/python3 demos/adhesion/fig317_series.py [LMEFORM]
"""
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adhesion_common as ac  # noqa: E402

OMEGAS = [1.0, 3.0, 6.0, 12.0, 25.0, 50.0, 100.0]
K, R, V, EPS = 1.0, 0.3, 0.85, 0.03


def main():
    lmeform = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ac.REPO, "build", "lmeform")
    out = os.path.join(ac.REPO, "build", "adhesion")
    runs = os.path.join(out, "fig317")
    os.makedirs(runs, exist_ok=True)
    records, start = [], time.time()
    for omega in OMEGAS:
        name = f"f317_w{omega:g}"
        scene = ac.make_scene(os.path.join(runs, name + ".toml"), name, omega=omega, eps=EPS, k=K, radius=R, reduced_volume=V)
        report = ac.run(lmeform, scene, runs, name)
        line = ac.membrane_contour(os.path.join(runs, name + ".h5"))
        w = ac.W_EFF_PER_OMEGA * omega
        rec = {"omega": omega, "R_over_Rc": R / math.sqrt(K / 4.0 / (2 * w)), "bound_fraction": ac.bound_fraction(line, EPS),
               "energy": report["energy"], "sigma": report["multipliers"]["area"], "p": report["multipliers"]["volume"],
               "nodes": report["nodes"], "converged": report["converged"], "wall_s": report["wall_s"],
               "contour": line[::2].round(5).tolist()}
        try:
            g = ac.contact_geometry(line, EPS)
            rec.update(contact_radius=g["contact_radius"], contact_curvature=g["curvature"])
        except RuntimeError as e:
            rec.update(contact_radius=None, contact_curvature=None, error=str(e))
        records.append(rec)
        print(f"omega {omega:5g} R/R_c {rec['R_over_Rc']:.2f} contact radius {rec['contact_radius']} "
              f"bound fraction {rec['bound_fraction']:.3f} E {rec['energy']:.4f} sigma {rec['sigma']:.4g} p {rec['p']:.4g} "
              f"{report['wall_s']:.1f} s {report['status']}", flush=True)
    json.dump({"k": K, "radius": R, "reduced_volume": V, "eps": EPS, "total_s": time.time() - start, "records": records},
              open(os.path.join(out, "fig317_series.json"), "w"), indent=1)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(records)
    fig, axes = plt.subplots(1, n, figsize=(2.3 * n, 2.6), sharey=True)
    for ax, r in zip(axes, records):
        c = r["contour"]
        rr = [p[0] for p in c]
        zz = [p[1] for p in c]
        ax.fill(rr + [-x for x in rr[::-1]], zz + zz[::-1], color="#9ecae1", ec="#08519c")
        ax.axhline(0.0, color="k", lw=2)
        ax.set_aspect("equal"); ax.set_xlim(-0.5, 0.5); ax.set_ylim(-0.02, 0.45)
        rc = r["contact_radius"]
        ax.set_title(f"omega = {r['omega']:g}\nR/R_c = {r['R_over_Rc']:.1f}" + (f", r_c = {rc:.3f}" if rc else ""), fontsize=8)
        ax.tick_params(labelsize=7)
    fig.suptitle(f"v = {V}, R = {R}, k = {K}, eps = {EPS}: adhesion grows left to right", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig317_series.png"), dpi=120)
    print(f"total {time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
