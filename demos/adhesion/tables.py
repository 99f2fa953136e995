#!/usr/bin/python3
"""Prints the markdown tables of docs/adhesion.md from the JSON files the measurement scripts wrote
(build/adhesion/*.json).   /usr/bin/python3 demos/adhesion/tables.py"""
import json
import os

OUT = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "build", "adhesion")


def load(name):
    path = os.path.join(OUT, name + ".json")
    return json.load(open(path)) if os.path.exists(path) else None


def f(x, fmt):
    return "–" if x is None else format(x, fmt)


d = load("contact_curvature")
if d:
    print(f"contact curvature (w = {d['w_eff_per_omega']:.4f} omega, z0 = {d['z0_per_eps']:.3f} eps), total {d['total_s']:.0f} s\n")
    print("| omega | w R^2/kappa | R_c / R | eps | eps / R_c | nodes | C_c measured | C_c theory | ratio | ratio, window [10, 40] | ratio, window [30, 80] | r_c | z_flat / eps | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in d["records"]:
        rc = (r["kappa"] / (2 * r["w_eff"])) ** 0.5
        th = r["curvature_theory"]
        w1, w2 = r.get("curvature_window_10_40"), r.get("curvature_window_30_80")
        print(f"| {r['omega']:g} | {r['w_eff'] * 0.09 / r['kappa']:.2f} | {rc / 0.3:.3f} | {r['eps']:g} | {r['eps'] / rc:.3f} | {r['nodes']} | "
              f"{f(r['curvature'], '.3f')} | {th:.3f} | {f(r['curvature'] and r['curvature'] / th, '.3f')} | "
              f"{f(w1 and w1 / th, '.3f')} | {f(w2 and w2 / th, '.3f')} | "
              f"{f(r.get('contact_radius'), '.4f')} | {f(r.get('z_flat') and r['z_flat'] / r['eps'], '.2f')} | {r['wall_s']:.1f} |")
    print()
d = load("free_bound")
if d:
    print(f"free/bound, R = {d['radius']}, v = {d['reduced_volume']}, eps = {d['eps']}, total {d['total_s']:.0f} s\n")
    print("| eps | omega | R / R_c | w R^2/kappa | band fraction | -E_adh/(w A0) | r_c | E_bend | E | sigma | p | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in d["records"]:
        print(f"| {r['eps']:g} | {r['omega']:g} | {r['R_over_Rc']:.3f} | {r['w_R2_over_kappa']:.3f} | {r['bound_fraction']:.4f} | "
              f"{f(r.get('adhesion_fraction'), '.4f')} | {f(r.get('contact_radius'), '.4f')} | {r['bending_energy']:.4f} | {r['energy']:.4f} | "
              f"{r['tension_multiplier']:.4g} | {r['pressure_multiplier']:.4g} | {r['wall_s']:.1f} |")
    print()
d = load("droplet_limit")
if d:
    print(f"droplet limit, R = {d['radius']}, v = {d['reduced_volume']}, eps = {d['eps']}, total {d['total_s']:.0f} s\n")
    print("| omega | R_c / R | eps / R_c | sigma | p | R_cap | -2 sigma / R_cap | psi (deg) | psi Young-Dupre (deg) | -sigma (1 + cos psi) | w | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in d["records"]:
        print(f"| {r['omega']:g} | {r['Rc_over_R']:.3f} | {r['eps_over_Rc']:.2f} | {r['sigma']:.4g} | {r['p']:.4g} | {r['R_cap']:.4f} | "
              f"{r['laplace_p']:.4g} | {r['psi_deg']:.1f} | {f(r['psi_young_dupre_deg'], '.1f')} | {r['w_young_dupre']:.4g} | "
              f"{r['w_eff']:.4g} | {r['wall_s']:.1f} |")
    print()
d = load("fig317_series")
if d:
    print(f"Fig. 3.17 series, R = {d['radius']}, v = {d['reduced_volume']}, eps = {d['eps']}, total {d['total_s']:.0f} s\n")
    print("| omega | R / R_c | contact radius r_c | r_c / R | band fraction | E | sigma | p | wall s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in d["records"]:
        rc = r.get("contact_radius")
        print(f"| {r['omega']:g} | {r['R_over_Rc']:.2f} | {f(rc, '.4f')} | {f(rc and rc / d['radius'], '.3f')} | {r['bound_fraction']:.3f} | "
              f"{r['energy']:.4f} | {r['sigma']:.4g} | {r['p']:.4g} | {r['wall_s']:.1f} |")
