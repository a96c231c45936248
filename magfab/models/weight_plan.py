"""The weight plan: which weighings to make, for a skin of a given stiffness (docs/models.md M25).

A plan is a list of (mass on the tip in g, stand angle in degrees): at each of :data:`ANGLES_DEG` the cap alone and
up to three loads on it, each within :data:`PLAN_RANGE_FRACTION` of the skin's predicted ranges. The build ships the
plan for the softest skin of the material band, which is safe for every skin. The two-stage bench weighs the softest
plan's first two flat loads (:func:`first_weighings`), fits them, and walks the plan for the stiffness they give
(:func:`stiffness_of`), so a stiff skin is weighed over its own range.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from ..errors import ScanError
from ..formats.weights_csv import MIN_WEIGHINGS
from ..units import G0

if TYPE_CHECKING:
    from .predict import Prediction
    from .weighing import SensorModel, WeightFit

__all__ = ["weight_plan", "first_weighings", "stiffness_of", "over_softest", "reskin_plan", "ANGLES_DEG", "MIN_FIRST",
           "MIN_TILT_DEG", "RESKIN_MIN", "STANDARD_WEIGHTS_G", "PLAN_RANGE_FRACTION", "STIFFNESS_SIGMAS"]

#: Fewest weighings a first calibration takes (a new skin with the magnet's parameters kept takes
#: :data:`RESKIN_MIN`).
MIN_FIRST = 6
#: Fewest distinct loads a new skin takes: the cap alone flat, the heaviest weight flat and at the steepest angle
#: (:func:`reskin_plan`), for a shear modulus, a rest distance and a background per stand; the fewest rows a
#: weighings file holds.
RESKIN_MIN = MIN_WEIGHINGS
#: The least stand angle a first calibration's tilted weighings need, degrees (our choice: half the plan's least
#: tilt). Below it a load's shear part (sin 10 deg = 17 % of it) tells the shear stiffness too little: on eight
#: centred MagOne sensors the stated shear bound was 1.04-1.12x the plan's at 10 deg, 1.1-1.5x at 2, 1.5-4.3x at 0.5.
MIN_TILT_DEG = 10.0
#: Standard weights (g) a bench has: the usual 1-2-5 series of a calibration weight set (OIML R 111 nominal values).
STANDARD_WEIGHTS_G = (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0)
#: The weights of a plan stay at or below this fraction of the predicted normal range.
PLAN_RANGE_FRACTION = 0.9
#: How many posterior sigmas below the first two weighings' fitted shear modulus the stiffness a plan is made for
#: sits (:func:`stiffness_of`). Over 80 drawn MagOne sensors (tilted and centred, seed 7) the two flat weighings' fit
#: was at most 1.09 of its sigma (about 0.09 in the log) above the truth; with the plan's 90 % of the range, a skin is
#: pressed past its range only by a fit more than 2.6 sigma high.
STIFFNESS_SIGMAS = 1.5
#: The stand's angles, degrees.
ANGLES_DEG = (0.0, 20.0, 40.0)


def weight_plan(prediction: Prediction, cap_g: float = 0.0, stiffness: float = 1.0, *,
                loads_g: Sequence[float] = STANDARD_WEIGHTS_G, tilted_max_g: float = math.inf
                ) -> list[tuple[float, float]]:
    """The weighings to make, as (mass on the tip in g, stand angle): at each of :data:`ANGLES_DEG` the cap alone and
    three of the loads ``loads_g`` put on it (the standard 1-2-5 weights, or the weight jig's coin pairs,
    :func:`magfab.jig.Jig.loads_g`): the heaviest whose load stays within :data:`PLAN_RANGE_FRACTION` of the predicted
    normal range (its normal part) and of the predicted shear range (its shear part), then the heaviest lighter
    than it within half that, and within a quarter (fewer where fewer fit). A tilted stand carries at most
    ``tilted_max_g`` (what stays in the jig's pockets). The ranges are the softest material's, times ``stiffness``:
    the skin's shear modulus over the softest (:func:`first_weighings` and :func:`stiffness_of` find it, so a stiff
    skin is weighed over its whole range, not a soft one's). A stand on which the cap alone pushes past the range
    has no weighings. ScanError for a design whose range the cap and the lightest load already pass, or whose shear
    range the cap alone passes on every stand tilted :data:`MIN_TILT_DEG` or more, or whose ranges leave fewer than
    :data:`MIN_FIRST` weighings."""
    # the skin's ranges: the softest material's, times its stiffness
    normal_N, shear_N = (max(stiffness, 1.0) * r for r in (prediction.normal.range_N, prediction.shear.range_N))
    lightest = min(loads_g) + cap_g
    if lightest * G0 / 1000.0 > PLAN_RANGE_FRACTION * normal_N:
        raise ScanError(f"the cap with the lightest load ({lightest:g} g, {lightest * G0:.3g} mN) is past "
                        f"{PLAN_RANGE_FRACTION:.0%} of this design's normal range ({1000.0 * normal_N:.3g} mN): no "
                        "weight plan fits it; calibrate it from a scan")
    out = []
    for angle in ANGLES_DEG:
        a = math.radians(angle)
        limit_N = PLAN_RANGE_FRACTION * min(normal_N / math.cos(a), shear_N / math.sin(a) if angle > 0 else math.inf)
        if cap_g * G0 / 1000.0 > limit_N:  # the cap alone pushes past the range here: no weighing on this stand
            continue
        # the fractions of what the loads reach: the range, or the heaviest load the jig carries steadily there
        limit_g = min(limit_N * 1000.0 / G0 - cap_g, tilted_max_g if angle > 0 else max(loads_g))
        picked: list[float] = []
        for fraction in (1.0, 0.5, 0.25):
            below = [w for w in loads_g if w <= limit_g * fraction and (not picked or w < picked[-1])]
            if below:
                picked.append(max(below))
        out += [(cap_g + w, angle) for w in (0.0, *sorted(picked))]
    if not any(angle >= MIN_TILT_DEG for _, angle in out):
        raise ScanError(f"the cap alone ({cap_g:g} g) pushes past {PLAN_RANGE_FRACTION:.0%} of this design's shear "
                        f"range ({1000.0 * shear_N:.3g} mN) on every tilted stand: no weight plan tells its shear; "
                        "calibrate it from a scan")
    if len(out) < MIN_FIRST:
        raise ScanError(f"only {len(out)} weighings fit this design's ranges (normal {1000.0 * normal_N:.3g} mN, shear "
                        f"{1000.0 * shear_N:.3g} mN) with the cap and its loads, fewer than the {MIN_FIRST} a first "
                        "weight calibration needs; calibrate it from a scan")
    return out


def first_weighings(plan: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """The two weighings that come first, flat: the cap alone and the heaviest load of ``plan``, the plan for the
    softest skin (:func:`weight_plan` at stiffness 1, safe for any skin); their fit gives the skin's stiffness
    (:func:`stiffness_of`) and with it the rest of the plan."""
    flat = [p for p in plan if p[1] == 0.0]
    return [min(flat), max(flat)]


def stiffness_of(fit: WeightFit, model: SensorModel, prediction: Prediction) -> float:
    """The fitted skin's shear modulus over the softest of the material band (at least 1), taken
    :data:`STIFFNESS_SIGMAS` posterior sigmas below the fit, so that a plan made for it stays inside the skin's
    range."""
    low = float(fit.theta[0]) - STIFFNESS_SIGMAS * math.sqrt(max(float(fit.covariance[0, 0]), 0.0))
    return max(1.0, over_softest(low, prediction))


def over_softest(log_mu: float, prediction: Prediction) -> float:
    """A skin's shear modulus over the softest of the material band, from its log ratio to the nominal (the fit's
    ``log_mu``)."""
    return math.exp(log_mu) * float(prediction.curves["nominal"].mu_kPa) / float(prediction.curves["soft"].mu_kPa)


def reskin_plan(plan: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """A new skin's three weighings from a plan: the cap alone flat, the heaviest weight flat and the heaviest at the
    steepest angle."""
    flat = [p for p in plan if p[1] == 0.0]
    steep = [p for p in plan if p[1] == max(q[1] for q in plan)]
    return [min(flat), max(flat), max(steep)]
