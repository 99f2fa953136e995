#!/usr/bin/python3
"""Measure the diffuse interface of an axisymmetric phase-field run along its output series.

    /usr/bin/python3 scripts/interface_width.py RUN_history.json [--every K] [--json OUT.json]
    /usr/bin/python3 scripts/interface_width.py --quadrature RUN_checkpoint_quadrature.h5... --eps EPS --area A0

For each series file (current node positions, their triangulation and the nodal phi) it prints

  sharp area     the area of the phi = 0 surface, 2 pi r ds summed over the contour's segments;
  sharp volume   the volume where phi > 0, 2 pi r dA;
  width          the volume of the band |phi| < 1/2 divided by the sharp area: for a tanh profile
                 of width delta, tanh(s / (sqrt(2) delta)), it is 2 sqrt(2) atanh(1/2) delta =
                 1.554 delta;
  relative       the width against the first file's.

phi is the nodal coefficients, linear on each triangle (sampled at 78 points per triangle for
the band); LME is not interpolating, so the numbers carry an error of the node spacing, which the
relative width mostly cancels. After a large deformation the coefficients oscillate at the node
scale and the sharp area is unreliable (a prolate at step 90 gave 3.6 for A0 = 2.01), and a re-mesh
changes the widths (0.94 -> 1.00 at a re-mesh that changed E by 4e-5).

--quadrature measures at the quadrature points instead, which carry phi0 and their weights through
resets and re-meshes: the checkpoint's points are the reference configuration of its last reset,
a state the run went through. It prints the band volume (|phi0| < 1/2, weights times 2 pi r), the
width (band volume / A0, the sharp area taken as the constrained area) and that width against a
tanh profile of width eps (1.554 eps), the measure that does not depend on the node spacing.

Why: the phase-field energy with spontaneous curvature C0 is not bounded by its sharp-interface
limit at finite eps C0. A flat interface whose profile has width alpha*eps has bending energy
k alpha [(1 - alpha^-2)^2 / (20 eps^2) + C0^2 / 2] per unit area, lowest near
alpha = 1 - 5/4 (eps C0)^2. A Lagrangian run can reach it by squeezing the interface, and this
script shows whether it did (docs/dynamics.md, the prolate after a jump of C0).
Needs Debian's python3-h5py and numpy (call /usr/bin/python3, not a pyenv one).
"""

import argparse
import json
import math
import os
import re
import sys


def fail(message):
    sys.exit(f"interface_width.py: {message}")


try:
    import h5py
    import numpy as np
except ImportError as error:
    fail(f"{error}: install python3-h5py and python3-numpy and run /usr/bin/python3")

SAMPLES_PER_SIDE = 12


def triangle_samples():
    """Barycentric coordinates of the centroids of a regular subdivision of a triangle."""
    n = SAMPLES_PER_SIDE
    rows = [((i + 1 / 3) / n, (j + 1 / 3) / n) for i in range(n) for j in range(n - i)]
    rows += [((i + 2 / 3) / n, (j + 2 / 3) / n) for i in range(n) for j in range(n - i - 1)]
    b = np.array(rows)
    return np.c_[b, 1 - b.sum(axis=1)]


def read_datasets(path, keys, what):
    """The named datasets of an HDF5 file, or a clear failure naming the one missing."""
    try:
        with h5py.File(path, "r") as f:
            for key in keys:
                if key not in f:
                    fail(f"{path}: no dataset '{key}' ({what} has {', '.join(keys)})")
            return [f[key][:] for key in keys]
    except OSError as error:
        fail(f"{path}: {error}")


def measure(path, samples):
    x, cells, phi = read_datasets(path, ("nodes", "cells", "fields/phi"), "a series file of an lmeform dynamics run")
    if x.shape[1] != 2:
        fail(f"{path}: nodes have {x.shape[1]} coordinates; this script measures axisymmetric (r, z) runs")
    p = x[cells]
    v = phi[cells]
    area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                        - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    band = 0.0
    inside = 0.0
    for w in samples:
        value = v @ w
        ring = area * 2 * math.pi * (p[:, :, 0] @ w) / len(samples)
        band += ring[np.abs(value) < 0.5].sum()
        inside += ring[value > 0].sum()
    sharp_area = 0.0
    for t in range(len(cells)):
        crossings = []
        for a, b in ((0, 1), (1, 2), (2, 0)):
            if (v[t, a] > 0) != (v[t, b] > 0):
                s = v[t, a] / (v[t, a] - v[t, b])
                crossings.append(p[t, a] + s * (p[t, b] - p[t, a]))
        if len(crossings) == 2:
            sharp_area += np.linalg.norm(crossings[1] - crossings[0]) * math.pi * (crossings[0][0] + crossings[1][0])
    if sharp_area == 0:
        fail(f"{path}: phi has no zero contour")
    return sharp_area, inside, band / sharp_area


def measure_quadrature(path, eps, area):
    x, weight, phi0 = read_datasets(path, ("nodes", "fields/weight", "fields/qdata_phi0"),
                                    "the checkpoint quadrature file of a run with a qdata phi0")
    ring = weight * 2 * math.pi * x[:, 0]
    band = ring[np.abs(phi0) < 0.5].sum()
    width = band / area
    return {"file": path, "band_volume": band, "inside_volume": ring[phi0 > 0].sum(), "width": width,
            "relative_to_tanh": width / (2 * math.sqrt(2) * math.atanh(0.5) * eps)}


def write_json(rows, path):
    temporary = path + ".part"
    with open(temporary, "w") as f:
        json.dump(rows, f, indent=1)
    os.replace(temporary, path)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("history", nargs="?", help="RUN_history.json of an lmeform dynamics run")
    parser.add_argument("--every", type=int, default=1, help="measure every K-th series file (default 1)")
    parser.add_argument("--json", help="also write the rows to this JSON file")
    parser.add_argument("--quadrature", nargs="+", help="checkpoint quadrature files to measure instead")
    parser.add_argument("--eps", type=float, help="with --quadrature: the interface parameter")
    parser.add_argument("--area", type=float, help="with --quadrature: the constrained area A0")
    args = parser.parse_args()
    if args.quadrature:
        if args.eps is None or args.area is None or args.eps <= 0 or args.area <= 0:
            fail("--quadrature needs --eps and --area, both positive")
        rows = [measure_quadrature(path, args.eps, args.area) for path in args.quadrature]
        for r in rows:
            print(f"{r['file']}: band volume {r['band_volume']:.5g}  inside volume {r['inside_volume']:.5g}  "
                  f"width {r['width']:.5g}  against 1.554 eps {r['relative_to_tanh']:.4f}")
        if args.json:
            write_json(rows, args.json)
        return
    if args.history is None:
        fail("give RUN_history.json or --quadrature files")
    if args.every < 1:
        fail("--every must be at least 1")
    try:
        with open(args.history) as f:
            history = json.load(f)
    except (OSError, json.JSONDecodeError) as error:
        fail(f"{args.history}: {error}")
    series = history.get("series")
    if not series:
        fail(f"{args.history}: no 'series' entries (was the run's output_every 0?)")
    folder = os.path.dirname(os.path.abspath(args.history))
    samples = triangle_samples()
    rows = []
    for entry in series[:: args.every]:
        path = os.path.join(folder, entry["file"])
        sharp_area, volume, width = measure(path, samples)
        step = int(re.findall(r"(\d+)\.h5$", entry["file"])[-1]) if re.search(r"\d+\.h5$", entry["file"]) else len(rows)
        t_star = entry.get("time", float("nan"))  # the series is written in t*
        rows.append({"step": step, "t_star": t_star, "sharp_area": sharp_area,
                     "sharp_volume": volume, "width": width, "relative_width": width / (rows[0]["width"] if rows else width)})
        r = rows[-1]
        print(f"step {r['step']:>5}  t* {r['t_star']:.4g}  sharp area {sharp_area:.5f}  sharp volume {volume:.5f}  "
              f"width {width:.5f}  relative {r['relative_width']:.3f}", flush=True)
    if args.json:
        write_json(rows, args.json)


if __name__ == "__main__":
    main()
