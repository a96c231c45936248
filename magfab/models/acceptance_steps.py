"""The acceptance test's two drift steps: turning the sensor over, and warming it.

**Rotation.** With nothing touching the tip, the whole sensor (board and fingertip) is turned upside down: 180 deg
about a horizontal axis. Two things change the field at the chip:

* the Earth's field in the chip's axes: a turn by 180 deg about an axis h maps E to 2 (E.h) h - E, so the field
  changes by twice E's part across h, at most 2 |E| in magnitude, |E| the spec's stated place or the recipe band's
  strongest (:func:`magfab.models.drift.earth_field_G`, recipes/bench.toml). With a reference chip the firmware
  subtracts what both chips read, and what is left is 2 |E| over the predicted uniform rejection
  (predictions.json ``reference.rejection.uniform``);
* the fingertip's own weight: upright it presses the magnet towards the chip, turned over it pulls it away. The
  load is the magnet's weight plus half the silicone's (a column loaded by its own weight moves its top as far as
  half that weight on the top would), rho g V each (recipes/assembly.toml magnet density, the silicone's from
  recipes/materials.toml or the spec), and turning over changes it by twice that; the field it is worth is that
  change times the steepest rise of Bz per newton of the weight table (``weight.table.delta_Bz_max_uT`` over its
  first step: the softest material and the strongest corner). The weight table loads the tip, not the magnet
  inside it, which is what the magnet's own weight does: near the top, where magfab puts the magnet, the two are
  close; the band takes the table's steepest slope for it.

So the band on |dB| (vector) is earth_change + self_weight_change, and the check widens it by the noise of the
difference of two means and a count on each axis. A larger change means the magnet moved: loose in its pocket
(not glued, the pocket too large) it shifts under its own weight, or steel or magnetised parts near the sensor
turned with it. ``gradient_uT_per_mm`` (dBz/dz at rest, predictions.json) turns a change into magnet travel. The
force the calibration reads for the change is reported against the drift budget's (``drift.rotation_band``'s
turned-over figure in the strongest field, scaled by the field change: the inverse is near linear over it).

**Warm-up.** With nothing touching the tip the chip is warmed by at least :data:`MIN_WARMUP_C` (a hand on the
board, or the board's own warm-up after power-up). The rest force the firmware sends moves by the drift
budget's compensated figure per degree (predictions.json ``drift.temperature.per_C_mN.normal_rest``: ``with`` for
the recipe coefficients, ``fitted`` when the calibration's thermal coefficients were fitted to a scan over
temperature, ``without`` for a calibration without them) times the temperature change, plus the noise of the
difference of two means (the resolution, which is the force noise at rest, x sqrt(2 / samples) x the
allowance sigmas). The budget's figures are in force through its worst-case calibration (the stiff material and
the weakest magnet: the most force per field); the sensor's own calibration is known when the check runs, so the
check scales both terms by its dFz/dBz at the rest reading over the budget's (``channel_mN_per_uT``, the budget's
magnet part at rest over the field change it makes): the same field drift, read through this sensor's calibration.
Without that the band (6.0 mN/C for MagOne with the recipe's coefficients) would hold a nominal MagOne with no
correction at all (4 mN/C through its calibration). The figures are worst cases over the coefficients' bands
(drift.py), so a correct correction passes with any sintered NdFeB in the recipe's spread; a missing or wrong correction
moves the rest force by about the uncompensated figure instead, and a magnet of another material by its own
coefficient's.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ..units import G0, UT_PER_GAUSS
from .calibration_thermal import MIN_SPAN_C
from .drift import earth_field_G

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["MIN_WARMUP_C", "G0", "self_weight_N", "rotation_section", "warmup_section"]

#: Least warming of the chip, C, for the warm-up step: the span calibration_thermal asks of a scan before it fits
#: a coefficient (a few degrees, twice the chip's temperature noise band).
MIN_WARMUP_C = MIN_SPAN_C


def _r(x: float, digits: int = 3) -> float:
    return round(float(x), digits) + 0.0


def self_weight_N(design: Design) -> tuple[float, float]:
    """(the magnet's weight, the silicone's), N: rho g V with the grade's density (recipes/magnets.toml) and the
    silicone's (the spec's override or recipes/materials.toml)."""
    magnet = design.magnet_grade.density_g_cm3.nominal
    silicone = design.spec.fabrication.density_g_cm3
    if silicone is None:
        silicone = design.material.density_g_cm3.nominal
    # g/cm^3 x mm^3 = 1e-3 g; x 1e-3 kg/g x g0
    return (magnet * design.magnet_volume_mm3 * 1e-6 * G0, float(silicone) * design.elastomer_volume_mm3 * 1e-6 * G0)


def _steepest_rise(weight: Mapping[str, Any]) -> float:
    """The largest rise of Bz per newton over the weight table's first step, uT/N."""
    table = weight["table"]
    force, rise = table["force_N"], table["delta_Bz_max_uT"]
    return (rise[1] - rise[0]) / (force[1] - force[0])


def rotation_section(design: Design, data: Mapping[str, Any], weight: Mapping[str, Any]) -> dict[str, Any]:
    """acceptance.json's ``rotation`` (module doc): the band on the field change, uT, and what it is made of."""
    low, stated, high = earth_field_G(design)
    reference = data.get("reference")
    rejection = float(reference["rejection"]["uniform"]) if reference else None
    earth_change = 2.0 * stated * UT_PER_GAUSS / (rejection or 1.0)
    magnet_N, silicone_N = self_weight_N(design)
    load = magnet_N + silicone_N / 2.0
    slope = _steepest_rise(weight)
    weight_change = 2.0 * load * slope
    drift = data.get("drift")
    predicted = None
    if drift is not None:  # the budget's turned-over figure in the strongest field, scaled to this change
        strongest = drift["rotation_band"][1]
        predicted = _r(abs(float(strongest["normal_rest_mN"])) * earth_change
                       / (float(strongest["field_G"]) * UT_PER_GAUSS))
    return {
        "turn_deg": 180.0,
        "earth_field_uT": _r(stated * UT_PER_GAUSS),
        "earth_field_band_uT": [_r(low * UT_PER_GAUSS), _r(high * UT_PER_GAUSS)],
        "reference_rejection": rejection,
        "earth_change_uT": _r(earth_change),
        "self_weight_N": {"magnet": _r(magnet_N, 6), "silicone": _r(silicone_N, 6), "load": _r(load, 6)},
        "steepest_rise_uT_per_N": _r(slope),
        "self_weight_change_uT": _r(weight_change),
        "band_uT": _r(earth_change + weight_change),
        "gradient_uT_per_mm": _r(abs(float(data["field"]["dBz_dz_rest_G_per_mm"])) * UT_PER_GAUSS),
        "predicted_normal_rest_mN": predicted,
        "self_weight_mN": _r(2.0 * load * 1000.0),
        "note": "turned upside down with nothing touching the tip: |dB| <= band_uT (the Earth's field turned over"
                + (", the reference subtracted" if rejection else "") + ", plus the fingertip's own weight "
                "reversed) + the noise of the difference and a count per axis",
    }


def warmup_section(data: Mapping[str, Any]) -> dict[str, Any] | None:
    """acceptance.json's ``warmup`` (module doc), or None without a drift budget."""
    drift = data.get("drift")
    if drift is None:
        return None
    temperature = drift["temperature"]
    per_C = temperature["per_C_mN"]["normal_rest"]
    # the budget's calibration at rest, mN per uT: the magnet's part of the uncompensated error over its field
    slope = float(temperature["per_C_parts_normal_rest_mN"]["magnet"]) / (
        float(temperature["per_C_parts_normal_rest_field_G"]["magnet"]) * UT_PER_GAUSS)
    return {
        "min_change_C": MIN_WARMUP_C,
        "per_C_mN": {case: _r(abs(float(v)), 4) for case, v in per_C.items()},
        "noise_mN": _r(float(drift["resolution_mN"]["normal"]), 4),
        "channel_mN_per_uT": _r(abs(slope), 6),
        "magnet_pct_per_C": float(drift["coefficients"]["magnet_pct_per_C"]),
        "note": "warmed by at least min_change_C with nothing touching the tip: |dFz| <= (per_C_mN[case] x |dT| + "
                "allowance_sigmas x noise_mN x sqrt(2 / samples)) x k, k = the sensor's calibration's dFz/dBz at rest "
                "over channel_mN_per_uT (the budget's worst-case calibration); case: fitted when the calibration's "
                "thermal coefficients were fitted, with for the recipe's, without for a calibration without them",
    }
