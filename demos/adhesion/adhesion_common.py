"""Shared by the adhesion measurement scripts (contact_curvature.py, free_bound.py, droplet_limit.py,
fig317_series.py): scene generation from adhered_vesicle.toml, one lmeform run, the phi = 0 contour
of the output and the measurements made on it.

Normalisations (derived in docs/adhesion.md):
  * bending: lmeform's helfrich_axisymmetric gives (k/8) int (c1 + c2)^2 dA in the sharp limit, so
    the seed's / Seifert-Lipowsky's kappa (E = kappa/2 int (c1 + c2)^2 dA) is kappa = k/4;
  * adhesion: with the equilibrium profile phi = tanh((z - z0)/(sqrt(2) eps)) of a flat membrane at
    the height z0 that minimises int W F dz, the form realises -W_EFF_PER_OMEGA * omega per area
    (computed by flat_adhesion_per_area below, independent of eps: W and F scale with eps);
  * the contact curvature of Seifert and Lipowsky is C_c = sqrt(2 w / kappa) = sqrt(8 w / k).
"""
import json
import math
import os
import re
import subprocess
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
FORM = os.path.join(HERE, "adhesion_axisymmetric.form")
BASE_SCENE = os.path.join(HERE, "adhered_vesicle.toml")


def adhesion_potential(h, omega, delta, repulsion=2.0):
    """W(h) of adhesion_axisymmetric.form."""
    hc = np.maximum(h, delta)
    lj = omega * (2.0 / 3.0 * (delta / hc) ** 10 - 5.0 / 3.0 * (delta / hc) ** 4)
    return np.where(h < delta, -omega + repulsion * omega * (delta - h) / delta, lj)


def flat_adhesion_per_area(delta_over_eps=2.0, repulsion=2.0):
    """(w / omega, z0 / eps): minus the least adhesion energy per area of a flat tanh interface, and the
    height of its phi = 0 level. Computed with eps = omega = 1 (the result is scale invariant)."""
    z = np.linspace(0.0, 40.0, 400001)
    W = adhesion_potential(z, 1.0, delta_over_eps, repulsion)

    def energy(z0):
        phi = np.tanh((z - z0) / math.sqrt(2.0))
        F = 3.0 * math.sqrt(2.0) / 8.0 * (phi * phi - 1.0) ** 2
        return np.trapz(W * F, z)

    grid = np.linspace(0.5, 6.0, 551)
    values = [energy(z0) for z0 in grid]
    i = int(np.argmin(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    for _ in range(60):  # golden-section refinement
        a, b = lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo)
        if energy(a) < energy(b):
            hi = b
        else:
            lo = a
    z0 = 0.5 * (lo + hi)
    return -energy(z0), z0


W_EFF_PER_OMEGA, Z0_PER_EPS = flat_adhesion_per_area()


def contact_curvature_theory(omega, k):
    """Seifert-Lipowsky: C_c = sqrt(2 w / kappa), w = W_EFF_PER_OMEGA omega, kappa = k / 4."""
    return math.sqrt(2.0 * W_EFF_PER_OMEGA * omega / (k / 4.0))


def oblate_semi_axes(A, V):
    """Semi-axes (a, c), c < a, of the oblate spheroid with area A and volume V."""
    def area(a, c):
        e = math.sqrt(1.0 - (c / a) ** 2)
        return 2 * math.pi * a * a * (1 + (1 - e * e) / e * math.atanh(e)) if e > 1e-8 else 4 * math.pi * a * a
    lo, hi = 1e-6, 1.0 - 1e-9  # aspect ratio c / a
    for _ in range(200):
        q = 0.5 * (lo + hi)
        a = (3 * V / (4 * math.pi * q)) ** (1.0 / 3.0)
        if area(a, q * a) > A:
            lo = q
        else:
            hi = q
    q = 0.5 * (lo + hi)
    a = (3 * V / (4 * math.pi * q)) ** (1.0 / 3.0)
    return a, q * a


def make_scene(path, name, *, omega, eps, radius=0.3, reduced_volume=0.9, k=1.0, spacing=None,
               box=None, gap=None, adhesion=True, out_dir=None):
    """A variant of adhered_vesicle.toml: the vesicle (R, v) starts as the oblate spheroid of its area
    and volume, its lowest point `gap` (default Z0_PER_EPS eps, the bottom of the well) above the wall
    z = 0; uniform grid of `spacing` (default eps / 2) on [0, box[0]] x [0, box[1]]."""
    spacing = spacing or eps / 2.0
    A0 = 4 * math.pi * radius ** 2
    V0 = reduced_volume * 4.0 / 3.0 * math.pi * radius ** 3
    a, c = oblate_semi_axes(A0, V0)
    gap = Z0_PER_EPS * eps if gap is None else gap
    if box is None:
        box = (a + 0.4 * radius + 4 * eps, 2 * c + gap + 0.8 * radius + 4 * eps)
    # whole numbers of intervals
    box = tuple(spacing * math.ceil(b / spacing - 1e-9) for b in box)
    text = open(BASE_SCENE).read()
    subs = [
        (r'^name = .*', f'name = "{name}"'),
        (r'"adhesion_axisymmetric.form"', f'"{FORM}"'),
        (r'^upper = .*', f'upper = [{box[0]:.10g}, {box[1]:.10g}]'),
        (r'^spacing = .*', f'spacing = {spacing:.10g}'),
        (r'^k = .*', f'k = {k:.10g}'),
        (r'^eps = .*', f'eps = {eps:.10g}'),
        (r'^omega = .*', f'omega = {omega:.10g}'),
        (r'^radius = .*', f'radius = {radius:.10g}'),
        (r'^reduced_volume = .*', f'reduced_volume = {reduced_volume:.10g}'),
        (r'^shape = .*', 'shape = "ellipsoid"'),
        (r'^center = .*', f'center = [0.0, {gap + c:.10g}]'),
        (r'^semi_axes = .*', f'semi_axes = [{a:.10g}, {c:.10g}]'),
        (r'^png = .*', 'png = false'),
    ]
    if out_dir:
        subs.append((r'^directory = .*', f'directory = "{out_dir}"'))
    for pattern, repl in subs:
        text, n = re.subn(pattern, repl.replace("\\", "\\\\"), text, count=1, flags=re.M)
        if n != 1:
            raise RuntimeError(f"{BASE_SCENE}: no line matches {pattern}")
    if not adhesion:
        # the form leaves the model too: its requirements read constants that are then not given
        text = text.replace(f', "{FORM}"', '')
        text = re.sub(r'^energy = \["bending", "adhesion"\].*$', 'energy = ["bending"]', text, flags=re.M)
        text = re.sub(r'^(omega|z_wall|delta_over_eps|repulsion) = .*\n', '', text, flags=re.M)
    text += ('\n[quantities]\nbending_energy = { energy = "bending" }\n'
             + ('adhesion_energy = { energy = "adhesion" }\n' if adhesion else ''))
    with open(path, "w") as f:
        f.write(text)
    return path


def run(lmeform, scene, out_dir, name):
    """Runs one scene; returns (the JSON report, the log's path)."""
    os.makedirs(out_dir, exist_ok=True)
    json_path = os.path.join(out_dir, name + ".json")
    log_path = os.path.join(out_dir, name + ".log")
    t = time.time()
    with open(log_path, "w") as log:
        code = subprocess.call([lmeform, "run", scene, "--json", json_path, "--output", out_dir], stdout=log, stderr=subprocess.STDOUT)
    if not os.path.exists(json_path):
        raise RuntimeError(f"{scene}: lmeform run failed with code {code} (log {log_path})")
    report = json.load(open(json_path))
    report["wall_clock_s"] = time.time() - t
    return report


def membrane_contour(h5_path):
    """The phi = 0 contour of an output file as an (n, 2) array of (r, z), ordered from its end on the
    axis nearest the wall (the longest contour line)."""
    import h5py
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.tri as mtri
    with h5py.File(h5_path, "r") as f:
        nodes = f["nodes"][:]
        cells = f["cells"][:]
        phi = f["fields/phi"][:]
    import matplotlib.pyplot as plt
    tri = mtri.Triangulation(nodes[:, 0], nodes[:, 1], cells)
    fig = plt.figure()
    lines = plt.tricontour(tri, phi, levels=[0.0]).allsegs[0]
    plt.close(fig)
    line = max(lines, key=lambda l: len(l))
    line = np.asarray(line)
    # start at the axis end with the lower z
    ends = [line[0], line[-1]]
    if abs(ends[1][0]) < abs(ends[0][0]) - 1e-12 or (abs(ends[0][0] - ends[1][0]) < 1e-9 and ends[1][1] < ends[0][1]):
        line = line[::-1]
    return line


def resample(line, ds):
    seg = np.hypot(*np.diff(line, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    keep = np.concatenate([[True], seg > 1e-12])
    s, line = s[keep], line[keep]
    t = np.arange(0.0, s[-1], ds)
    return t, np.column_stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])])


def contact_geometry(line, eps, angle_window=(20.0, 60.0)):
    """Measures the contact line on the meridian (ordered from the axis near the wall):
    the tangent angle theta(s) = atan2(dz, dr) of the arc-length-resampled contour is fitted by a
    quadratic in s over the points whose angle lies in angle_window (degrees) on the first rise off the
    flat contact zone; the fit is extrapolated to theta = 0, which defines the contact point s_c (the
    sharp model's contact line, where the bound part, theta = 0, meets the free part); the contact
    curvature is d theta / ds there. Returns a dict with curvature, contact radius r_c (the contour's r
    at s_c), the flat zone's height z_flat, and the fit's points."""
    ds = eps / 20.0
    s, pts = resample(line, ds)
    # smooth the polyline's kinks (the contour is piecewise linear on the triangles) over about eps / 2
    width = max(int(round(0.5 * eps / ds)), 1)
    kernel = np.ones(2 * width + 1) / (2 * width + 1)
    r = np.convolve(np.pad(pts[:, 0], width, mode="edge"), kernel, mode="valid")
    z = np.convolve(np.pad(pts[:, 1], width, mode="edge"), kernel, mode="valid")
    theta = np.degrees(np.unwrap(np.arctan2(np.gradient(z, s), np.gradient(r, s))))
    lo, hi = angle_window
    # first index where theta exceeds hi; the window is the run of points before it with theta >= lo
    above = np.flatnonzero(theta > hi)
    if len(above) == 0:
        raise RuntimeError("the contour never turns by the window's upper angle")
    j = above[0]
    i = j
    while i > 0 and theta[i - 1] >= lo:
        i -= 1
    ss, tt = s[i:j], np.radians(theta[i:j])
    if len(ss) < 5:
        raise RuntimeError("too few contour points in the angle window")
    c2, c1, c0 = np.polyfit(ss, tt, 2)
    # the root of the quadratic nearest the window, below it
    roots = np.roots([c2, c1, c0])
    roots = roots[np.isreal(roots)].real
    roots = roots[roots < ss[0] + 1e-12]
    if len(roots) == 0:
        raise RuntimeError("the fit does not extrapolate to theta = 0 below the window")
    sc = roots.max()
    curvature = 2 * c2 * sc + c1
    rc = float(np.interp(sc, s, r))
    flat = (theta[: max(i, 1)] < 5.0) & (r[: max(i, 1)] < rc - eps)
    z_flat = float(np.median(z[: max(i, 1)][flat])) if flat.any() else float("nan")
    return {"curvature": float(curvature), "contact_radius": rc, "z_flat": z_flat, "s_contact": float(sc),
            "window_s": [float(ss[0]), float(ss[-1])], "s": s, "r": r, "z": z, "theta": np.radians(theta)}


def bound_fraction(line, eps, tolerance=None):
    """Fraction of the membrane's area (the phi = 0 contour's surface of revolution) that lies within
    `tolerance` (default eps) above the lowest flat level Z0_PER_EPS eps (the bottom of the well)."""
    tolerance = eps if tolerance is None else tolerance
    s, pts = resample(line, eps / 20.0)
    r, z = pts[:, 0], pts[:, 1]
    dA = 2 * math.pi * r * (eps / 20.0)
    bound = z < Z0_PER_EPS * eps + tolerance
    return float(dA[bound].sum() / dA.sum())


def cap_circle(line, r_min_fraction=0.3, z_above=None):
    """Least-squares circle (centre on the axis r = 0) through the contour points with z above z_above:
    the free cap's radius R_cap and centre height."""
    r, z = line[:, 0], line[:, 1]
    keep = z > z_above if z_above is not None else np.ones(len(r), bool)
    r, z = r[keep], z[keep]
    # (r^2 + (z - zc)^2 = R^2) -> r^2 + z^2 = 2 zc z + (R^2 - zc^2): linear in (zc, R^2 - zc^2)
    A = np.column_stack([2 * z, np.ones(len(z))])
    b = r * r + z * z
    (zc, q), *_ = np.linalg.lstsq(A, b, rcond=None)
    return math.sqrt(q + zc * zc), float(zc)
