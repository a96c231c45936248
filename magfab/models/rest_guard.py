"""A scan's field at rest, and the guard that refuses a scan whose rest field is not this design's.

A scan of the wrong sensor (another design's build, another taxel of an array), of the wrong build, or of a
misassembled sensor (magnet of another grade, not pushed home, upside down) reads a field at rest outside the
design's acceptance band (``calibration/acceptance.json``, :mod:`magfab.models.acceptance`), which already holds
every tolerance of a correct build, the 15-30 C bench and the Earth's field. :func:`check_rest_band` refuses it
before any fit, so nothing is written (docs/bundle.md section 1).

**The rest rows.** A calibration scan starts (and, for a raster, passes) with nothing on the tip: the rows whose
reference force is zero. A reference log is tared but noisy, and may carry a constant offset; so the rest rows
are those whose force magnitude |F| lies within :data:`REST_FRACTION` of the scan's largest |F| (and at least
:data:`REST_FLOOR_N`) of the scan's least |F|. A simulated raster has exactly one such row (the axis, before any
indentation: its neighbours at rest carry a lateral force); a recording merged with a reference log has the
second or so before the first press. A scan that is never unloaded has its least-loaded rows judged instead,
whose field lies above rest (pressing raises |Bz|): such a scan may be refused as too strong.

**Temperature.** The band holds the bench's ambient range (``Tolerances.ambient_C``). A scan with a
``temperature_C`` column taken outside it has its rest field brought back to the nearest end of that range by the
magnet grade's remanence coefficient before it is compared.

**An array's taxel.** Its chip also reads the neighbours' field at rest (``offset_uT``, calibration/array.json)
and its magnet may be flipped (``polarity``): the band applies to polarity x (B - offset).

Units: field uT, force N, temperature degC.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ScanError

if TYPE_CHECKING:
    from ..formats.scan_csv import Scan
    from .calibration import Calibration

__all__ = ["REST_FRACTION", "REST_FLOOR_N", "AMBIENT_C", "RestField", "rest_rows", "rest_field", "rest_band",
           "check_rest_band", "sensitivity_uT_per_N", "calibrated_range_N"]

#: A row is at rest when its |F| is within this fraction of the scan's largest |F| of the least |F| ...
REST_FRACTION = 0.01
#: ... and never less than this, N (a scan with almost no load).
REST_FLOOR_N = 1e-3
#: The bench's ambient band the acceptance band holds, degC (magfab.models.acceptance.Tolerances.ambient_C).
AMBIENT_C = (15.0, 30.0)
#: The field step of the sensitivity's difference quotient, as a fraction of the calibration's scaled span.
SENSITIVITY_STEP = 0.01


@dataclass(frozen=True)
class RestField:
    """The field at rest of a scan: ``B_uT`` (3,) the mean of its ``rows`` rest rows, as the chip read them;
    ``temperature_C`` their mean chip temperature (None without the column); ``force_N`` their mean |F|."""

    B_uT: np.ndarray
    rows: int
    temperature_C: float | None
    force_N: float


def rest_rows(scan: Scan) -> np.ndarray:
    """Which rows of ``scan`` are at rest (module doc), (N,) bool; at least one."""
    if scan.F_N is None:
        raise ScanError(f"scan {scan.source}: no force columns, so no rows can be told to be at rest")
    load = np.linalg.norm(scan.F_N, axis=1)
    return load <= float(load.min()) + max(REST_FRACTION * float(load.max()), REST_FLOOR_N)


def rest_field(scan: Scan) -> RestField:
    """The scan's field at rest (:class:`RestField`)."""
    quiet = rest_rows(scan)
    assert scan.F_N is not None  # rest_rows refused a scan without forces
    temperature = None if scan.temperature_C is None else float(np.mean(scan.temperature_C[quiet]))
    return RestField(scan.B_uT[quiet].mean(axis=0), int(quiet.sum()), temperature,
                     float(np.mean(np.linalg.norm(scan.F_N[quiet], axis=1))))


def rest_band(bands: Mapping[str, Any], rest: RestField, *, lsb_z_uT: float = 0.0,
              remanence_per_C: float = 0.0) -> tuple[float, float]:
    """The band (low, high) of Bz at rest, uT, a correct sensor's rest rows fall in: acceptance.json's
    ``rest.Bz_uT`` widened by its measurement allowance (``measurement.allowance_sigmas`` x the noise of the mean
    of ``rest.rows`` samples, plus half a count of ``lsb_z_uT``) and, for a scan taken outside :data:`AMBIENT_C`,
    moved by the remanence's change (``remanence_per_C``, 1/degC: negative for NdFeB) from the nearest end."""
    band = bands["rest"]["Bz_uT"]
    low, high = float(band["min"]), float(band["max"])
    measurement = bands.get("measurement", {})
    noise = float(measurement.get("noise_z_uT", 0.0)) * float(measurement.get("allowance_sigmas", 4.0))
    allow = noise / math.sqrt(rest.rows) + lsb_z_uT / 2.0
    if rest.temperature_C is not None:
        t = rest.temperature_C
        gain = 1.0 + remanence_per_C * (t - min(max(t, AMBIENT_C[0]), AMBIENT_C[1]))
        low, high = sorted((low * gain, high * gain))
    return low - allow, high + allow


def check_rest_band(scan: Scan, bands: Mapping[str, Any], *, polarity: int = 1,
                    offset_uT: Sequence[float] = (0.0, 0.0, 0.0), lsb_z_uT: float = 0.0,
                    remanence_per_C: float = 0.0, where: str = "calibration/acceptance.json") -> RestField:
    """``scan``'s :class:`RestField`, or :class:`ScanError` (one line) when its Bz at rest, as ``polarity`` x
    (B - ``offset_uT``), lies outside :func:`rest_band`: the wrong sensor, the wrong build, or a misassembled one.
    ``where`` names the band's source in the message."""
    rest = rest_field(scan)
    bz = polarity * float(rest.B_uT[2] - float(offset_uT[2]))
    low, high = rest_band(bands, rest, lsb_z_uT=lsb_z_uT, remanence_per_C=remanence_per_C)
    if low <= bz <= high:
        return rest
    at = "" if rest.temperature_C is None else f" at {rest.temperature_C:.1f} C"
    what = ("upside down (the band's magnitude, negated)" if low <= -bz <= high else
            "stronger than" if bz > high else "weaker than")
    neighbours = "" if not any(offset_uT) else " (its neighbours' field removed)"
    raise ScanError(
        f"scan {scan.source}: its field at rest{neighbours}, Bz = {bz:.0f} uT{at} (the mean of its {rest.rows} "
        f"row(s) at the least force), is {what} this design's acceptance band {low:.0f} .. {high:.0f} uT ({where}): "
        "the wrong sensor, the wrong build, or a misassembled sensor (magnet grade, seating, polarity); calibrate "
        "with a scan of a sensor built to this design, or check the sensor with magfab-readout check")


def sensitivity_uT_per_N(calibration: Calibration, rest_B_uT: Sequence[float],
                         temperature_C: float | None = None) -> tuple[float, float]:
    """(normal, shear) sensitivity at rest, uT/N: the field change per newton the fitted calibration gives at the
    rest field, dBz/dFz and dBr/dFr, each as the forward difference quotient over a field step of
    :data:`SENSITIVITY_STEP` of the calibration's span of Bz (normal) or Br (shear), taken from the rest field into
    the scanned region (pressing raises |Bz| and shear raises Br). The global polynomial is used (what the
    firmware computes), at the rest temperature. NaN when the force does not change over the step."""
    b0 = calibration.corrected(np.asarray(rest_B_uT, float)[None, :],
                               None if temperature_C is None else [temperature_C])[0]
    scaling = calibration.scaling
    h_z = SENSITIVITY_STEP * 2.0 * float(scaling.bz_scale)
    h_r = SENSITIVITY_STEP * 2.0 * float(scaling.br_scale)
    bz_sign = 1.0 if b0[2] >= 0 else -1.0
    br0 = float(np.hypot(b0[0], b0[1]))
    direction = np.array([1.0, 0.0]) if br0 == 0.0 else b0[:2] / br0
    pressed = b0 + np.array([0.0, 0.0, bz_sign * h_z])
    sheared = np.array([*(b0[:2] + h_r * direction), b0[2]])
    points = np.array([b0, pressed, sheared])
    force = calibration.model(points, "poly")
    d_fz, d_fr = float(force[1, 0] - force[0, 0]), float(force[2, 1] - force[0, 1])
    normal = h_z / abs(d_fz) if d_fz else math.nan
    shear = h_r / abs(d_fr) if d_fr else math.nan
    return normal, shear


def calibrated_range_N(scan: Scan, calibration: Calibration) -> tuple[float, float]:
    """(normal, shear) range the calibration covers, N: the largest Fz and the largest Fr of the scan's rows whose
    field lies inside the calibration's valid region (what the readout reports without an out-of-region flag)."""
    assert scan.F_N is not None
    b = calibration.corrected(scan.B_uT, scan.temperature_C)
    inside = calibration.region.contains(b[:, 2], np.hypot(b[:, 0], b[:, 1]))
    if not inside.any():
        return 0.0, 0.0
    return float(np.max(scan.F_N[inside, 2])), float(np.max(scan.Fr_N[inside]))
