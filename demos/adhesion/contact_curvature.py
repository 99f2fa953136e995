#!/usr/bin/python3
"""The contact curvature of an adhered vesicle against Seifert-Lipowsky, C_c = sqrt(2 w / kappa).

Runs variants of adhered_vesicle.toml (R = 0.3, v = 0.9, k = 1, grid spacing eps / 2) for four omega
(a decade) and three eps, measures the meridian curvature of the phi = 0 contour at the contact line
(adhesion_common.contact_geometry: a quadratic fit of the tangent angle theta(s) over the points with
theta in [20, 60] degrees, extrapolated to theta = 0, the contact point; the curvature is d theta/ds
there), and writes build/adhesion/contact_curvature.json and .png.

  /usr/bin/python3 demos/adhesion/contact_curvature.py [LMEFORM] [--quick]
"""
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adhesion_common as ac  # noqa: E402

OMEGAS = [6.0, 12.0, 25.0, 60.0]
EPSILONS = [0.03, 0.02, 0.015]
K = 1.0


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    lmeform = args[0] if args else os.path.join(ac.REPO, "build", "lmeform")
    out = os.path.join(ac.REPO, "build", "adhesion")
    runs = os.path.join(out, "contact_curvature")
    os.makedirs(runs, exist_ok=True)
    epsilons = EPSILONS[:1] if "--quick" in sys.argv else EPSILONS
    records = []
    start = time.time()
    for eps in epsilons:
        for omega in OMEGAS:
            name = f"cc_w{omega:g}_e{eps:g}"
            scene = ac.make_scene(os.path.join(runs, name + ".toml"), name, omega=omega, eps=eps, k=K)
            report = ac.run(lmeform, scene, runs, name)
            rec = {"omega": omega, "kappa": K / 4.0, "k": K, "eps": eps, "nodes": report["nodes"],
                   "converged": report["converged"], "energy": report["energy"],
                   "w_eff": ac.W_EFF_PER_OMEGA * omega,
                   "curvature_theory": ac.contact_curvature_theory(omega, K), "wall_s": report["wall_s"]}
            try:
                line = ac.membrane_contour(os.path.join(runs, name + ".h5"))
                g = ac.contact_geometry(line, eps)
                rec.update(curvature=g["curvature"], contact_radius=g["contact_radius"], z_flat=g["z_flat"])
                # the measurement's sensitivity to its fit window
                for lo, hi in ((10.0, 40.0), (30.0, 80.0)):
                    try:
                        rec[f"curvature_window_{lo:g}_{hi:g}"] = ac.contact_geometry(line, eps, angle_window=(lo, hi))["curvature"]
                    except RuntimeError as e:
                        rec[f"curvature_window_{lo:g}_{hi:g}"] = None
                        rec[f"error_window_{lo:g}_{hi:g}"] = str(e)
            except RuntimeError as e:
                rec.update(curvature=None, error=str(e))
            records.append(rec)
            c = rec["curvature"]
            print(f"omega {omega:5g} eps {eps:6g} nodes {rec['nodes']:6d}  C_c {c if c is None else round(c, 3)}  "
                  f"theory {rec['curvature_theory']:.3f}  ratio {c / rec['curvature_theory'] if c else float('nan'):.3f}  "
                  f"{report['wall_s']:.1f} s  {report['status']}", flush=True)
    with open(os.path.join(out, "contact_curvature.json"), "w") as f:
        json.dump({"w_eff_per_omega": ac.W_EFF_PER_OMEGA, "z0_per_eps": ac.Z0_PER_EPS, "radius": 0.3,
                   "reduced_volume": 0.9, "total_s": time.time() - start, "records": records}, f, indent=1)
    plot(records, os.path.join(out, "contact_curvature.png"))
    print(f"total {time.time() - start:.0f} s")


def plot(records, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for eps in sorted({r["eps"] for r in records}, reverse=True):
        rs = [r for r in records if r["eps"] == eps and r["curvature"]]
        ax[0].plot([r["omega"] for r in rs], [r["curvature"] for r in rs], "o-", label=f"eps = {eps:g}")
        ax[1].plot([eps * r["curvature_theory"] for r in rs], [r["curvature"] / r["curvature_theory"] for r in rs], "o-", label=f"eps = {eps:g}")
    for omega in sorted({r["omega"] for r in records}):
        rs = [r for r in records if r["omega"] == omega and r["curvature"]]
        ax[1].plot([r["eps"] * r["curvature_theory"] for r in rs], [r["curvature"] / r["curvature_theory"] for r in rs], "k:", lw=0.8)
        ax[1].annotate(f"omega {omega:g}", (rs[-1]["eps"] * rs[-1]["curvature_theory"], rs[-1]["curvature"] / rs[-1]["curvature_theory"]),
                       fontsize=7, xytext=(-10, -12), textcoords="offset points")
    om = sorted({r["omega"] for r in records})
    ax[0].plot(om, [ac.contact_curvature_theory(o, K) for o in om], "k--", label="sqrt(2 w / kappa)")
    ax[0].set_xscale("log"); ax[0].set_yscale("log")
    ax[0].set_xlabel("omega"); ax[0].set_ylabel("contact curvature C_c")
    ax[1].axhline(1.0, color="k", ls="--")
    ax[1].set_xlabel("eps / R_c (R_c = 1 / theory)"); ax[1].set_ylabel("C_c / theory"); ax[1].set_xlim(left=0)
    for a in ax:
        a.legend(); a.grid(True, which="both", alpha=0.3)
    fig.suptitle("Contact curvature, R = 0.3, v = 0.9, k = 1 (kappa = 0.25), w = %.4f omega" % ac.W_EFF_PER_OMEGA)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
