#!/usr/bin/python3
"""FEniCSx (dolfinx 0.5) reference runs of phase-field fracture: single-edge-notched tension (SENT)
and shear (SENS), for overlaying lmeform's curves.

    /usr/bin/python3 demos/fracture/fenicsx_fracture.py --case sent|sens [--l 0.015] --out DIR

Model (the same as the lmeform side):
  * unit square [0,1]^2 mm, plane strain, lambda = 121.15 kN/mm^2, mu = 80.77 kN/mm^2,
    Gc = 2.7e-3 kN/mm, l = 0.015 mm (--l 0.0075 as an option);
  * phase field v: v = 1 intact, v = 0 broken; AT2 surface energy Gc [(1 - v)^2/(2 l) + l/2 |grad v|^2]
    (1D optimal profile 1 - exp(-|x|/l));
  * degradation g(v) = v^2 + k, k = 1e-6, on the tensile part of the volumetric-deviatoric split
    (Amor et al. 2009) with K = lambda + 2 mu/3 and the 3D deviator of the plane-strain strain:
    psi+ = K/2 <tr e>+^2 + mu |dev e|^2, psi- = K/2 <tr e>-^2, |dev e|^2 = e:e - (tr e)^2/3;
    total energy int g(v) psi+ + psi- + Gc [(1 - v)^2/(2 l) + l/2 |grad v|^2] dx;
  * the notch is an initial field, not geometry: v0 = 1 - exp(-d/l), d the distance to the segment
    y = 0.5, 0 <= x <= 0.5 (interpolated at the nodes; --notch-core is a variant, not the model);
  * irreversibility: 0 <= v <= v of the previous load step, the v subproblem solved as a
    bound-constrained problem by PETSc SNES vinewtonrsls;
  * alternate minimization in each load step: u (SNES newtonls, the split makes it piecewise
    linear) then v, until max |v - v_before| < 1e-4 over one u-v sweep (--tol), at most 100 sweeps
    (--max-iter; a step that reaches it is counted in "unconverged_steps" and the load goes on);
  * SENT: bottom u = 0, top u_x = 0, u_y = delta; SENS: bottom u = 0, top u_x = delta, u_y = 0, left
    and right edges u_y = 0. The force is the reaction on the top edge (kN per mm thickness): the
    sum over the top dofs, in the loaded component, of the residual vector int sigma : eps(w) dx;
  * P1 triangles for u and v. Default mesh: unstructured (Delaunay of jittered, smoothed hexagonal
    lattices, scipy), node spacing l/2.5 in the band the crack crosses (SENT |y - 0.5| <= 0.05,
    x >= 0.45; SENS x >= 0.45, y <= 0.55) and along the notch (|y - 0.5| <= 0.03, x <= 0.45), growing
    by a quarter of the distance away from them up to 0.05; fixed nodes on the notch segment. Its
    edge directions are spread evenly: on create_rectangle meshes (--mesh right|left|crossed, refined
    by bisection in the same bands, 3 levels from 24 x 24) the SENS crack follows the mesh lines.
    The JSON records the measured sizes (mean edge and longest edge in the band).
  * load steps (--schedule UNTIL:STEP,...): SENT a uniform 1e-5 mm up to 0.007 mm; SENS 1e-4 mm up
    to 0.0097, 1e-5 mm up to 0.01025 (the peak), 1e-4 mm up to 0.015 (larger steps away from the
    peak keep the run near ten minutes on one core).
  * linear solvers: u, MUMPS LU at every Newton iteration (a full Newton step, retried with half
    steps if it cycles); v, CG with BoomerAMG (rtol 1e-12) inside vinewtonrsls.

Writes DIR/fenicsx_fracture_<case>_l<l>.json (delta, force, elastic and surface energy per step,
peak force and its delta, sizes, wall and CPU time, per step the u and v solve times, sweeps and
Newton iterations, the crack points (nodes where v < 0.1 outside the initial notch)) and
DIR/fenicsx_fracture_<case>_l<l>.png (v at the last step; --snapshots adds earlier ones).
A run stopped by hand (Ctrl-C, SIGTERM) finishes the step in progress and writes both files for
the steps done ("stopped_by_signal": true, "steps" of "steps_scheduled").
Serial only: the reaction sum and the output assume one process.
"""
import argparse
import json
import logging
import os
import signal
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np
import scipy.sparse
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx
import dolfinx.fem.petsc
from dolfinx import fem, mesh as dmesh
from scipy.spatial import Delaunay

logging.disable(logging.INFO)  # the JIT compiler logs every build at INFO

LAMBDA, MU, GC, K_RESIDUAL = 121.15, 80.77, 2.7e-3, 1e-6
BULK = LAMBDA + 2.0 * MU / 3.0
NOTCH_Y, NOTCH_TIP_X = 0.5, 0.5
# SENT: a uniform 1e-5 mm to 0.007 mm. SENS: see the header.
DEFAULT_SCHEDULES = {"sent": "0.007:1e-5", "sens": "0.0097:1e-4,0.01025:1e-5,0.015:1e-4"}
QUAD = {"quadrature_degree": 2}  # exact: strains are constant per cell, v is P1


def in_fine_band(case, x, y, margin):
    """Where the crack is expected to run: refined to the finest level."""
    if case == "sent":
        return (np.abs(y - NOTCH_Y) <= 0.05 + margin) & (x >= 0.45 - margin)
    return (x >= 0.45 - margin) & (y <= 0.55 + margin)


def in_notch_band(x, y, margin):
    """Along the initial notch (|y - 0.5| <= 2 l for l = 0.015, x <= 0.45)."""
    return (np.abs(y - NOTCH_Y) <= 0.03 + margin) & (x <= 0.45 + margin)


def distance_to_fine_regions(case, x, y):
    """Distance to the crack band or to the notch band (0 inside either)."""
    if case == "sent":
        band = np.hypot(np.maximum(0.45 - x, 0.0), np.maximum(np.abs(y - NOTCH_Y) - 0.05, 0.0))
    else:
        band = np.hypot(np.maximum(0.45 - x, 0.0), np.maximum(y - 0.55, 0.0))
    notch = np.hypot(np.maximum(x - 0.45, 0.0), np.maximum(np.abs(y - NOTCH_Y) - 0.03, 0.0))
    return np.minimum(band, notch)


def unstructured_points(case, spacing, grade=0.25, coarsest=0.05, jitter=0.5, smoothing=2, seed=20100407):
    """Nodes of a graded, direction-free triangulation of the unit square.

    Hexagonal lattices of spacing spacing * 2^k fill the zones whose target size
    spacing + grade * (distance to the fine regions), capped at coarsest, falls in [2^k, 2^(k+1)) * spacing;
    every lattice node is moved by up to jitter * its spacing in each direction, so that after two
    Laplacian smoothing sweeps the edge directions are spread evenly (a regular lattice would favour
    three crack directions and a structured mesh two or four). The square's edges and the notch
    segment y = 0.5, 0 <= x <= 0.5 carry fixed nodes, so that v0 = 0 is represented exactly there.
    """
    rng = np.random.default_rng(seed)

    def target(x, y):
        return np.minimum(spacing + grade * distance_to_fine_regions(case, x, y), coarsest)

    def zone(h):
        return np.floor(np.log2(h / spacing) + 1e-9).clip(0)

    lattice = []
    for k in range(int(zone(np.array(coarsest))) + 1):
        sk = spacing * 2**k
        rows = np.arange(0.5, 1.0 / (sk * np.sqrt(3) / 2)) * sk * np.sqrt(3) / 2
        for j, y in enumerate(rows):
            xs = np.arange(0.5 + 0.5 * (j % 2), 1.0 / sk) * sk
            ys = np.full_like(xs, y)
            keep = zone(target(xs, ys)) == k
            lattice.append(np.column_stack([xs[keep], ys[keep]]))
    free = np.vstack(lattice)
    free_h = target(free[:, 0], free[:, 1])
    free += jitter * spacing * 2 ** zone(free_h)[:, None] * rng.uniform(-1.0, 1.0, free.shape)

    def walk(a, b):
        """Nodes from a towards b (b excluded) at the local target spacing."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        length, t, out = np.linalg.norm(b - a), 0.0, [a]
        while True:
            p = a + (b - a) * t / length
            t += target(p[:1], p[1:])[0]
            if t > length - 0.5 * target(b[:1], b[1:])[0]:
                return np.array(out)
            out.append(a + (b - a) * t / length)

    corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    boundary = np.vstack([walk(corners[i], corners[(i + 1) % 4]) for i in range(4)])
    notch = np.vstack([walk((0.0, NOTCH_Y), (NOTCH_TIP_X, NOTCH_Y))[1:], [[NOTCH_TIP_X, NOTCH_Y]]])
    fixed = np.vstack([boundary, notch])
    free_h = target(free[:, 0], free[:, 1])
    inside = np.all((free > 0.5 * free_h[:, None]) & (free < 1.0 - 0.5 * free_h[:, None]), axis=1)
    free, free_h = free[inside], free_h[inside]
    near_notch = (np.abs(free[:, 1] - NOTCH_Y) < 0.6 * free_h) & (free[:, 0] < NOTCH_TIP_X + 0.6 * free_h)
    free = free[~near_notch]

    points = np.vstack([fixed, free])
    is_free = np.arange(len(points)) >= len(fixed)
    for _ in range(smoothing):
        cells = Delaunay(points).simplices
        rows = np.concatenate([cells[:, 0], cells[:, 1], cells[:, 2], cells[:, 1], cells[:, 2], cells[:, 0]])
        cols = np.concatenate([cells[:, 1], cells[:, 2], cells[:, 0], cells[:, 0], cells[:, 1], cells[:, 2]])
        adjacency = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(points),) * 2).tocsr()
        adjacency.data[:] = 1.0
        mean_neighbour = adjacency @ points / np.asarray(adjacency.sum(axis=1))
        points[is_free] += 0.5 * (mean_neighbour[is_free] - points[is_free])
    return points, Delaunay(points).simplices


def build_unstructured_mesh(case, spacing, seed):
    points, cells = unstructured_points(case, spacing, seed=seed)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.triangle, 1))
    return dmesh.create_mesh(MPI.COMM_WORLD, cells.astype(np.int64), points, domain)


DIAGONALS = {"right": dmesh.DiagonalType.right, "left": dmesh.DiagonalType.left,
             "crossed": dmesh.DiagonalType.crossed}


def build_structured_mesh(case, n0, levels, notch_levels, diagonal):
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [np.array([0.0, 0.0]), np.array([1.0, 1.0])], [n0, n0],
                                 dmesh.CellType.triangle, diagonal=DIAGONALS[diagonal])
    for level in range(1, max(levels, notch_levels) + 1):
        h = 1.0 / (n0 * 2 ** (level - 1))  # leg length of the cells about to be split
        tdim = msh.topology.dim
        msh.topology.create_entities(1)
        x = msh.geometry.x
        cells_vertices = msh.geometry.dofmap.array.reshape(-1, 3)
        cx, cy = x[cells_vertices, 0], x[cells_vertices, 1]
        # A cell is marked when any vertex is in the region grown by one cell: the refined zone
        # then covers the whole band, not only the cells whose centre lies in it.
        marked = np.zeros(len(cells_vertices), dtype=bool)
        if level <= levels:
            marked |= np.any(in_fine_band(case, cx, cy, h), axis=1)
        if level <= notch_levels:
            marked |= np.any(in_notch_band(cx, cy, h), axis=1)
        cells = np.flatnonzero(marked).astype(np.int32)
        edges = dmesh.compute_incident_entities(msh, cells, tdim, 1)
        msh = dmesh.refine(msh, edges, redistribute=False)
    return msh


def cell_sizes(msh, case, l):
    ncells = msh.topology.index_map(msh.topology.dim).size_local
    x = msh.geometry.x
    verts = msh.geometry.dofmap.array.reshape(-1, 3)
    corners = x[verts, :2]
    edges = np.stack([np.linalg.norm(corners[:, i] - corners[:, (i + 1) % 3], axis=1) for i in range(3)], axis=1)
    h = edges.max(axis=1)  # longest edge of each cell
    area = 0.5 * np.abs(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    quality = 4.0 * np.sqrt(3.0) * area / np.sum(edges**2, axis=1)  # 1 for an equilateral triangle
    inside = np.all(in_fine_band(case, x[verts, 0], x[verts, 1], 0.0), axis=1)
    along_notch = np.all(in_notch_band(x[verts, 0], x[verts, 1], 0.0), axis=1)
    return {"cells": int(ncells), "edge_mean_band": float(edges[inside].mean()),
            "h_p99_band": float(np.percentile(h[inside], 99)), "h_max_band": float(h[inside].max()),
            "edge_mean_band_over_l": float(edges[inside].mean() / l), "h_max_notch": float(h[along_notch].max()),
            "h_min": float(h.min()), "h_max": float(h.max()), "quality_min": float(quality.min())}


def parse_schedule(text):
    """"until:step,until:step,...": constant steps up to each end, in increasing order."""
    stages = []
    for item in text.split(","):
        until, step = (float(part) for part in item.split(":"))
        if step <= 0 or (stages and until <= stages[-1][0]):
            raise ValueError(f"--schedule {text!r}: ends must increase and steps be positive")
        stages.append((until, step))
    return stages


def load_schedule(stages):
    """The delta after each load step (0 excluded); every stage end is hit exactly."""
    deltas, start = [], 0.0
    for until, step in stages:
        count = max(1, int(round((until - start) / step)))
        deltas += [round(start + (until - start) * (i + 1) / count, 12) for i in range(count)]
        start = until
    return deltas


class SnesProblem:
    """F and J callbacks for PETSc SNES, Dirichlet rows set to x - g with identity Jacobian rows."""

    def __init__(self, residual, unknown, bcs):
        self.unknown = unknown
        self.bcs = bcs
        self.L = fem.form(residual)
        self.a = fem.form(ufl.derivative(residual, unknown, ufl.TrialFunction(unknown.function_space)))
        self.b = fem.petsc.create_vector(self.L)
        self.A = fem.petsc.create_matrix(self.a)

    def F(self, snes, x, b):
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        x.copy(self.unknown.vector)
        self.unknown.vector.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with b.localForm() as b_local:
            b_local.set(0.0)
        fem.petsc.assemble_vector(b, self.L)
        fem.petsc.apply_lifting(b, [self.a], bcs=[self.bcs], x0=[x], scale=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fem.petsc.set_bc(b, self.bcs, x, -1.0)

    def J(self, snes, x, A, P):
        A.zeroEntries()
        fem.petsc.assemble_matrix(A, self.a, self.bcs)
        A.assemble()


def make_snes(problem, prefix, vi, overrides):
    snes = PETSc.SNES().create(MPI.COMM_WORLD)
    snes.setOptionsPrefix(prefix)
    opts = PETSc.Options()
    defaults = {"snes_type": "vinewtonrsls" if vi else "newtonls", "snes_linesearch_type": "basic",
                "snes_rtol": 1e-9, "snes_stol": 0.0, "snes_max_it": 50}
    if vi:
        # The v Hessian (2 psi+ + Gc/l) M + Gc l K is well conditioned whatever the damage, and the
        # reduced (inactive-set) systems change size between iterations: CG with BoomerAMG, solved
        # tightly, is 4x faster here than a sparse LU of every reduced system.
        # Residual entries are of the order Gc/l times a cell area (1e-6 here): atol far below that.
        defaults.update({"snes_atol": 1e-13, "ksp_type": "cg", "pc_type": "hypre", "ksp_rtol": 1e-12,
                         "ksp_atol": 1e-16})
    else:
        # Degraded cells (g = k = 1e-6) make the u Hessian too ill-conditioned for AMG: sparse LU.
        # Residual entries are nodal forces (reactions of 0.1 to 1 kN): 1e-8 kN is far below them.
        defaults.update({"snes_atol": 1e-8, "ksp_type": "preonly", "pc_type": "lu",
                         "pc_factor_mat_solver_type": "mumps"})
    for key, value in defaults.items():
        opts[prefix + key] = value
    for key, value in overrides.items():
        if key.startswith(prefix):
            opts[key] = value
    snes.setFunction(problem.F, problem.b)
    snes.setJacobian(problem.J, problem.A)
    snes.setFromOptions()
    return snes


def run(args):
    t_start = time.perf_counter()
    cpu_start = time.process_time()
    case, l = args.case, args.l
    if args.mesh == "unstructured":
        msh = build_unstructured_mesh(case, args.spacing, args.seed)
    else:
        msh = build_structured_mesh(case, args.n0, args.levels, args.notch_levels, args.mesh)
    sizes = cell_sizes(msh, case, l)
    V_u = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    V_v = fem.FunctionSpace(msh, ("Lagrange", 1))
    u, v = fem.Function(V_u, name="u"), fem.Function(V_v, name="v")
    v_step, v_sweep, v_lower = fem.Function(V_v), fem.Function(V_v), fem.Function(V_v)
    u_start = fem.Function(V_u)

    def notch_field(p):
        dx_tip = np.maximum(p[0] - NOTCH_TIP_X, 0.0)
        d = np.sqrt(dx_tip**2 + (p[1] - NOTCH_Y) ** 2)
        return 1.0 - np.exp(-np.maximum(d - args.notch_core, 0.0) / l)

    v.interpolate(notch_field)
    v0 = v.x.array.copy()
    v_step.x.array[:] = v0
    v_lower.x.array[:] = 0.0

    eps = ufl.sym(ufl.grad(u))
    tr = ufl.tr(eps)
    tension = ufl.conditional(ufl.gt(tr, 0.0), 1.0, 0.0)
    psi_plus = 0.5 * BULK * tr**2 * tension + MU * (ufl.inner(eps, eps) - tr**2 / 3.0)
    psi_minus = 0.5 * BULK * tr**2 * (1.0 - tension)
    degradation = v**2 + K_RESIDUAL
    identity = ufl.Identity(2)
    sigma = (degradation * (BULK * tr * tension * identity + 2.0 * MU * (eps - tr / 3.0 * identity))
             + BULK * tr * (1.0 - tension) * identity)
    dx = ufl.Measure("dx", domain=msh, metadata=QUAD)
    w_u, w_v = ufl.TestFunction(V_u), ufl.TestFunction(V_v)
    residual_u = ufl.inner(sigma, ufl.sym(ufl.grad(w_u))) * dx
    surface_density = GC * ((1.0 - v) ** 2 / (2.0 * l) + 0.5 * l * ufl.inner(ufl.grad(v), ufl.grad(v)))
    energy_v = (degradation * psi_plus + surface_density) * dx
    residual_v = ufl.derivative(energy_v, v, w_v)
    elastic_energy_form = fem.form((degradation * psi_plus + psi_minus) * dx)
    surface_energy_form = fem.form(surface_density * dx)

    fdim = msh.topology.dim - 1
    bottom = dmesh.locate_entities_boundary(msh, fdim, lambda p: np.isclose(p[1], 0.0))
    top = dmesh.locate_entities_boundary(msh, fdim, lambda p: np.isclose(p[1], 1.0))
    sides = dmesh.locate_entities_boundary(msh, fdim, lambda p: np.isclose(p[0], 0.0) | np.isclose(p[0], 1.0))
    zero = PETSc.ScalarType(0.0)
    delta_const = fem.Constant(msh, PETSc.ScalarType(0.0))
    bottom_dofs = fem.locate_dofs_topological(V_u, fdim, bottom)
    top_x = fem.locate_dofs_topological(V_u.sub(0), fdim, top)
    top_y = fem.locate_dofs_topological(V_u.sub(1), fdim, top)
    bcs = [fem.dirichletbc(np.zeros(2, dtype=PETSc.ScalarType), bottom_dofs, V_u)]
    if case == "sent":
        bcs += [fem.dirichletbc(zero, top_x, V_u.sub(0)), fem.dirichletbc(delta_const, top_y, V_u.sub(1))]
        reaction_dofs = top_y
    else:
        side_y = fem.locate_dofs_topological(V_u.sub(1), fdim, sides)
        bcs += [fem.dirichletbc(delta_const, top_x, V_u.sub(0)), fem.dirichletbc(zero, top_y, V_u.sub(1)),
                fem.dirichletbc(zero, side_y, V_u.sub(1))]
        reaction_dofs = top_x

    problem_u = SnesProblem(residual_u, u, bcs)
    problem_v = SnesProblem(residual_v, v, [])
    overrides = dict(option.split("=", 1) for option in args.petsc)
    snes_u = make_snes(problem_u, "u_", vi=False, overrides=overrides)
    snes_v = make_snes(problem_v, "v_", vi=True, overrides=overrides)
    reaction_form = fem.form(residual_u)
    reaction_vec = fem.petsc.create_vector(reaction_form)

    def reaction():
        with reaction_vec.localForm() as r:
            r.set(0.0)
        fem.petsc.assemble_vector(reaction_vec, reaction_form)
        return float(reaction_vec.array[reaction_dofs].sum())

    n_u, n_v = V_u.dofmap.index_map.size_local * 2, V_v.dofmap.index_map.size_local
    coords = V_v.tabulate_dof_coordinates()[:, :2]
    os.makedirs(args.out, exist_ok=True)
    stem = os.path.join(args.out, f"fenicsx_fracture_{case}_l{l:g}")
    snapshots = [float(d) for d in args.snapshots.split(",") if d]
    deltas = load_schedule(parse_schedule(args.schedule))
    record = {"delta": [0.0], "force": [0.0], "elastic_energy": [0.0],
              "surface_energy": [float(fem.assemble_scalar(surface_energy_form))],
              "sweeps": [0], "u_solve_s": [0.0], "v_solve_s": [0.0], "step_s": [0.0],
              "newton_u": [0], "newton_v": [0], "sweep_change": [0.0]}
    unconverged = []
    u_retries = u_failures = 0
    setup_s = time.perf_counter() - t_start
    print(f"{case}: l = {l}, {sizes['cells']} cells, {n_v} nodes, {n_u} + {n_v} unknowns, "
          f"band edges: mean {sizes['edge_mean_band']:.5f}, longest {sizes['h_max_band']:.5f}, {len(deltas)} steps, setup {setup_s:.1f} s", flush=True)
    # A run stopped by hand (SIGINT, SIGTERM) finishes the step in progress and writes its record
    # of the steps done: a long run is never lost whole.
    stop_signals = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda received, frame: stop_signals.append(received))
    t_loop = time.perf_counter()
    for step, delta in enumerate(deltas, start=1):
        t_step = time.perf_counter()
        delta_const.value = delta
        fem.petsc.set_bc(u.vector, bcs)
        u.x.scatter_forward()
        t_u = t_v = 0.0
        it_u = it_v = 0
        change = np.inf
        sweeps = 0
        while sweeps < args.max_iter:
            sweeps += 1
            v_sweep.x.array[:] = v.x.array
            t0 = time.perf_counter()
            u_start.x.array[:] = u.x.array
            snes_u.solve(None, u.vector)
            it_u += snes_u.getIterationNumber()
            if snes_u.getConvergedReason() <= 0:
                # Full Newton steps can cycle when cells switch between tension and compression
                # (the stress is only piecewise linear): retry from the same start with half steps.
                u_retries += 1
                u.x.array[:] = u_start.x.array
                options = PETSc.Options()
                options["u_snes_linesearch_damping"] = 0.5
                options["u_snes_max_it"] = 400
                snes_u.setFromOptions()
                snes_u.solve(None, u.vector)
                it_u += snes_u.getIterationNumber()
                options["u_snes_linesearch_damping"] = 1.0
                options["u_snes_max_it"] = 50
                snes_u.setFromOptions()
                if snes_u.getConvergedReason() <= 0:
                    u_failures += 1
                    print(f"  step {step}: u SNES reason {snes_u.getConvergedReason()} after the damped retry",
                          flush=True)
            u.x.scatter_forward()
            # The reaction of this equilibrium (u and the v it was solved with); the v solve below
            # moves v by less than --tol once the sweeps have converged.
            force = reaction()
            t1 = time.perf_counter()
            snes_v.setVariableBounds(v_lower.vector, v_step.vector)
            snes_v.solve(None, v.vector)
            v.x.scatter_forward()
            t_v += time.perf_counter() - t1
            t_u += t1 - t0  # includes the reaction assembly
            if snes_v.getConvergedReason() <= 0:
                print(f"  step {step}: v SNES reason {snes_v.getConvergedReason()}", flush=True)
            it_v += snes_v.getIterationNumber()
            change = float(np.abs(v.x.array - v_sweep.x.array).max())
            if change < args.tol:
                break
        if change >= args.tol:
            unconverged.append(step)
        v_step.x.array[:] = v.x.array
        record["delta"].append(delta)
        record["force"].append(force)
        record["elastic_energy"].append(float(fem.assemble_scalar(elastic_energy_form)))
        record["surface_energy"].append(float(fem.assemble_scalar(surface_energy_form)))
        record["sweeps"].append(sweeps)
        record["u_solve_s"].append(t_u)
        record["v_solve_s"].append(t_v)
        record["newton_u"].append(it_u)
        record["newton_v"].append(it_v)
        record["sweep_change"].append(change)
        record["step_s"].append(time.perf_counter() - t_step)
        for snapshot in snapshots:
            if record["delta"][-2] < snapshot <= delta + 1e-12:
                plot_field(V_v, v, coords, f"{stem}_at_{delta:.5f}.png",
                           f"FEniCSx {case.upper()}, l = {l:g}: v at delta = {delta:.5f} mm")
        if sweeps > 10 or step % args.print_every == 0:
            print(f"  step {step:5d} delta {delta:.6f} F {force:.5f} sweeps {sweeps:3d} change {change:.1e} "
                  f"min v {v.x.array.min():.3f} t {time.perf_counter() - t_loop:.0f} s", flush=True)
        if stop_signals:
            print(f"  stopped by signal {stop_signals[0]} after step {step} (delta {delta:.6f}) of {len(deltas)}", flush=True)
            break
    loop_s = time.perf_counter() - t_loop
    steps_done = len(record["delta"]) - 1

    forces = np.array(record["force"])
    peak = int(np.argmax(forces))
    broken = (v.x.array < 0.1) & (v0 >= 0.1)
    crack = coords[broken]
    crack = crack[np.argsort(np.hypot(crack[:, 0] - NOTCH_TIP_X, crack[:, 1] - NOTCH_Y))]
    sweeps_arr = np.array(record["sweeps"][1:])
    result = {
        "solver": "fenicsx", "dolfinx": dolfinx.__version__, "case": case, "l": l,
        "model": {"lambda": LAMBDA, "mu": MU, "Gc": GC, "k": K_RESIDUAL, "split": "volumetric-deviatoric (Amor 2009)",
                  "surface": "AT2 Gc[(1-v)^2/(2l) + l/2|grad v|^2]", "degradation": "v^2 + k",
                  "plane": "strain", "notch": "initial field v0 = 1 - exp(-max(d - core, 0)/l), segment y=0.5, 0<=x<=0.5",
                  "notch_core": args.notch_core,
                  "irreversibility": "0 <= v <= v_previous_step (SNES vinewtonrsls)"},
        "discretization": {"element": "P1/P1 triangles", "mesh": args.mesh,
                           **({"spacing": args.spacing, "seed": args.seed} if args.mesh == "unstructured" else
                              {"n0": args.n0, "levels": args.levels, "notch_levels": args.notch_levels}), **sizes,
                           "nodes": int(n_v), "unknowns_u": int(n_u), "unknowns_v": int(n_v),
                           "unknowns": int(n_u + n_v)},
        "schedule": args.schedule,
        "staggered": {"tol_v_max_change": args.tol, "max_sweeps": args.max_iter,
                      "unconverged_steps": unconverged,
                      "u_newton_damped_retries": u_retries, "u_newton_failures": u_failures},
        "steps": steps_done, "steps_scheduled": len(deltas), "stopped_by_signal": bool(stop_signals),
        "peak_force": float(forces[peak]), "delta_at_peak": float(record["delta"][peak]),
        "setup_s": setup_s, "loop_s": loop_s, "wall_s": time.perf_counter() - t_start,
        "cpu_s": time.process_time() - cpu_start,
        "mean_step_s": loop_s / max(steps_done, 1), "total_sweeps": int(sweeps_arr.sum()),
        "max_sweeps_in_a_step": int(sweeps_arr.max()),
        "u_solve_s_total": float(np.sum(record["u_solve_s"])), "v_solve_s_total": float(np.sum(record["v_solve_s"])),
        "crack_points_v_below_0.1": crack.round(5).tolist(),
        **record,
    }
    with open(stem + ".json.part", "w") as f:
        json.dump(result, f, indent=1)
    os.replace(stem + ".json.part", stem + ".json")
    plot_field(V_v, v, coords, stem + ".png", f"FEniCSx {case.upper()}, l = {l:g}: v at delta = {record['delta'][-1]:g} mm")
    print(f"{case}{' (stopped by hand: the peak so far)' if stop_signals else ''}: peak force {result['peak_force']:.5f} kN at delta {result['delta_at_peak']:.6f} mm, "
          f"{steps_done} steps, {result['total_sweeps']} sweeps, unconverged {len(unconverged)}, "
          f"wall {result['wall_s']:.1f} s, cpu {result['cpu_s']:.1f} s (u {result['u_solve_s_total']:.1f} s, v {result['v_solve_s_total']:.1f} s)"
          f" -> {stem}.json", flush=True)
    return result


def plot_field(V_v, v, coords, path, title):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.tri as mtri
    triangles = V_v.dofmap.list.array.reshape(-1, 3)
    tri = mtri.Triangulation(coords[:, 0], coords[:, 1], triangles)
    fig, ax = plt.subplots(figsize=(5.2, 4.6))
    art = ax.tripcolor(tri, v.x.array, shading="gouraud", cmap="viridis", vmin=0.0, vmax=1.0)
    fig.colorbar(art, ax=ax, label="v")
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", choices=["sent", "sens"], required=True)
    ap.add_argument("--l", type=float, default=0.015)
    ap.add_argument("--out", required=True)
    ap.add_argument("--mesh", choices=["unstructured"] + sorted(DIAGONALS), default="unstructured",
                    help="unstructured (default), or a create_rectangle mesh with that diagonal refined by bisection")
    ap.add_argument("--spacing", type=float, default=None,
                    help="unstructured: node spacing in the crack and notch bands (default l/2.5)")
    ap.add_argument("--seed", type=int, default=20100407, help="unstructured: seed of the node jitter")
    ap.add_argument("--n0", type=int, default=24, help="structured: cells per side of the initial uniform mesh")
    ap.add_argument("--levels", type=int, default=3, help="bisection levels in the crack band")
    ap.add_argument("--notch-levels", type=int, default=None,
                    help="bisection levels along the initial notch (default: --levels)")
    ap.add_argument("--schedule", default=None, metavar="UNTIL:STEP,...",
                    help="load steps: constant STEP up to each UNTIL (default: see DEFAULT_SCHEDULES)")
    ap.add_argument("--notch-core", type=float, default=0.0,
                    help="not the reference model: v0 = 0 within this distance of the notch segment and "
                         "1 - exp(-(d - core)/l) beyond (0: the model as specified)")
    ap.add_argument("--tol", type=float, default=1e-4, help="max |v change| over one u-v sweep")
    ap.add_argument("--max-iter", type=int, default=100, help="max u-v sweeps per load step")
    ap.add_argument("--print-every", type=int, default=50)
    ap.add_argument("--snapshots", default="", help="comma-separated deltas at which to also plot v")
    ap.add_argument("--petsc", action="append", default=[], metavar="PREFIX_KEY=VALUE",
                    help="override a PETSc option of the u_ or v_ solver, e.g. v_pc_factor_mat_solver_type=petsc")
    args = ap.parse_args()
    if args.spacing is None:
        args.spacing = args.l / 2.5
    if args.notch_levels is None:
        args.notch_levels = args.levels
    if args.schedule is None:
        args.schedule = DEFAULT_SCHEDULES[args.case]
    if MPI.COMM_WORLD.size != 1:
        sys.exit("fenicsx_fracture.py: run serially (the reaction sum and the outputs assume one process)")
    run(args)


if __name__ == "__main__":
    main()
