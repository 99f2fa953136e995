#!/usr/bin/python3
"""FEniCSx (dolfinx 0.5) twin of demos/fracture/surfing.toml on linear finite elements.

    /usr/bin/python3 demos/fracture/fenicsx_surfing.py [--h 0.01] [--out FILE]

The model and load of surfing.toml: the strip [0, 1] x [-0.25, 0.25], E = 1, nu = 0.3 (plane strain),
Gc = 1, l = 0.02, AT2 with g(v) = (1 - k) v^2 + k, k = 1e-6, no split; the whole boundary follows
the mode-I field of a tip at (xt, 0), K = sqrt(Gc E'), xt from 0.3 to 0.54 in 24 steps; the initial
crack y = 0, x <= 0.3 as the same initial field; irreversibility 0 <= v <= v of the previous step
(PETSc SNES vinewtonrsls); alternate minimization to max |v - v_before| < 1e-4 per sweep.
P1 triangles of a structured mesh (right diagonals) of spacing 0.02, bisected in the band
|y| <= 0.04 until its spacing is --h.

The tip of a step is the largest x of the nodes within h of y = 0 with v < 1/2 (as surfing.py);
fitted over the second half of the steps: the crack speed d(tip)/d(xt) and the dissipation
d(E_s)/d(xt), d(E_s)/d(tip) in units of Gc. Prints them and writes a JSON record.
"""
import argparse
import json
import os
import pathlib
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np
import ufl
from dolfinx import fem, mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from fenicsx_fracture import SnesProblem, make_snes  # noqa: E402

E, NU, GC, L, K_RESIDUAL = 1.0, 0.3, 1.0, 0.02, 1e-6
LAMBDA = E * NU / ((1 + NU) * (1 - 2 * NU))
MU = E / (2 * (1 + NU))
KAPPA = 3 - 4 * NU
K_I = np.sqrt(GC * E / (1 - NU**2))
BAND = 0.04


def mode_one(xt):
    def field(p):
        dx, dy = p[0] - xt, p[1]
        r = np.hypot(dx, dy)
        theta = np.arctan2(dy, dx)
        scale = K_I / (2 * MU) * np.sqrt(r / (2 * np.pi)) * (KAPPA - np.cos(theta))
        return np.vstack([scale * np.cos(theta / 2), scale * np.sin(theta / 2)])
    return field


def strip_mesh(h):
    h0 = 0.02
    msh = dmesh.create_rectangle(MPI.COMM_SELF, [np.array([0.0, -0.25]), np.array([1.0, 0.25])],
                                 [round(1 / h0), round(0.5 / h0)], dmesh.CellType.triangle,
                                 diagonal=dmesh.DiagonalType.right)
    size = h0
    while size > h * 1.0001:
        msh.topology.create_entities(1)
        vertices = msh.geometry.dofmap.array.reshape(-1, 3)
        y = msh.geometry.x[vertices, 1]
        cells = np.flatnonzero(np.any(np.abs(y) <= BAND + size, axis=1)).astype(np.int32)
        edges = dmesh.compute_incident_entities(msh, cells, 2, 1)
        msh = dmesh.refine(msh, edges, redistribute=False)
        size /= 2
    return msh


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--h", type=float, default=0.01, help="spacing in the band |y| <= 0.04 (0.02 / 2^n)")
    parser.add_argument("--tol", type=float, default=1e-4)
    parser.add_argument("--out", default=None, help="JSON file to write")
    args = parser.parse_args()
    start = time.perf_counter()
    msh = strip_mesh(args.h)
    U = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    V = fem.FunctionSpace(msh, ("Lagrange", 1))
    u, v = fem.Function(U), fem.Function(V)
    v_previous, v_lower, v_sweep = fem.Function(V), fem.Function(V), fem.Function(V)

    def initial(p):
        d = np.where(p[0] < 0.3, np.abs(p[1]), np.hypot(p[0] - 0.3, p[1]))
        return 1 - np.exp(-np.maximum(d - 0.01, 0.0) / L)

    v.interpolate(initial)
    v_previous.x.array[:] = v.x.array
    v_lower.x.array[:] = 0.0

    eps = ufl.sym(ufl.grad(u))
    psi = 0.5 * LAMBDA * ufl.tr(eps) ** 2 + MU * ufl.inner(eps, eps)
    g = (1 - K_RESIDUAL) * v**2 + K_RESIDUAL
    dx = ufl.Measure("dx", domain=msh, metadata={"quadrature_degree": 2})
    surface_density = GC * ((1 - v) ** 2 / (2 * L) + L / 2 * ufl.inner(ufl.grad(v), ufl.grad(v)))
    energy = (g * psi + surface_density) * dx
    residual_u = ufl.derivative(energy, u, ufl.TestFunction(U))
    residual_v = ufl.derivative(energy, v, ufl.TestFunction(V))
    surface = fem.form(surface_density * dx)

    boundary_dofs = fem.locate_dofs_topological(
        U, 1, dmesh.locate_entities_boundary(msh, 1, lambda p: np.full(p.shape[1], True)))
    u_boundary = fem.Function(U)
    bcs = [fem.dirichletbc(u_boundary, boundary_dofs)]
    snes_u = make_snes(SnesProblem(residual_u, u, bcs), "u_", vi=False, overrides={})
    snes_v = make_snes(SnesProblem(residual_v, v, []), "v_", vi=True, overrides={})

    coords = V.tabulate_dof_coordinates()
    near_axis = np.abs(coords[:, 1]) < args.h * 1.1
    nodes = V.dofmap.index_map.size_local
    print(f"h = {args.h}: {nodes} nodes, {msh.topology.index_map(2).size_local} cells", flush=True)
    rows = []
    for step, xt in enumerate(np.linspace(0.3, 0.54, 25)):
        t0 = time.perf_counter()
        u_boundary.interpolate(mode_one(xt))
        sweeps = 0
        if step > 0:
            while sweeps < 1000:
                sweeps += 1
                v_sweep.x.array[:] = v.x.array
                snes_u.solve(None, u.vector)
                u.x.scatter_forward()
                snes_v.setVariableBounds(v_lower.vector, v_previous.vector)
                snes_v.solve(None, v.vector)
                v.x.scatter_forward()
                if np.abs(v.x.array - v_sweep.x.array).max() < args.tol:
                    break
        v_previous.x.array[:] = v.x.array
        broken = near_axis & (v.x.array < 0.5)
        tip = float(coords[broken, 0].max()) if broken.any() else float("nan")
        dissipated = float(fem.assemble_scalar(surface))
        rows.append((xt, tip, dissipated, sweeps, time.perf_counter() - t0))
        print(f"step {step:2d}  xt {xt:.3f}  tip {tip:.4f}  dissipated {dissipated:.6f}  sweeps {sweeps:3d}  "
              f"{rows[-1][4]:.1f} s", flush=True)
    data = np.array(rows)
    half = data[len(data) // 2:]
    speed = np.polyfit(half[:, 0], half[:, 1], 1)[0]
    rate_xt = np.polyfit(half[:, 0], half[:, 2], 1)[0] / GC
    rate_tip = np.polyfit(half[:, 1], half[:, 2], 1)[0] / GC
    wall = time.perf_counter() - start
    print(f"crack speed {speed:.4f}; dissipation d(E_s)/d(xt) = {rate_xt:.4f} Gc, d(E_s)/d(tip) = {rate_tip:.4f} Gc "
          f"over the last {len(half)} steps; {nodes} nodes, {wall:.0f} s")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"h": args.h, "l": L, "nodes": nodes, "crack_speed": speed, "dissipation_rate": rate_xt,
                       "dissipation_per_tip_advance": rate_tip, "wall_s": wall,
                       "steps": [dict(zip(["xt", "tip", "dissipated", "sweeps", "wall_s"], map(float, r)))
                                 for r in rows]}, f, indent=1)


if __name__ == "__main__":
    main()
