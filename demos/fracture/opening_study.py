#!/usr/bin/env python3
"""The cost of an opened crack on the LME band (docs/fracture.md, "Surfing"): demos/fracture/opening.toml
run with the band's spacing h = l/2 and l/4; per opening delta, the surface energy per unit length of
the whole crack (4 x dissipated: two halves of length 0.5) in units of Gc, which Griffith puts at 1.
    opening_study.py LMEFORM OUT_DIR [--quick]
--quick runs h = l/2 only. Writes `opening` records (h_min, delta, delta / sqrt(Gc l / E),
band_energy_per_gc, wall_s) into OUT_DIR/fracture.json and draws OUT_DIR/fracture_opening.png.
"""
import json
import pathlib
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from gamma_convergence import merge_records  # noqa: E402  (one writer of fracture.json's records)

HERE = pathlib.Path(__file__).resolve().parent
GC, L, E = 1.0, 0.02, 1.0


def run(lmeform, spacing, work):
    scene = (HERE / "opening.toml").read_text().replace("spacing = 0.01, width = 0.03", f"spacing = {spacing}, width = 0.03")
    if spacing != 0.01 and f"spacing = {spacing}" not in scene:
        raise SystemExit("opening_study: could not set the band's spacing in opening.toml")
    path = work / f"opening_{spacing}.toml"
    path.write_text(scene.replace('directory = "build/demo/fracture/opening"', f'directory = "{work / ("out_" + str(spacing))}"'))
    start = time.time()
    subprocess.run([lmeform, "run", str(path)], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.time() - start
    rows = json.loads((work / ("out_" + str(spacing)) / "history.json").read_text())["steps"]
    delta = [r["constants"]["delta"] for r in rows]
    energy = [4 * r["quantities"]["dissipated"] / GC for r in rows]
    return delta, energy, wall


def main():
    lmeform, out = sys.argv[1], pathlib.Path(sys.argv[2])
    quick = "--quick" in sys.argv
    out.mkdir(parents=True, exist_ok=True)
    records = []
    with tempfile.TemporaryDirectory() as tmp:
        for spacing in ([0.01] if quick else [0.01, 0.005]):
            delta, energy, wall = run(lmeform, spacing, pathlib.Path(tmp))
            scale = (GC * L / E) ** 0.5
            print(f"h = {spacing} (l/{L / spacing:g}): " + ", ".join(f"delta {d:g}: {e:.4f} Gc" for d, e in zip(delta, energy)) + f"; {wall:.1f} s")
            records.append({"case": "opening", "model": "at2", "l": L, "h_min": spacing, "delta": delta,
                            "delta_over_sqrt_gc_l_over_e": [d / scale for d in delta], "band_energy_per_gc": energy,
                            "reference": 1.0, "rel_error": [e - 1.0 for e in energy], "wall_s": wall})
    merge_records(out / "fracture.json", records, {"opening"})
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5.2, 3.6))
        for r in records:
            ax.semilogx([x for x in r["delta_over_sqrt_gc_l_over_e"][1:]], r["band_energy_per_gc"][1:], "o-", ms=3,
                        label=f"h = l/{L / r['h_min']:g}")
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.set_xlabel("opening / sqrt(Gc l / E)")
        ax.set_ylabel("band energy per length / Gc")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "fracture_opening.png", dpi=120)
    except ImportError:
        pass


if __name__ == "__main__":
    main()
