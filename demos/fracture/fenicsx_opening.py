#!/usr/bin/python3
"""FEniCSx (dolfinx 0.5) twin of demos/fracture/opening.toml: the cost of opening an AT2 crack on
linear finite elements.

    /usr/bin/python3 demos/fracture/fenicsx_opening.py [--h 0.01] [--diagonal right] [--out FILE]

The half strip [0, 0.5] x [0, 0.25] whose bottom edge is the crack's plane (v = 0 and u_y = 0 there),
opened by u = (0, delta/2) on the top edge; E = 1, nu = 0.3 (plane strain), Gc = 1, l = 0.02,
g(v) = (1 - k) v^2 + k, k = 1e-6, no split, no irreversibility (the crack is held by v = 0 on its
plane); P1 triangles of a structured mesh with spacing h. Each opening is solved by alternate
minimization from the previous one (u, then v, both linear solves) until max |v - v_before| < 1e-9.
Prints and writes (JSON) the surface energy per unit length of the whole crack, 4 x the half strip's
surface energy (two halves, length 0.5): Griffith's value is Gc at every opening.
"""
import argparse
import json
import os
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np
import ufl
from dolfinx import fem, mesh
from dolfinx.fem.petsc import LinearProblem
from mpi4py import MPI
from petsc4py import PETSc

OPENINGS = [0.0, 0.1, 0.3, 0.6, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--h", type=float, default=0.01, help="mesh spacing (default 0.01 = l/2)")
    parser.add_argument("--diagonal", default="right", choices=["right", "left", "crossed"])
    parser.add_argument("--tol", type=float, default=1e-9)
    parser.add_argument("--out", default=None, help="JSON file to write")
    args = parser.parse_args()

    E, nu, Gc, l, k = 1.0, 0.3, 1.0, 0.02, 1e-6
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    nx, ny = round(0.5 / args.h), round(0.25 / args.h)
    diagonal = {"right": mesh.DiagonalType.right, "left": mesh.DiagonalType.left,
                "crossed": mesh.DiagonalType.crossed}[args.diagonal]
    domain = mesh.create_rectangle(MPI.COMM_SELF, [np.array([0.0, 0.0]), np.array([0.5, 0.25])], [nx, ny],
                                   cell_type=mesh.CellType.triangle, diagonal=diagonal)
    U = fem.VectorFunctionSpace(domain, ("CG", 1))
    V = fem.FunctionSpace(domain, ("CG", 1))
    u, v = fem.Function(U), fem.Function(V)
    v.interpolate(lambda x: 1.0 - np.exp(-x[1] / l))

    def eps(w):
        return ufl.sym(ufl.grad(w))

    def psi(w):
        e = eps(w)
        return 0.5 * lam * ufl.tr(e) ** 2 + mu * ufl.inner(e, e)

    fdim = domain.topology.dim - 1
    bottom = mesh.locate_entities_boundary(domain, fdim, lambda x: np.isclose(x[1], 0.0))
    top = mesh.locate_entities_boundary(domain, fdim, lambda x: np.isclose(x[1], 0.25))
    opening = fem.Constant(domain, PETSc.ScalarType(0.0))
    uy_top = fem.dirichletbc(opening, fem.locate_dofs_topological(U.sub(1), fdim, top), U.sub(1))
    ux_top = fem.dirichletbc(PETSc.ScalarType(0.0), fem.locate_dofs_topological(U.sub(0), fdim, top), U.sub(0))
    uy_bottom = fem.dirichletbc(PETSc.ScalarType(0.0), fem.locate_dofs_topological(U.sub(1), fdim, bottom), U.sub(1))
    v_bottom = fem.dirichletbc(PETSc.ScalarType(0.0), fem.locate_dofs_topological(V, fdim, bottom), V)

    du, w = ufl.TrialFunction(U), ufl.TestFunction(U)
    g = (1 - k) * v ** 2 + k
    a_u = g * (lam * ufl.tr(eps(du)) * ufl.tr(eps(w)) + 2 * mu * ufl.inner(eps(du), eps(w))) * ufl.dx
    L_u = ufl.inner(fem.Constant(domain, PETSc.ScalarType((0.0, 0.0))), w) * ufl.dx
    dv, q = ufl.TrialFunction(V), ufl.TestFunction(V)
    a_v = ((2 * (1 - k) * psi(u) + Gc / l) * dv * q + Gc * l * ufl.inner(ufl.grad(dv), ufl.grad(q))) * ufl.dx
    L_v = Gc / l * q * ufl.dx
    lu = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
    u_problem = LinearProblem(a_u, L_u, bcs=[ux_top, uy_top, uy_bottom], u=u, petsc_options=lu)
    v_problem = LinearProblem(a_v, L_v, bcs=[v_bottom], u=v, petsc_options=lu)
    surface = fem.form(Gc * ((1 - v) ** 2 / (2 * l) + l / 2 * ufl.inner(ufl.grad(v), ufl.grad(v))) * ufl.dx)
    elastic = fem.form(g * psi(u) * ufl.dx)

    records, start = [], time.perf_counter()
    for delta in OPENINGS:
        opening.value = delta / 2
        for sweep in range(1, 100001):
            before = v.x.array.copy()
            u_problem.solve()
            v_problem.solve()
            change = np.max(np.abs(v.x.array - before))
            if change < args.tol:
                break
        crack = 4 * fem.assemble_scalar(surface)
        records.append({"delta": delta, "crack_energy_per_length": crack, "elastic": fem.assemble_scalar(elastic),
                        "sweeps": sweep, "v_min_row1": float(np.min(v.x.array[np.isclose(
                            V.tabulate_dof_coordinates()[:, 1], args.h)]))})
        print(f"delta {delta:6.2f}  crack energy / Gc {crack:.4f}  sweeps {sweep}", flush=True)
    wall = time.perf_counter() - start
    print(f"h = {args.h} ({args.diagonal}), {V.dofmap.index_map.size_global} nodes, {wall:.1f} s")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"h": args.h, "l": l, "diagonal": args.diagonal, "nodes": V.dofmap.index_map.size_global,
                       "wall_s": wall, "records": records}, f, indent=1)


if __name__ == "__main__":
    main()
