#!/usr/bin/env python3
"""The anisotropic surface energy of forms/fracture_anisotropic.form and the crack angles it selects.

G(theta): the energy per unit length of a straight crack whose normal makes the angle theta with the
material axis m0, the minimum over profiles of Gc/(4 l) int c^2 + 2 l^2 a c'^2 + l^4 b c''^2 dx with
c(0) = 1 (c = 1 - v), a(theta) = a1 cos^2 + a2 sin^2, b(theta) = g1111 + (g1122 + 2 g1212 - g1111)
sin^2(2 theta)/2 (the form's header). Computed by finite differences on the half line with the
symmetric condition c'(0) = 0 (a crack, not a boundary), 1000 intervals over 20 l.
A crack direction t (unit tangent) is allowed where the polar plot of 1/G is convex; the preferred
crack directions are the minima of G as a function of the crack direction (normal + 90 degrees).

    anisotropy.py polar OUT.png [--g1111 1 --g1122 0.5 --g1212 4.25 --a1 1 --a2 1]
    anisotropy.py angle SERIES.h5 X0 Y0      the crack angle of a run: a line through the nodes
                                              with v < 0.5 ahead of the initial tip (X0, Y0)
    anisotropy.py record RUN_DIR THETA0_DEG OUT   the last step's crack angle, the mean upward and
                                              downward angles of its ridge (a sawtooth), a record in
                                              OUT/fracture.json and OUT/fracture_anisotropic_THETA0.png
"""
import math
import sys

import numpy as np


def profile_energy(a, b, l=1.0, gc=1.0, length=20.0, n=1000):
    """min Gc/(4l) int_{-inf}^{inf} c^2 + 2 l^2 a c'^2 + l^4 b c''^2, c(0) = 1: twice the half line,
    by finite differences with the mirror ghost c_{-1} = c_1 (c'(0) = 0) and c = 0 beyond 20 l; 1000 intervals: 1e-4 of the converged value)."""
    h = length * l / n
    N = n + 1
    w = np.full(N, h)
    w[0] = h / 2
    # first differences (N-1 x N) and second differences with the mirror ghost (N x N)
    D1 = (np.eye(N, k=1) - np.eye(N))[:-1] / h
    D2 = (np.eye(N, k=1) - 2 * np.eye(N) + np.eye(N, k=-1)) / h**2
    D2[0, 1] = 2 / h**2
    Q = np.diag(w) + 2 * l * l * a * h * D1.T @ D1 + l**4 * b * D2.T @ np.diag(w) @ D2
    c = np.linalg.solve(Q[1:, 1:], -Q[1:, 0])
    full = np.concatenate([[1.0], c])
    return 2 * gc / (4 * l) * (full @ Q @ full)


def surface_energy(theta, p):
    a = p["a1"] * math.cos(theta) ** 2 + p["a2"] * math.sin(theta) ** 2
    b = p["g1111"] + (p["g1122"] + 2 * p["g1212"] - p["g1111"]) * math.sin(2 * theta) ** 2 / 2
    return profile_energy(a, b)


def params(argv):
    p = {"g1111": 1.0, "g1122": 0.5, "g1212": 4.25, "a1": 1.0, "a2": 1.0}
    for k in list(p):
        if f"--{k}" in argv:
            p[k] = float(argv[argv.index(f"--{k}") + 1])
    return p


def polar(out, p):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    thetas = np.linspace(0, 2 * math.pi, 361)
    # G is a function of the normal angle; it has the symmetry of the cubic tensor (period pi/2)
    base = {round(t, 9): None for t in thetas}
    quarter = np.linspace(0, math.pi / 2, 91)
    gq = np.array([surface_energy(t, p) for t in quarter])
    g = np.array([gq[int(round((t % (math.pi / 2)) / (math.pi / 2) * 90)) % 91] for t in thetas])
    fig, ax = plt.subplots(1, 2, subplot_kw={"projection": "polar"}, figsize=(9, 4.2))
    ax[0].plot(thetas, g)
    ax[0].set_title("G(normal angle) / Gc")
    ax[1].plot(thetas, 1 / g)
    ax[1].set_title("1 / G: not convex = forbidden directions")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    imin = int(np.argmin(gq))
    print(f"G / Gc over the normal angle (0..90 deg, relative to theta0): min {gq.min():.4f} at {quarter[imin] * 180 / math.pi:.1f} deg, "
          f"max {gq.max():.4f} at {quarter[int(np.argmax(gq))] * 180 / math.pi:.1f} deg")
    # convexity of 1/G (a polar curve r(t) is convex where r^2 + 2 r'^2 - r r'' >= 0)
    r = 1 / gq
    dt = quarter[1] - quarter[0]
    rp = np.gradient(r, dt)
    rpp = np.gradient(rp, dt)
    concave = [quarter[i] * 180 / math.pi for i in range(2, len(r) - 2) if r[i] ** 2 + 2 * rp[i] ** 2 - r[i] * rpp[i] < 0]
    if concave:
        print(f"1/G is not convex for normal angles {min(concave):.0f}..{max(concave):.0f} deg (mod 90): forbidden crack directions")
    else:
        print("1/G is convex: every direction is allowed (weak anisotropy)")
    return gq, quarter


def crack_angle(series, x0, y0):
    import h5py
    with h5py.File(series, "r") as f:
        x = np.array(f["nodes"])
        v = np.array(f["fields"]["v"]).ravel()
    sel = (v < 0.5) & (x[:, 0] > x0 + 0.02)
    pts = x[sel]
    if len(pts) < 3:
        return float("nan"), 0
    d = pts - np.array([x0, y0])
    # the principal direction of the damaged nodes ahead of the tip
    _, _, vt = np.linalg.svd(d - d.mean(axis=0))
    t = vt[0]
    if t[0] < 0:
        t = -t
    return math.degrees(math.atan2(t[1], t[0])), len(pts)


def crack_path(series, x0, bin_width=0.01):
    """The crack's ridge ahead of the initial tip: per bin of x, the y of the node of least v (< 0.5)."""
    import h5py
    with h5py.File(series, "r") as f:
        x = np.array(f["nodes"])
        v = np.array(f["fields"]["v"]).ravel()
    points = []
    edges = np.arange(x0, x[:, 0].max(), bin_width)
    for lo in edges:
        sel = (x[:, 0] >= lo) & (x[:, 0] < lo + bin_width) & (v < 0.5)
        if not sel.any():
            break
        j = np.argmin(np.where(sel, v, np.inf))
        points.append(x[j])
    return np.array(points)


def record(run, degrees, out):
    """Appends the anisotropic run's crack angles to OUT/fracture.json."""
    import json
    import pathlib
    run, out = pathlib.Path(run), pathlib.Path(out)
    last = sorted((run / "series").glob("*.h5"))[-1]
    angle, n = crack_angle(last, 0.3, 0.0)
    path = crack_path(last, 0.31)
    local = []
    for a, b in zip(path[:-2], path[2:]):
        local.append(math.degrees(math.atan2(b[1] - a[1], b[0] - a[0])))
    up = [a for a in local if a > 5]
    down = [a for a in local if a < -5]
    # preferred crack directions (minima of G: crack normal along a material axis) nearest to x
    minima = sorted(((degrees + k * 90 + 90) % 180 + 180) % 180 for k in range(2))
    minima = [m - 180 if m > 90 else m for m in minima]
    rec = {"case": "anisotropic", "model": "anisotropic", "l": 0.02, "h_min": 0.01, "theta0": degrees, "crack_angle_deg": angle,
           "sawtooth_up_deg": float(np.mean(up)) if up else None, "sawtooth_down_deg": float(np.mean(down)) if down else None,
           "reference": min(minima, key=abs), "reference_minima_deg": minima, "path_points": len(path), "damaged_nodes": n}
    print(json.dumps(rec))
    file = out / "fracture.json"
    old = json.loads(file.read_text()) if file.exists() else {"records": []}
    old["records"] = [r for r in old["records"] if not (r.get("case") == "anisotropic" and r.get("theta0") == degrees)] + [rec]
    file.write_text(json.dumps(old, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import h5py
        with h5py.File(last, "r") as f:
            x = np.array(f["nodes"])
            v = np.array(f["fields"]["v"]).ravel()
        fig, ax = plt.subplots(figsize=(6, 3.2))
        t = ax.tricontourf(x[:, 0], x[:, 1], v, levels=np.linspace(0, 1, 11), cmap="viridis")
        fig.colorbar(t, ax=ax, label="v")
        ax.set_aspect("equal")
        ax.set_title(f"theta0 = {degrees} deg: crack at {angle:.1f} deg")
        fig.tight_layout()
        fig.savefig(out / f"fracture_anisotropic_{degrees}.png", dpi=120)
    except ImportError:
        pass


if __name__ == "__main__":
    if sys.argv[1] == "polar":
        polar(sys.argv[2], params(sys.argv))
    elif sys.argv[1] == "record":
        record(sys.argv[2], float(sys.argv[3]), sys.argv[4])
    elif sys.argv[1] == "angle":
        angle, n = crack_angle(sys.argv[2], float(sys.argv[3]), float(sys.argv[4]))
        print(f"crack angle {angle:.1f} deg ({n} nodes with v < 0.5 ahead of the tip)")
