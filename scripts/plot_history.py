#!/usr/bin/python3
"""Draw columns of a load-stepped run's history (history.csv) against another (docs/scenes.md).

    /usr/bin/python3 plot_history.py history.csv OUT.png --x delta --y force[1] [--y ...] [--title T]

One curve per --y column against the --x column (a force-displacement curve), markers at the
steps. `lmeform plot history.csv --x ... --y ...` calls it; it is installed next to the binary
(share/lmeform/). Needs Debian's python3-matplotlib (call /usr/bin/python3); without it exits 3.
"""

import argparse
import csv
import os
import sys


def fail(message, code=1):
    print(f"plot_history.py: {message}", file=sys.stderr)
    sys.exit(code)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file", help="history.csv written by lmeform run")
    parser.add_argument("out", help="PNG to write")
    parser.add_argument("--x", required=True, help="the column on the horizontal axis")
    parser.add_argument("--y", required=True, action="append", help="a column on the vertical axis (repeatable)")
    parser.add_argument("--title", default=None)
    parser.add_argument("--dpi", type=int, default=150)
    args = parser.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:
        fail(f"{e}; run with Debian's /usr/bin/python3 (python3-matplotlib)", code=3)
    try:
        with open(args.file, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        fail(f"{args.file}: cannot read: {e}")
    if not rows:
        fail(f"{args.file}: no rows")
    columns = list(rows[0].keys())
    for name in [args.x] + args.y:
        if name not in columns:
            fail(f"{args.file} has no column '{name}' (columns: {', '.join(columns)})")
    x = [float(r[args.x]) for r in rows]
    fig, ax = plt.subplots(figsize=(6.4, 4.4), layout="constrained")
    for name in args.y:
        ax.plot(x, [float(r[name]) for r in rows], marker="o", markersize=3, label=name)
    ax.set_xlabel(args.x)
    ax.set_ylabel(args.y[0] if len(args.y) == 1 else "")
    if len(args.y) > 1:
        ax.legend()
    ax.grid(True, linewidth=0.4, alpha=0.5)
    ax.set_title(args.title if args.title is not None else os.path.basename(os.path.dirname(os.path.abspath(args.file))), fontsize=10)
    tmp = args.out + ".tmp"
    try:
        fig.savefig(tmp, dpi=args.dpi, format="png")
        os.replace(tmp, args.out)
    except OSError as e:
        if os.path.exists(tmp):
            os.remove(tmp)
        fail(f"{args.out}: cannot write: {e}")


if __name__ == "__main__":
    main()
