"""The weight plan a build ships (``calibration/weigh_plan.json``, format ``magfab-weigh-plan/1``, docs/bundle.md
section 1b): the weighings ``magfab-readout weigh`` walks the bench through, in the weight jig's coins.

Each step is a stand angle and a number of coins, with how many go in each of the cap's pockets (equal stacks in
each opposite pair, :func:`magfab.jig.coin_layout`); the mass on the tip is the cap's, which the bench weighs, plus
the coins'. The plan is :meth:`magfab.jig.Jig.plan` for the softest skin of the material band with the heaviest cap a
print may make, so it stays inside the range of every skin and cap (a stiffer skin is weighed over less of its
range: the fit's shape terms carry the rest, docs/models.md M25). ``first`` names its two steps that come first on
the two-stage bench: their fit gives the skin's stiffness, and :func:`adapted_plan` the plan for it (``magfab
weigh-plan``), which weighs a stiff skin over its own range. ``reskin`` names the three steps a new skin on a
calibrated board takes (:func:`magfab.models.weight_plan.reskin_plan`). ``nominal`` tabulates the nominal sensor's
field against the mass on the tip at each angle (:meth:`magfab.models.weighing.SensorModel.predict` at the priors'
centres, no background): the readout prints it beside each reading, and its simulated board serves it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ScanError
from ..jig import ANGLES_DEG, coin_layout, jig_of
from ..models.weighing import SensorModel, checked_fit
from ..models.weight_plan import STIFFNESS_SIGMAS, first_weighings, reskin_plan, stiffness_of
from ..recipes import catalogue

if TYPE_CHECKING:
    from ..design import Design
    from ..formats.weights_csv import Weighing
    from ..models.predict import Prediction

__all__ = ["FORMAT", "weigh_plan", "plan_document", "adapted_plan", "stiffest_skin", "NOMINAL_POINTS"]

FORMAT = "magfab-weigh-plan/1"
#: Masses the nominal field is tabulated at per angle, from none to a fifth past the plan's heaviest there.
NOMINAL_POINTS = 25


def weigh_plan(design: Design, prediction: Prediction) -> dict[str, Any] | None:
    """The plan a build ships, for the softest skin (safe for every skin), or None for an array.
    :class:`ScanError` (from :func:`magfab.models.weight_plan.weight_plan`) for a design no plan fits, saying why."""
    if design.array is not None:
        return None
    return plan_document(design, prediction)


def plan_document(design: Design, prediction: Prediction, stiffness: float = 1.0,
                  adapted: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The plan's document (module doc) for a skin ``stiffness`` times the softest of the band; ``adapted``: where
    that stiffness comes from (:func:`adapted_plan`), kept in the document."""
    jig = jig_of(design)
    plan = jig.plan(prediction, stiffness=stiffness)
    cap = jig.cap_mass_bound_g()
    pairs = [(m, a) for m, a, _ in plan]
    stiffest = jig.plan(prediction, stiffness=stiffest_skin(prediction))
    model = SensorModel.of(design, prediction)
    theta = np.concatenate([model.prior.mean, np.zeros(3 * len(ANGLES_DEG))])
    nominal = []
    for angle in sorted({a for _, a, _ in plan}):  # a stand the cap alone overloads has no weighings
        top = 1.2 * max(m for m, a, _ in plan if a == angle)
        masses = np.linspace(0.0, top, NOMINAL_POINTS)
        field = model.predict(theta, masses, np.full_like(masses, angle), ANGLES_DEG)
        ok = np.isfinite(field).all(axis=1)  # past the normal curve's end there is no field to serve
        nominal.append({"angle_deg": angle, "mass_g": [round(float(m), 4) for m in masses[ok]],
                        "field_uT": [[round(float(v), 3) for v in row] for row in field[ok]]})
    coin = catalogue("bench")["weigh-coin"]
    doc = {
        "format": FORMAT,
        "spec": design.spec.name,
        "coin": {"name": coin.name, "mass_g": jig.coin_g, "diameter_mm": coin["diameter_mm"].nominal,
                 "source": coin["mass_g"].source},
        "pockets": jig.pockets,
        "cap_mass_bound_g": round(cap, 3),
        "coins_most": max(n for plan_ in (plan, stiffest) for _, _, n in plan_),
        "stands_deg": list(ANGLES_DEG),
        # per stand, the most coins any skin's plan puts there (the stiffest skin's): a skin's plan stays within it
        "stand_coins_most": [max((n for plan_ in (plan, stiffest) for _, a, n in plan_ if a == angle), default=0)
                             for angle in ANGLES_DEG],
        "stiffness": round(stiffness, 4),
        "steps": [{"angle_deg": a, "coins": n, "layout": coin_layout(n, jig.pockets),
                   "moment_arm_mm": round(jig.moment_arm_mm(n), 3)} for _, a, n in plan],
        "first": [pairs.index(p) for p in first_weighings(pairs)],
        "reskin": [pairs.index(p) for p in reskin_plan(pairs)],
        "nominal": nominal,
    }
    if adapted is not None:
        doc["adapted"] = dict(adapted)
    return doc


def stiffest_skin(prediction: Prediction) -> float:
    """The material band's stiffest skin over its softest (the most coins any skin's plan takes is its plan's)."""
    return float(prediction.curves["stiff"].mu_kPa) / float(prediction.curves["soft"].mu_kPa)


def adapted_plan(design: Design, prediction: Prediction, weighings: Sequence[Weighing], source: str,
                 sha256: str) -> dict[str, Any]:
    """The plan for the skin the shipped plan's first two weighings (``weighings``, from the file ``source``) show:
    the model fitted to them (:func:`magfab.models.weighing.checked_fit`, with its refusals), the plan made for the
    stiffness :func:`magfab.models.weight_plan.stiffness_of` takes from the fit (no stiffer than the band's
    stiffest). :class:`ScanError` for weighings that are not the first two: flat, the cap alone and the heaviest of
    the shipped plan's flat loads or lighter."""
    jig = jig_of(design)
    cap = jig.cap_mass_bound_g()
    coins_g = max(m for m, a, _ in jig.plan(prediction) if a == 0.0) - cap  # the shipped plan's heaviest flat coins
    loads = {round(w.mass_g, 3) for w in weighings}
    tilted = [w for w in weighings if w.angle_deg != 0.0]
    # the cap is the lightest load (weigh takes a cap up to twice its printed bound); the coins on it, the rest
    if (tilted or len(loads) < 2 or min(loads) > 2.0 * cap
            or max(loads) - min(loads) > coins_g + 0.5 * jig.coin_g):
        raise ScanError(f"{source}: {len(weighings)} weighings of {len(loads)} distinct masses, {len(tilted)} of them "
                        f"tilted, {min(loads):g} to {max(loads):g} g: the plan's first weighings are flat, the cap "
                        f"alone (at most {2.0 * cap:.1f} g) and with up to {coins_g:.1f} g of coins: "
                        "magfab-readout weigh FIRST.csv --first")
    model = SensorModel.of(design, prediction)
    fit = checked_fit(model, weighings, source=source)
    stiffness = min(stiffness_of(fit, model, prediction), stiffest_skin(prediction))  # no stiffer than the band
    named = fit.named()["mu_ratio"]
    return plan_document(design, prediction, stiffness, {
        "weighings": source, "weighings_sha256": sha256,
        "mu_ratio": {"value": round(named["value"], 4), "sd": round(named["sd"], 4)},
        "note": f"the skin's shear modulus fitted to the first weighings, over the design's nominal; the plan is made "
                f"for {STIFFNESS_SIGMAS:g} posterior sigmas below it (docs/models.md M25)"})
