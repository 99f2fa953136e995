#!/usr/bin/python3
"""The free/bound transition: at fixed k = 1, R = 0.3, v = 0.97 (nearly a sphere), eps = 0.03 (spacing 0.015; and eps = 0.02 at five omega), the bound
fraction of the membrane's area against R / R_c, R_c = sqrt(kappa / (2 w)) (kappa = k / 4,
w = W_EFF_PER_OMEGA omega), sweeping omega. Two measures of the bound part: `bound_fraction`,
the part of the phi = 0 contour's surface of revolution within eps above the bottom of the well
(z0 = Z0_PER_EPS eps), a geometric band that also counts a flat-bottomed free vesicle; and
`adhesion_fraction` = -E_adh / (w A0), the area that the adhesion energy accounts for at w per area. Writes
build/adhesion/free_bound.json and .png.

  /usr/bin/python3 demos/adhesion/free_bound.py [LMEFORM]
"""
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adhesion_common as ac  # noqa: E402

OMEGAS = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 11.0, 15.0, 20.0, 30.0, 45.0]
K, R, V, EPS = 1.0, 0.3, 0.97, 0.03
# a finer interface at a few omega: does the weak binding below R = 2 R_c shrink with eps?
FINER_EPS, FINER_OMEGAS = 0.02, [0.5, 2.0, 6.0, 11.0, 20.0]


def contact_radius(line, eps):
    try:
        return ac.contact_geometry(line, eps)["contact_radius"]
    except RuntimeError:
        return None


def main():
    lmeform = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ac.REPO, "build", "lmeform")
    out = os.path.join(ac.REPO, "build", "adhesion")
    runs = os.path.join(out, "free_bound")
    os.makedirs(runs, exist_ok=True)
    records, start = [], time.time()
    for eps, omega in [(EPS, o) for o in OMEGAS] + [(FINER_EPS, o) for o in FINER_OMEGAS]:
        name = f"fb_w{omega:g}" + ("" if eps == EPS else f"_e{eps:g}")
        scene = ac.make_scene(os.path.join(runs, name + ".toml"), name, omega=omega, eps=eps, k=K, radius=R, reduced_volume=V)
        report = ac.run(lmeform, scene, runs, name)
        line = ac.membrane_contour(os.path.join(runs, name + ".h5"))
        w = ac.W_EFF_PER_OMEGA * omega
        rc_theory = math.sqrt(K / 4.0 / (2 * w)) if w > 0 else math.inf
        rec = {"omega": omega, "eps": eps, "w_eff": w, "R_over_Rc": R / rc_theory, "w_R2_over_kappa": w * R * R / (K / 4.0),
               "bound_fraction": ac.bound_fraction(line, eps),
               "adhesion_fraction": -report["quantities"]["adhesion_energy"] / (w * 4 * math.pi * R * R) if w > 0 else None,
               "bending_energy": report["quantities"]["bending_energy"], "lowest_z": float(line[:, 1].min()),
               "contact_radius": contact_radius(line, eps), "energy": report["energy"], "tension_multiplier": report["multipliers"]["area"],
               "pressure_multiplier": report["multipliers"]["volume"], "converged": report["converged"],
               "nodes": report["nodes"], "wall_s": report["wall_s"], "contour": line[::2].round(5).tolist()}
        records.append(rec)
        print(f"eps {eps:g} omega {omega:5g}  R/R_c {rec['R_over_Rc']:.3f}  w R^2/kappa {rec['w_R2_over_kappa']:.3f}  "
              f"bound fraction {rec['bound_fraction']:.4f}  adhesion fraction {rec['adhesion_fraction'] or 0:.4f}  r_c {rec['contact_radius'] or 0:.4f}  E_bend {rec['bending_energy']:.4f}  E {rec['energy']:.5f}  {report['wall_s']:.1f} s  {report['status']}", flush=True)
    json.dump({"k": K, "radius": R, "reduced_volume": V, "eps": EPS, "w_eff_per_omega": ac.W_EFF_PER_OMEGA,
               "total_s": time.time() - start, "records": records}, open(os.path.join(out, "free_bound.json"), "w"), indent=1)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    main = [r for r in records if r["eps"] == EPS]
    finer = [r for r in records if r["eps"] == FINER_EPS]
    ax[0].plot([r["R_over_Rc"] for r in main], [r["bound_fraction"] for r in main], "o-", label=f"band: z < z0 + eps, eps = {EPS}")
    ax[0].plot([r["R_over_Rc"] for r in main[1:]], [r["adhesion_fraction"] for r in main[1:]], "s-", label=f"-E_adh / (w A0), eps = {EPS}")
    ax[0].plot([r["R_over_Rc"] for r in finer], [r["bound_fraction"] for r in finer], "o--", label=f"band, eps = {FINER_EPS}")
    ax[0].plot([r["R_over_Rc"] for r in finer], [r["adhesion_fraction"] for r in finer], "s--", label=f"-E_adh / (w A0), eps = {FINER_EPS}")
    ax[0].axhline(main[0]["bound_fraction"], color="gray", ls=":", label="band fraction at omega = 0")
    ax[0].axvline(2.0, color="k", ls="--", label="w R^2 / kappa = 2 (sphere, Seifert-Lipowsky)")
    ax[0].set_xlabel("R / R_c"); ax[0].set_ylabel("bound fraction of the area"); ax[0].legend(fontsize=7); ax[0].grid(alpha=0.3)
    for r in main[1::2]:
        c = r["contour"]
        ax[1].plot([p[0] for p in c], [p[1] for p in c], label=f"R/R_c = {r['R_over_Rc']:.2f}")
    ax[1].axhline(0.0, color="k"); ax[1].set_aspect("equal"); ax[1].set_xlabel("r"); ax[1].set_ylabel("z")
    ax[1].legend(fontsize=7)
    fig.suptitle(f"Free/bound transition, R = {R}, v = {V}, k = {K}; shapes at eps = {EPS}")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "free_bound.png"), dpi=110)
    print(f"total {time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
