"""A silicone's Yeoh law fitted to its uniaxial tensile test: the large-strain law of recipes/materials.toml.

The neo-Hookean bands of the recipes are fitted to (or, at their stiff end, read at) engineering strains up to
100 %, so they end at a stretch of 2. The FE reaches further: MagOne's kernel-averaged peak stretch is 3.7 at 3 mm
of indentation. The tensile tests of the Soft Robotics Materials Database (Marechal et al., Soft Robotics 2021;
ASTM D412, pulled to failure) reach break, stretches of 8 to 18, so a law fitted to them holds past 2.

The law, incompressible, in units of mu = 2 C10 (:class:`~.material._Material`):

    W = mu / 2 [(I1 - 3) + k2 (I1 - 3)^2 + k3 (I1 - 3)^3],   uniaxial engineering stress
    P(lam) = mu (lam - lam^-2) [1 + 2 k2 s + 3 k3 s^2],       s = lam^2 + 2 / lam - 3.

P is linear in (mu, mu k2, mu k3), so the fit is a linear least squares, weighted by 1 / max(P, floor): relative
error above a tenth of the fitted range's peak stress, so the small strains where a sensor works weigh as much as the
large ones, and the noisy toe of a crosshead-strain test (the first few % of strain) does not dominate. The
coefficients are kept non-negative (scipy's ``nnls``): a Yeoh law with every coefficient positive is stable at every
strain, and the FE needs that. With k3 free, the fits come out with k3 slightly negative, which makes dW/dI1 vanish
at a stretch of about 6. The FE's pointwise stretch passes that at the magnet's corner, and its Newton iteration
stopped at 2.89 mm on MagOne on every mesh tried (1, 0.5, 0.35 mm); with k3 = 0 it reaches 3 mm as fast as the
neo-Hookean law.

``bench/material_fits.py`` fits every silicone with data; ``tests/models/test_material_fits.py`` refits them and
checks the recipes carry the same numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["YeohFit", "uniaxial_stress_kPa", "fit_yeoh", "read_tensile_csv", "FIT_STRETCH", "FLOOR", "ERROR_FROM"]

#: The stretch the fits reach: past the FE's kernel-averaged peak stretch at 3 mm of indentation on MagOne (3.7).
FIT_STRETCH = 4.0
#: The weight floor, a fraction of the fitted range's peak stress.
FLOOR = 0.1
#: Errors are stated from this stretch on: below it a crosshead-strain test's toe (slack, the grips seating) is not
#: the material.
ERROR_FROM = 1.2


@dataclass(frozen=True)
class YeohFit:
    """A Yeoh law fitted to a uniaxial test: mu (kPa) and the ratios k2 = C20/C10, k3 = C30/C10, over stretches
    1 to ``stretch_max``, with its relative error over [:data:`ERROR_FROM`, ``stretch_max``] (rms and max, %)."""

    mu_kPa: float
    k2: float
    k3: float
    stretch_max: float
    rms_pct: float
    max_pct: float
    points: int

    def stress_kPa(self, stretch: np.ndarray | float) -> np.ndarray:
        """The law's uniaxial engineering stress, kPa."""
        return uniaxial_stress_kPa(stretch, self.mu_kPa, self.k2, self.k3)


def uniaxial_stress_kPa(stretch: np.ndarray | float, mu_kPa: float, k2: float, k3: float) -> np.ndarray:
    """Engineering (nominal) stress of the incompressible Yeoh law in uniaxial tension or compression, kPa."""
    lam = np.asarray(stretch, dtype=float)
    s = lam * lam + 2.0 / lam - 3.0
    return mu_kPa * (lam - lam ** -2) * (1.0 + 2.0 * k2 * s + 3.0 * k3 * s * s)


def fit_yeoh(stretch: np.ndarray, stress_kPa: np.ndarray, stretch_max: float = FIT_STRETCH,
             floor: float = FLOOR) -> YeohFit:
    """The Yeoh law with non-negative coefficients that fits the uniaxial test (``stretch``, engineering
    ``stress_kPa``) over stretches up to ``stretch_max`` (module doc)."""
    from scipy.optimize import nnls  # lazy: scipy is slow to import and only the fits need it

    lam = np.asarray(stretch, dtype=float)
    p = np.asarray(stress_kPa, dtype=float)
    used = (lam > 1.0) & (lam <= stretch_max) & np.isfinite(p)
    if np.count_nonzero(used) < 4:
        raise ValueError(f"need at least 4 points between stretch 1 and {stretch_max:g} to fit; got "
                         f"{np.count_nonzero(used)}")
    lam, p = lam[used], p[used]
    s = lam * lam + 2.0 / lam - 3.0
    g = lam - lam ** -2
    a = np.stack([g, 2.0 * g * s, 3.0 * g * s * s], axis=1)  # P = a @ (mu, mu k2, mu k3)
    w = 1.0 / np.maximum(p, floor * float(p.max()))
    coef, _ = nnls(a * w[:, None], p * w)
    mu = float(coef[0])
    if not mu > 0.0:
        raise ValueError("the fit found no positive shear modulus: the data do not rise with stretch")
    k2, k3 = float(coef[1]) / mu, float(coef[2]) / mu
    stated = lam >= ERROR_FROM
    rel = np.abs(a[stated] @ coef - p[stated]) / p[stated]
    rms, worst = (float(np.sqrt(np.mean(rel * rel))), float(rel.max())) if rel.size else (math.nan, math.nan)
    return YeohFit(mu, k2, k3, float(stretch_max), 100.0 * rms, 100.0 * worst, int(lam.size))


def read_tensile_csv(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(stretch, engineering stress in kPa) from a Soft Robotics Materials Database tensile test: semicolon-separated,
    a block of ``PARAMETER;INFO`` lines, then a header row starting ``Time (s)`` naming ``Engineering Strain`` and
    ``Engineering Stress (MPa)``."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.startswith("Time"))
    except StopIteration:
        raise ValueError(f"{path}: no header row starting 'Time'") from None
    header = lines[start].split(";")
    strain_col, stress_col = header.index("Engineering Strain"), header.index("Engineering Stress (MPa)")
    rows = [line.split(";") for line in lines[start + 1:] if line.strip()]
    strain = np.array([float(r[strain_col]) for r in rows])
    stress = np.array([float(r[stress_col]) for r in rows]) * 1000.0
    return 1.0 + strain, stress
