#!/usr/bin/env python3
"""Plots the tables written by lme_basis_demo (the README demo, `make demo`).

usage: plot_lme_basis.py DIR

reads  DIR/lme_basis_gamma08.csv  -> writes DIR/lme_basis_gamma08.png (p, p', p''; seed Fig. 2.3)
       DIR/lme_transition.csv     -> writes DIR/lme_transition.png    (gamma 0.6 -> 6; seed Fig. 2.2)

Only numpy and matplotlib (Agg backend). PNGs are written to a temporary name and renamed.
"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def read_table(path):
    """Returns (meta, columns, data): '# key=v1,v2' comment lines, the header names, the numbers."""
    meta, header, rows = {}, None, []
    try:
        with open(path, encoding="utf-8") as f:
            for line in f:
                line = line.strip()
                if not line:
                    continue
                if line.startswith("#"):
                    body = line[1:].strip()
                    key, sep, value = body.partition("=")
                    if sep and key.strip().isidentifier():
                        meta[key.strip()] = np.array([float(v) for v in value.split(",")])
                    else:
                        meta.setdefault("title", body)
                elif header is None:
                    header = line.split(",")
                else:
                    rows.append([float(v) for v in line.split(",")])
    except OSError as e:
        sys.exit(f"plot_lme_basis.py: cannot read {path}: {e.strerror} (run lme_basis_demo --out DIR first)")
    except ValueError as e:
        sys.exit(f"plot_lme_basis.py: {path}: malformed number: {e}")
    if header is None or not rows:
        sys.exit(f"plot_lme_basis.py: {path}: no data")
    data = np.array(rows)
    if data.shape[1] != len(header):
        sys.exit(f"plot_lme_basis.py: {path}: {data.shape[1]} columns but {len(header)} names in the header")
    return meta, header, data


def columns(header, data, prefix):
    idx = [i for i, name in enumerate(header) if name.startswith(prefix) and name[len(prefix):].isdigit()]
    return data[:, idx]


def save(fig, path):
    tmp = path + ".tmp.png"
    try:
        fig.savefig(tmp, dpi=100)
        os.replace(tmp, path)
    except OSError as e:
        sys.exit(f"plot_lme_basis.py: cannot write {path}: {e.strerror}")
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.remove(tmp)
    print(f"wrote {path}")


def mark_nodes(ax, nodes):
    ax.plot(nodes, np.zeros_like(nodes), "o", color="black", ms=3.5, zorder=5, clip_on=False)


def plot_derivatives(directory):
    meta, header, data = read_table(os.path.join(directory, "lme_basis_gamma08.csv"))
    x = data[:, 0]
    nodes = meta["nodes"]
    gamma = meta["gamma"][0]
    panels = [
        (columns(header, data, "p"), r"$p_a(x)$", "basis functions"),
        (columns(header, data, "dp"), r"$p_a'(x)$", "first derivatives"),
        (columns(header, data, "d2p"), r"$p_a''(x)$", "second derivatives"),
    ]
    colors = plt.cm.turbo(np.linspace(0.05, 0.95, len(nodes)))
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), constrained_layout=True)
    for ax, (values, label, title) in zip(axes, panels):
        for a in range(values.shape[1]):
            ax.plot(x, values[:, a], color=colors[a], lw=1.4)
        ax.axhline(0.0, color="0.6", lw=0.6)
        mark_nodes(ax, nodes)
        ax.set_xlim(x[0], x[-1])
        ax.set_xlabel("$x$")
        ax.set_ylabel(label)
        ax.set_title(title)
        ax.grid(alpha=0.25)
    fig.suptitle(
        rf"1D local maximum-entropy basis, $\gamma = {gamma:g}$, {len(nodes)} uniform nodes on [0, 1] "
        r"(dots), $h = {:g}$".format(meta["spacing"][0])
    )
    save(fig, os.path.join(directory, "lme_basis_gamma08.png"))


def plot_transition(directory):
    meta, header, data = read_table(os.path.join(directory, "lme_transition.csv"))
    x = data[:, 0]
    p = columns(header, data, "p")
    nodes, gamma = meta["nodes"], meta["gamma"]
    norm = matplotlib.colors.Normalize(vmin=gamma.min(), vmax=gamma.max())
    cmap = plt.cm.viridis
    fig, (ax, axg) = plt.subplots(
        2, 1, figsize=(11, 5.4), sharex=True, gridspec_kw={"height_ratios": [4, 1]}, constrained_layout=True
    )
    for a in range(p.shape[1]):
        ax.plot(x, p[:, a], color=cmap(norm(gamma[a])), lw=1.5)
    mark_nodes(ax, nodes)
    ax.set_ylim(-0.03, 1.05)
    ax.set_ylabel(r"$p_a(x)$")
    ax.set_title(
        r"Seamless transition from meshfree ($\gamma_a = %g$, left) to Delaunay-like ($\gamma_a = %g$, right)"
        % (gamma[0], gamma[-1])
    )
    ax.grid(alpha=0.25)
    fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, label=r"$\gamma_a$", pad=0.01)
    axg.scatter(nodes, gamma, c=gamma, cmap=cmap, norm=norm, s=18, zorder=3)
    axg.plot(nodes, gamma, color="0.5", lw=0.8)
    axg.set_ylabel(r"$\gamma_a$")
    axg.set_xlabel("$x$")
    axg.set_xlim(x[0], x[-1])
    axg.grid(alpha=0.25)
    save(fig, os.path.join(directory, "lme_transition.png"))


def main(argv):
    if len(argv) != 2 or argv[1] in ("-h", "--help"):
        print(__doc__.strip(), file=sys.stderr if len(argv) != 2 else sys.stdout)
        return 0 if len(argv) == 2 else 2
    directory = argv[1]
    if not os.path.isdir(directory):
        sys.exit(f"plot_lme_basis.py: {directory} is not a directory (run lme_basis_demo --out {directory} first)")
    plot_derivatives(directory)
    plot_transition(directory)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
