#!/usr/bin/python3
"""How far a phase-field vesicle with spontaneous curvature can fall below its sharp-interface
energy by thinning its interface, against what budding would gain.

    /usr/bin/python3 scripts/budding_energetics.py [--R0 0.4] [--v 0.8] [--C0 25] [--eps 0.02 0.01 ...]

Sharp interface, E = k/2 \\int (H - C0)^2 dA with H the mean of the principal curvatures (the
convention of forms/helfrich*.form), k = 1: a sphere of radius r has 2 pi (1 - C0 r)^2. It prints
the sphere of area 4 pi R0^2 and the two spheres with the same area and volume v 4/3 pi R0^3
(the budded limit).

Phase field: a flat interface with the profile tanh(x / (sqrt(2) alpha eps)), alpha = 1 the
equilibrium width. Per unit area its bending energy is (k C0^2 / 2) alpha [1 + (1 - alpha^-2)^2 /
(10 (eps C0)^2)] and its area functional (alpha + 1/alpha) / 2 times the sharp area. The energy
at fixed functional area is lowest at some alpha < 1; the script prints that alpha and the
relative change of the energy, with and without the area factor. A Lagrangian run that can
squeeze the interface reaches it (docs/dynamics.md, the prolate after a jump of C0).
"""

import argparse
import math

from scipy.optimize import brentq, minimize_scalar


def sphere(r, C0):
    return 2 * math.pi * (1 - C0 * r) ** 2


def two_spheres(R0, v):
    """Radii r1 >= r2 with r1^2 + r2^2 = R0^2 and r1^3 + r2^3 = v R0^3."""
    def volume_gap(r1):
        r2 = math.sqrt(max(R0 * R0 - r1 * r1, 0.0))
        return r1 ** 3 + r2 ** 3 - v * R0 ** 3
    r1 = brentq(volume_gap, R0 / math.sqrt(2), R0)
    return r1, math.sqrt(R0 * R0 - r1 * r1)


def thinning(eps_C0, area_factor):
    def relative_energy(alpha):
        e = alpha * (1 + (1 - alpha ** -2) ** 2 / (10 * eps_C0 ** 2))
        return e / ((alpha + 1 / alpha) / 2) if area_factor else e
    best = minimize_scalar(relative_energy, bounds=(0.2, 1.0), method="bounded", options={"xatol": 1e-10})
    return best.x, best.fun - 1


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--R0", type=float, default=0.4)
    parser.add_argument("--v", type=float, default=0.8)
    parser.add_argument("--C0", type=float, default=25.0)
    parser.add_argument("--eps", type=float, nargs="+", default=[0.02, 0.01, 0.008, 0.005, 0.004])
    a = parser.parse_args()
    r1, r2 = two_spheres(a.R0, a.v)
    e_sphere, e_two = sphere(a.R0, a.C0), sphere(r1, a.C0) + sphere(r2, a.C0)
    print(f"sharp interface, C0 R0 = {a.C0 * a.R0:g}, v = {a.v:g}")
    print(f"  sphere of radius {a.R0:g}: E = {e_sphere:.2f}")
    print(f"  two spheres, radii {r1:.5f} and {r2:.5f}: E = {e_two:.2f} ({(e_two / e_sphere - 1) * 100:+.1f} % of the sphere)")
    print("phase field, flat interface (relative change of the energy per unit area at the best width)")
    print(f"  {'eps':>7} {'eps/R0':>7} {'eps C0':>7} {'alpha':>7} {'dE':>8} {'alpha_A':>8} {'dE_A':>8}")
    for eps in a.eps:
        alpha, de = thinning(eps * a.C0, False)
        alpha_a, de_a = thinning(eps * a.C0, True)
        print(f"  {eps:7.4f} {eps / a.R0:7.4f} {eps * a.C0:7.3f} {alpha:7.3f} {de * 100:+7.2f}% {alpha_a:8.3f} {de_a * 100:+7.2f}%")
    print("  alpha, dE: the functional area free; alpha_A, dE_A: at fixed functional area (a constrained run)")


if __name__ == "__main__":
    main()
