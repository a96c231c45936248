"""The weight plan a build ships (``calibration/weigh_plan.json``, format ``magfab-weigh-plan/1``, docs/bundle.md
section 1b): the weighings ``magfab-readout weigh`` walks the bench through, in the weight jig's coins.

Each step is a stand angle and a number of coins, with how many go in each of the cap's pockets (equal stacks in
each opposite pair, :func:`magfab.jig.coin_layout`); the mass on the tip is the cap's, which the bench weighs, plus
the coins'. The plan is :meth:`magfab.jig.Jig.plan` for the softest skin of the material band with the heaviest cap a
print may make, so it stays inside the range of every skin and cap (a stiffer skin is weighed over less of its
range: the fit's shape terms carry the rest, docs/models.md M25). ``reskin`` names the three steps a new skin on a
calibrated board takes (:func:`magfab.models.weighing.reskin_plan`). ``nominal`` tabulates the nominal sensor's
field against the mass on the tip at each angle (:meth:`magfab.models.weighing.SensorModel.predict` at the priors'
centres, no background): the readout prints it beside each reading, and its simulated board serves it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..jig import ANGLES_DEG, coin_layout, jig_of
from ..models.weighing import SensorModel, reskin_plan
from ..recipes import catalogue

if TYPE_CHECKING:
    from ..design import Design
    from ..models.predict import Prediction

__all__ = ["FORMAT", "weigh_plan", "NOMINAL_POINTS"]

FORMAT = "magfab-weigh-plan/1"
#: Masses the nominal field is tabulated at per angle, from none to a fifth past the plan's heaviest there.
NOMINAL_POINTS = 25


def weigh_plan(design: Design, prediction: Prediction) -> dict[str, Any] | None:
    """The plan for a single taxel, or None for an array. :class:`ScanError` (from
    :func:`magfab.models.weighing.weight_plan`) for a design no plan fits, saying why."""
    if design.array is not None:
        return None
    jig = jig_of(design)
    plan = jig.plan(prediction)
    cap = jig.cap_mass_bound_g()
    pairs = [(m, a) for m, a, _ in plan]
    reskin = [pairs.index(p) for p in reskin_plan(pairs)]
    coin = catalogue("bench")["weigh-coin"]
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
    return {
        "format": FORMAT,
        "spec": design.spec.name,
        "coin": {"name": coin.name, "mass_g": jig.coin_g, "diameter_mm": coin["diameter_mm"].nominal,
                 "source": coin["mass_g"].source},
        "pockets": jig.pockets,
        "cap_mass_bound_g": round(cap, 3),
        "steps": [{"angle_deg": a, "coins": n, "layout": coin_layout(n, jig.pockets),
                   "moment_arm_mm": round(jig.moment_arm_mm(n), 3)} for _, a, n in plan],
        "reskin": reskin,
        "nominal": nominal,
    }
