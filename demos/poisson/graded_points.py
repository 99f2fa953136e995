#!/usr/bin/python3
"""Graded node sets on the unit square for the Poisson demo (a [nodes] file = "..." of a scene).

    /usr/bin/python3 demos/poisson/graded_points.py N OUT.txt [--alpha A] [--warp B]

N x N nodes, the image of the uniform grid of the unit square under the smooth map
    X = s(xi) + B sin(pi xi) sin(2 pi eta) / (2 pi),   Y = s(eta) + B sin(2 pi xi) sin(pi eta) / (2 pi),
    s(t) = t - A sin(2 pi t) / (2 pi).
s clusters the nodes towards the sides: the spacing is (1 - A) h at the boundary and (1 + A) h in
the middle (h = 1/(N - 1); A = 0.5: a ratio of 3). The warp B bends the grid lines so the set is
not a tensor-product grid (B = 0: it is). Both terms vanish on the sides' normal direction, so every
boundary node stays on its side and the corners stay put. Deterministic; coordinates are written
with 17 significant digits, one point per line (docs/geometry.md).
"""

import argparse
import math
import sys


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("n", type=int, help="nodes per axis (>= 3)")
    p.add_argument("out", help="output point file")
    p.add_argument("--alpha", type=float, default=0.5, help="grading amplitude A in [0, 1)")
    p.add_argument("--warp", type=float, default=0.15, help="warp amplitude B (small: the map must stay one-to-one)")
    a = p.parse_args()
    if a.n < 3 or not 0 <= a.alpha < 1:
        sys.exit("graded_points.py: need N >= 3 and 0 <= alpha < 1")
    tau = 2 * math.pi

    def s(t):
        return t - a.alpha * math.sin(tau * t) / tau

    lines = [f"# graded_points.py {a.n} --alpha {a.alpha} --warp {a.warp}: {a.n * a.n} nodes on [0, 1]^2"]
    for j in range(a.n):
        eta = j / (a.n - 1)
        for i in range(a.n):
            xi = i / (a.n - 1)
            x = s(xi) + a.warp * math.sin(math.pi * xi) * math.sin(tau * eta) / tau
            y = s(eta) + a.warp * math.sin(tau * xi) * math.sin(math.pi * eta) / tau
            # The sides exactly: sin(pi) is 1.2e-16, not 0.
            if i in (0, a.n - 1):
                x = float(i > 0)
            if j in (0, a.n - 1):
                y = float(j > 0)
            lines.append(f"{min(max(x, 0.0), 1.0):.17g} {min(max(y, 0.0), 1.0):.17g}")
    with open(a.out, "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
