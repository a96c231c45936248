"""Fit each silicone's Yeoh law to its tensile test to break, print the recipe rows, and draw the fits.

Run from the repository::

    python bench/material_fits.py [--plot material_fits.png]

The data are bench/data/tensile/*.csv: the Soft Robotics Materials Database's pull-to-failure tests (see the NOTICE
there), thinned to a point every 0.05 of stretch up to 4 and every 0.5 past it. The fit is
:func:`magfab.models.mechanics.material_fit.fit_yeoh` (its doc: weights, the non-negative coefficients, why). The
printed ``yeoh_*`` rows are what recipes/materials.toml carries; tests/models/test_material_fits.py refits and
compares. The plot shows each test's stress against stretch to 6, the Yeoh law (solid to its fitted stretch, dashed
past it), and the recipe's neo-Hookean band (shaded), which is fitted to 100 % strain only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from magfab.models.mechanics.material_fit import fit_yeoh, read_tensile_csv  # noqa: E402
from magfab.recipes.resolve import material  # noqa: E402

DATA = ROOT / "bench" / "data" / "tensile"
#: The recipe key of each test file.
FILES = {"ecoflex-00-10": "Ecoflex 00-10.csv", "ecoflex-00-30": "Ecoflex 00-30.csv",
         "ecoflex-00-50": "Ecoflex 00-50.csv", "dragon-skin-10": "Dragon Skin 10 MEDIUM.csv",
         "dragon-skin-20": "Dragon Skin 20.csv", "dragon-skin-30": "Dragon Skin 30.csv"}


def fits() -> dict:
    """Every silicone's fit: {key: (stretch, stress kPa, YeohFit)}."""
    out = {}
    for key, name in FILES.items():
        lam, p = read_tensile_csv(DATA / name)
        out[key] = (lam, p, fit_yeoh(lam, p))
    return out


def _plot(path: Path, results: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(12, 7))
    for ax, (key, (lam, p, f)) in zip(axes.ravel(), results.items()):
        band = material(key).shear_modulus_kPa
        x = np.linspace(1.0, 6.0, 300)
        g = x - x ** -2
        ax.fill_between(x, band.low * g, band.high * g, color="0.85", label="neo-Hookean band (recipe)")
        shown = lam <= 6.0
        ax.plot(lam[shown], p[shown], "k.", ms=3, label="tensile test")
        inside = x <= f.stretch_max
        ax.plot(x[inside], f.stress_kPa(x[inside]), "C3-", label="Yeoh fit")
        ax.plot(x[~inside], f.stress_kPa(x[~inside]), "C3--", label="Yeoh, past the fit")
        ax.set_title(f"{key}: mu {f.mu_kPa:.3g} kPa, k2 {f.k2:.3g}, k3 {f.k3:.2g}", fontsize=9)
        ax.set_xlabel("stretch")
        ax.set_ylabel("engineering stress, kPa")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plot", type=Path, help="write the fits' figure here (PNG)")
    args = ap.parse_args(argv)
    results = fits()
    print(f"{'silicone':16s} {'mu kPa':>7s} {'k2':>7s} {'k3':>9s} {'rms %':>6s} {'max %':>6s} points  data end")
    for key, (lam, _, f) in results.items():
        print(f"{key:16s} {f.mu_kPa:7.3g} {f.k2:7.3g} {f.k3:9.3g} {f.rms_pct:6.1f} {f.max_pct:6.1f} {f.points:6d}  "
              f"{lam.max():.1f}")
    if args.plot:
        _plot(args.plot, results)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
