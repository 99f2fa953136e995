#!/usr/bin/python3
"""FEniCSx (dolfinx 0.5.2) reference solutions of the three Stokes test problems.

    /usr/bin/python3 demos/stokes/fenicsx_stokes.py [--quick] --out DIR

Solves -nu Lap u + grad p = f, div u = 0 with Dirichlet velocity on the whole boundary and
zero-mean pressure, on ladders of uniform triangle meshes, with
  (a) Taylor-Hood P2/P1, and
  (b) equal-order P1/P1 stabilised by GLS, which for P1 velocities (Lap u_h = 0 in each cell) is
      the consistent pressure-stabilisation term
          - sum_K tau_K ((grad p - f), grad q)_K,   tau_K = C h_K^2 / nu,  C = 0.1,
      h_K the cell diameter (longest edge).
The constant pressure is removed with a PETSc null space (direct MUMPS LU with null-pivot
detection); the error of the pressure is measured after subtracting the mean of p_h.
Errors (L2 of u, H1 seminorm of u, L2 of p) integrate the exact solution written as a UFL
expression of the coordinates with a quadrature of degree 8.
wall_s is the time of assembly (matrix, vector, lifting, boundary values) + solve (LU factorisation
and triangular solves), the fastest of --repeat (3) solves; the forms are JIT-compiled before,
the smallest mesh of each series is solved once as a warm-up and discarded.  Writes DIR/stokes_fenicsx_only.json.
"""
import argparse
import json
import logging
import os
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx
import dolfinx.fem.petsc
from dolfinx import fem, mesh as dmesh

logging.getLogger().setLevel(logging.WARNING)  # silence the JIT compiler's build_ext log

NU = 1.0
C_STAB = 0.1
QDEG = 8

# Uniform N x N squares, each cut into 2 triangles.  Unknowns (all dofs, boundary included):
#   P2/P1: 2 (2N+1)^2 + (N+1)^2,   P1/P1: 3 (N+1)^2.
LADDERS = {
    "P2/P1 Taylor-Hood": {"full": [6, 12, 24, 48, 60], "quick": [6, 12, 24, 32]},
    "P1/P1 stabilized": {"full": [10, 20, 40, 80, 100], "quick": [10, 20, 40, 56]},
}


def exact(problem, x):
    """UFL expressions (u, p, f) of the exact solution at the spatial coordinate x."""
    X, Y = x[0], x[1]
    pi = ufl.pi
    if problem == "colliding_flow":
        u = ufl.as_vector((20 * X * Y**3, 5 * X**4 - 5 * Y**4))
        p = 60 * X**2 * Y - 20 * Y**3
        f = ufl.as_vector((0.0 * X, 0.0 * X))
    elif problem == "poiseuille":
        u = ufl.as_vector((4 * Y * (1 - Y), 0.0 * X))
        p = 8 * (0.5 - X)
        f = ufl.as_vector((0.0 * X, 0.0 * X))
    elif problem == "manufactured":
        s, c = ufl.sin, ufl.cos
        u = ufl.as_vector((pi * s(pi * X) ** 2 * s(2 * pi * Y),
                           -pi * s(2 * pi * X) * s(pi * Y) ** 2))
        p = c(pi * X) * c(pi * Y)
        f = ufl.as_vector((
            -2 * NU * pi**3 * s(2 * pi * Y) * (2 * c(2 * pi * X) - 1) - pi * s(pi * X) * c(pi * Y),
            2 * NU * pi**3 * s(2 * pi * X) * (2 * c(2 * pi * Y) - 1) - pi * c(pi * X) * s(pi * Y)))
    else:
        raise ValueError(problem)
    return u, p, f


def exact_velocity_numpy(problem):
    """Boundary values for interpolation: x has shape (3, npoints)."""
    if problem == "colliding_flow":
        return lambda x: np.vstack((20 * x[0] * x[1]**3, 5 * x[0]**4 - 5 * x[1]**4))
    if problem == "poiseuille":
        return lambda x: np.vstack((4 * x[1] * (1 - x[1]), np.zeros_like(x[0])))
    if problem == "manufactured":
        pi = np.pi
        return lambda x: np.vstack((pi * np.sin(pi * x[0])**2 * np.sin(2 * pi * x[1]),
                                    -pi * np.sin(2 * pi * x[0]) * np.sin(pi * x[1])**2))
    raise ValueError(problem)


DOMAINS = {"colliding_flow": ((-1.0, -1.0), (1.0, 1.0)),
           "poiseuille": ((0.0, 0.0), (1.0, 1.0)),
           "manufactured": ((0.0, 0.0), (1.0, 1.0))}


def solve(problem, element, n):
    t_setup = time.perf_counter()
    lo, hi = DOMAINS[problem]
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [np.array(lo), np.array(hi)], [n, n],
                                 dmesh.CellType.triangle)
    cell = msh.ufl_cell()
    ku = 2 if element.startswith("P2") else 1
    Ve = ufl.VectorElement("Lagrange", cell, ku)
    Qe = ufl.FiniteElement("Lagrange", cell, 1)
    W = fem.FunctionSpace(msh, ufl.MixedElement([Ve, Qe]))
    V, _ = W.sub(0).collapse()
    Q, q_map = W.sub(1).collapse()

    x = ufl.SpatialCoordinate(msh)
    u_ex, p_ex, f = exact(problem, x)
    (u, p) = ufl.TrialFunctions(W)
    (v, q) = ufl.TestFunctions(W)
    dx = ufl.Measure("dx", domain=msh, metadata={"quadrature_degree": QDEG})
    a = (NU * ufl.inner(ufl.grad(u), ufl.grad(v)) - p * ufl.div(v) - q * ufl.div(u)) * dx
    # The zero constant keeps L a form on W when f is identically zero (UFL drops Zero integrands).
    zero = fem.Constant(msh, PETSc.ScalarType((0.0, 0.0)))
    L = ufl.inner(f, v) * dx + ufl.inner(zero, v) * dx
    if ku == 1:
        h = ufl.CellDiameter(msh)
        tau = C_STAB * h**2 / NU
        # GLS with P1 velocities: the viscous part of the residual vanishes cell-wise.
        a -= tau * ufl.inner(ufl.grad(p), ufl.grad(q)) * dx
        L -= tau * ufl.inner(f, ufl.grad(q)) * dx
    a_form, L_form = fem.form(a), fem.form(L)

    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(msh.topology)
    u_bc = fem.Function(V)
    u_bc.interpolate(exact_velocity_numpy(problem))
    dofs = fem.locate_dofs_topological((W.sub(0), V), tdim - 1, facets)
    bc = fem.dirichletbc(u_bc, dofs, W.sub(0))

    # Null space: constant pressure, zero velocity.
    ns_vec = fem.petsc.create_vector(L_form)
    with ns_vec.localForm() as loc:
        loc.set(0.0)
        loc.array[q_map] = 1.0
    ns_vec.normalize()
    nullspace = PETSc.NullSpace().create(vectors=[ns_vec], comm=msh.comm)
    setup_s = time.perf_counter() - t_setup

    # ---- timed: assembly + solve
    t0 = time.perf_counter()
    A = fem.petsc.assemble_matrix(a_form, bcs=[bc])
    A.assemble()
    A.setNullSpace(nullspace)
    b = fem.petsc.assemble_vector(L_form)
    fem.petsc.apply_lifting(b, [a_form], bcs=[[bc]])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    fem.petsc.set_bc(b, [bc])
    nullspace.remove(b)
    t1 = time.perf_counter()

    ksp = PETSc.KSP().create(msh.comm)
    ksp.setOperators(A)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    pc.setFactorSetUpSolverType()
    pc.getFactorMatrix().setMumpsIcntl(icntl=24, ival=1)  # detect the null pivot
    pc.getFactorMatrix().setMumpsIcntl(icntl=25, ival=0)  # return one solution of the singular system
    wh = fem.Function(W)
    ksp.solve(b, wh.vector)
    wh.x.scatter_forward()
    t2 = time.perf_counter()
    if ksp.getConvergedReason() < 0:
        raise RuntimeError(f"KSP failed: reason {ksp.getConvergedReason()}")

    # ---- errors
    uh, ph = wh.sub(0).collapse(), wh.sub(1).collapse()
    comm = msh.comm

    def integral(expr):
        return comm.allreduce(fem.assemble_scalar(fem.form(expr * dx)), op=MPI.SUM)

    area = (hi[0] - lo[0]) * (hi[1] - lo[1])
    p_mean = integral(ph) / area
    eu = uh - u_ex
    err_u_l2 = np.sqrt(integral(ufl.inner(eu, eu)))
    err_u_h1 = np.sqrt(integral(ufl.inner(ufl.grad(eu), ufl.grad(eu))))
    err_p_l2 = np.sqrt(integral((ph - p_mean - p_ex) ** 2))
    div_l2 = np.sqrt(integral(ufl.div(uh) ** 2))
    unknowns = W.dofmap.index_map.size_global * W.dofmap.index_map_bs
    for obj in (A, b, ksp, ns_vec):
        obj.destroy()
    return {"code": "fenicsx", "element": element, "problem": problem, "mesh_n": n,
            "cells": 2 * n * n, "unknowns": int(unknowns),
            "error_u_l2": float(err_u_l2), "error_u_h1": float(err_u_h1),
            "error_p_l2": float(err_p_l2), "div_u_l2": float(div_l2),
            "wall_s": t2 - t0, "assembly_s": t1 - t0, "solve_s": t2 - t1,
            "setup_s": setup_s, "nu": NU,
            "stabilization": "gls (-tau (grad p - f, grad q), tau = C h^2/nu)" if ku == 1 else "none",
            "C": C_STAB if ku == 1 else None}


def rates(records, key):
    """Convergence rate in h (= -2 d log e / d log unknowns in 2D) between successive rows."""
    out = [None]
    for r0, r1 in zip(records, records[1:]):
        if r0[key] > 0 and r1[key] > 0:
            out.append(-2 * np.log(r1[key] / r0[key]) / np.log(r1["unknowns"] / r0["unknowns"]))
        else:
            out.append(None)
    return out


def main():
    global C_STAB
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="meshes up to ~10,000 unknowns")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--problems", default="colliding_flow,poiseuille,manufactured")
    ap.add_argument("--stab-c", type=float, default=C_STAB, help="C in tau = C h^2/nu (P1/P1)")
    ap.add_argument("--repeat", type=int, default=3,
                    help="solves per mesh; wall_s is the fastest (the errors do not change)")
    args = ap.parse_args()
    C_STAB = args.stab_c
    os.makedirs(args.out, exist_ok=True)
    mode = "quick" if args.quick else "full"
    print(f"dolfinx {dolfinx.__version__}, PETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}, "
          f"{MPI.COMM_WORLD.size} rank(s), mode {mode}", flush=True)
    records = []
    for problem in args.problems.split(","):
        for element, ladder in LADDERS.items():
            ns = ladder[mode]
            solve(problem, element, ns[0])  # warm-up (JIT, MUMPS loading), discarded
            series = []
            for n in ns:
                runs = [solve(problem, element, n) for _ in range(args.repeat)]
                best = min(runs, key=lambda r: r["wall_s"])
                best["repeats"] = args.repeat
                best["wall_s_all"] = [r["wall_s"] for r in runs]
                series.append(best)
            ru, rh, rp = rates(series, "error_u_l2"), rates(series, "error_u_h1"), rates(series, "error_p_l2")
            print(f"\n{problem}, {element}")
            print(f"{'N':>4} {'unknowns':>9} {'|u-uh|_L2':>10} {'rate':>5} {'|u-uh|_H1':>10} {'rate':>5} "
                  f"{'|p-ph|_L2':>10} {'rate':>5} {'wall_s':>8} {'asm_s':>7} {'solve_s':>7}")
            fmt = lambda r: "   - " if r is None else f"{r:5.2f}"
            for r, a, b_, c in zip(series, ru, rh, rp):
                print(f"{r['mesh_n']:4d} {r['unknowns']:9d} {r['error_u_l2']:10.3e} {fmt(a)} "
                      f"{r['error_u_h1']:10.3e} {fmt(b_)} {r['error_p_l2']:10.3e} {fmt(c)} "
                      f"{r['wall_s']:8.4f} {r['assembly_s']:7.4f} {r['solve_s']:7.4f}", flush=True)
            records += series
    path = os.path.join(args.out, "stokes_fenicsx_only.json")
    with open(path, "w") as fh:
        json.dump(records, fh, indent=1)
    print(f"\nwrote {path} ({len(records)} records)")


if __name__ == "__main__":
    sys.exit(main())
