#!/usr/bin/python3
"""The droplet limit R_c << R: Young-Dupre and Laplace against the constraint multipliers.

lmeform's multipliers satisfy grad E = sigma grad A + p grad V at the solution (JSON `multipliers`:
area -> sigma, volume -> p), so sigma = dE/dA0 and p = dE/dV0; the membrane's effective tension is
-sigma. In the droplet limit the free part is a spherical cap of radius R_cap and
  Laplace:       p = -2 sigma / R_cap                        (seed 3.41 in this convention)
  Young-Dupre:   w = -sigma (1 + cos psi)                    (seed 3.40 with tension -sigma)
psi the contact angle inside the vesicle. Measured on the phi = 0 contour: a least-squares circle
(centre on the axis) through the points higher than z_flat + (z_top - z_flat) / 2 gives R_cap and
its centre z_c; cos psi = -(z_c - z_flat) / R_cap, z_flat the flat contact zone's level.
R = 0.3, v = 0.9, k = 1, eps = 0.02 (spacing 0.01). Writes build/adhesion/droplet_limit.json.

  /usr/bin/python3 demos/adhesion/droplet_limit.py [LMEFORM]
"""
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adhesion_common as ac  # noqa: E402

OMEGAS = [25.0, 60.0, 120.0, 250.0]
K, R, V, EPS = 1.0, 0.3, 0.9, 0.02


def main():
    lmeform = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ac.REPO, "build", "lmeform")
    out = os.path.join(ac.REPO, "build", "adhesion")
    runs = os.path.join(out, "droplet_limit")
    os.makedirs(runs, exist_ok=True)
    records, start = [], time.time()
    for omega in OMEGAS:
        name = f"dl_w{omega:g}"
        scene = ac.make_scene(os.path.join(runs, name + ".toml"), name, omega=omega, eps=EPS, k=K, radius=R, reduced_volume=V)
        report = ac.run(lmeform, scene, runs, name)
        line = ac.membrane_contour(os.path.join(runs, name + ".h5"))
        g = ac.contact_geometry(line, EPS)
        z_flat, z_top = g["z_flat"], float(line[:, 1].max())
        R_cap, z_c = ac.cap_circle(line, z_above=z_flat + 0.5 * (z_top - z_flat))
        cos_psi = -(z_c - z_flat) / R_cap
        sigma, p = report["multipliers"]["area"], report["multipliers"]["volume"]
        w = ac.W_EFF_PER_OMEGA * omega
        rc = math.sqrt(K / 4.0 / (2 * w))
        yd = -w / sigma - 1.0  # cos psi predicted by Young-Dupre from the measured sigma
        rec = {"omega": omega, "w_eff": w, "Rc_over_R": rc / R, "eps_over_Rc": EPS / rc, "sigma": sigma, "p": p,
               "R_cap": R_cap, "laplace_p": -2 * sigma / R_cap, "psi_deg": math.degrees(math.acos(max(-1, min(1, cos_psi)))),
               "psi_young_dupre_deg": math.degrees(math.acos(yd)) if -1 <= yd <= 1 else None,
               "w_young_dupre": -sigma * (1 + cos_psi), "contact_radius": g["contact_radius"], "z_flat": z_flat,
               "nodes": report["nodes"], "converged": report["converged"], "wall_s": report["wall_s"]}
        records.append(rec)
        print(f"omega {omega:5g} R_c/R {rec['Rc_over_R']:.3f} eps/R_c {rec['eps_over_Rc']:.2f} sigma {sigma:.4g} p {p:.4g} "
              f"R_cap {R_cap:.4f} -2sigma/R_cap {rec['laplace_p']:.4g}  psi {rec['psi_deg']:.1f}  psi_YD {rec['psi_young_dupre_deg']}  "
              f"-sigma(1+cos psi) {rec['w_young_dupre']:.4g} vs w {w:.4g}  {report['wall_s']:.1f} s {report['status']}", flush=True)
    json.dump({"k": K, "radius": R, "reduced_volume": V, "eps": EPS, "w_eff_per_omega": ac.W_EFF_PER_OMEGA,
               "total_s": time.time() - start, "records": records}, open(os.path.join(out, "droplet_limit.json"), "w"), indent=1)
    print(f"total {time.time() - start:.0f} s")


if __name__ == "__main__":
    main()
