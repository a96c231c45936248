"""The weighings CSV (docs/bundle.md section 1b): the chip's mean field under known weights, which `magfab calibrate
--weights` fits (:mod:`magfab.models.weighing`).

One row per weighing: ``mass_g`` (everything resting on the tip: the jig's cap and the weights on it), ``angle_deg``
(the stand's angle; 0 is flat), the chip's mean field ``Bx_uT, By_uT, Bz_uT`` over ``samples`` readings and their
standard deviation ``Bx_sd_uT, By_sd_uT, Bz_sd_uT``; columns in any order, others ignored, ``#`` lines are comments.
:func:`read_weights_csv` is the one reader: every malformed file gives one :class:`~magfab.errors.ScanError` line
naming the file, the line and the column.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import ScanError
from .scan_csv import _header, _lines, _number, _require

__all__ = ["Weighing", "WEIGHT_COLUMNS", "BANDS", "MIN_WEIGHINGS", "MAX_WEIGHINGS", "read_weights_csv", "weights_csv"]

WEIGHT_COLUMNS = ("mass_g", "angle_deg", "Bx_uT", "By_uT", "Bz_uT", "Bx_sd_uT", "By_sd_uT", "Bz_sd_uT", "samples")
#: Plausible band of each column (low, high, unit): the mass up to 10 kg (far past any tip's range), the stand's
#: angle 0-80 degrees (at 90 the weight would hang off the tip), the field as a scan's, a spread below 10 mT and at
#: least one reading.
BANDS = {
    "mass_g": (0.0, 1e4, "g"), "angle_deg": (0.0, 80.0, "deg"),
    "Bx_uT": (-1e6, 1e6, "uT"), "By_uT": (-1e6, 1e6, "uT"), "Bz_uT": (-1e6, 1e6, "uT"),
    "Bx_sd_uT": (0.0, 1e4, "uT"), "By_sd_uT": (0.0, 1e4, "uT"), "Bz_sd_uT": (0.0, 1e4, "uT"),
    "samples": (1.0, 1e7, "readings"),
}
#: Fewest weighings a fit takes (a re-skin's three; a first calibration wants twelve, on three angles).
MIN_WEIGHINGS = 3
#: Most weighings a file may hold (each costs a model evaluation in every step of the fit).
MAX_WEIGHINGS = 500


@dataclass(frozen=True)
class Weighing:
    """One weighing: ``mass_g`` resting on the tip (the cap included) with the board at ``angle_deg`` on the stand,
    the chip's mean field ``field_uT`` (3,) over ``samples`` readings and their standard deviation ``sd_uT`` (3,)."""

    mass_g: float
    angle_deg: float
    field_uT: tuple[float, float, float]
    sd_uT: tuple[float, float, float]
    samples: int

    @property
    def standard_error_uT(self) -> np.ndarray:
        return np.asarray(self.sd_uT, float) / math.sqrt(max(self.samples, 1))


def read_weights_csv(source: str | os.PathLike[str] | bytes, least: int = MIN_WEIGHINGS) -> list[Weighing]:
    """The weighings of a CSV file (path), CSV text or bytes.

    Raises :class:`ScanError` (one line: file, line, column, what is allowed) for a missing file or column, a value
    that is not an ASCII decimal number or lies outside its column's :data:`BANDS`, a count of samples that is not a
    whole number, a row of the wrong length, or fewer than ``least`` (:data:`MIN_WEIGHINGS`; the two-stage bench's
    first weighings are two) or more than :data:`MAX_WEIGHINGS` rows."""
    lines, name, _ = _lines(source, "weighings CSV")
    hline, names = _header(lines, name)
    _require(names, WEIGHT_COLUMNS, name, hline, "any order; others ignored")
    rows = len(lines) - 1
    if not least <= rows <= MAX_WEIGHINGS:
        what = "a weight calibration takes" if least == MIN_WEIGHINGS else "a skin's plan takes"
        raise ScanError(f"{name}: {rows} weighings; {what} {least} to {MAX_WEIGHINGS} (twelve on three stand angles "
                        "for a first calibration, three for a new skin, two for the plan of a skin)")
    index = {c: names.index(c) for c in WEIGHT_COLUMNS}
    out = []
    for row, (number, text) in enumerate(lines[1:], 1):
        fields = text.split(",")
        if len(fields) != len(names):
            raise ScanError(f"{name}: line {number}: {len(fields)} values, but the header (line {hline}) names "
                            f"{len(names)} columns; every row needs one value per column")
        v = {c: _number(fields[index[c]], name, number, c, row, BANDS[c]) for c in WEIGHT_COLUMNS}
        if v["samples"] != int(v["samples"]):
            raise ScanError(f"{name}: line {number} (row {row}), column 'samples': {v['samples']:g} is not a whole "
                            "number of readings")
        out.append(Weighing(v["mass_g"], v["angle_deg"], (v["Bx_uT"], v["By_uT"], v["Bz_uT"]),
                            (v["Bx_sd_uT"], v["By_sd_uT"], v["Bz_sd_uT"]), int(v["samples"])))
    return out


def weights_csv(weighings: Sequence[Weighing], comments: Sequence[str] = ()) -> str:
    """The CSV text of ``weighings``, ``comments`` as ``#`` lines."""
    lines = [f"# {c}" for c in comments] + [",".join(WEIGHT_COLUMNS)]
    for w in weighings:
        values = [w.mass_g, w.angle_deg, *w.field_uT, *w.sd_uT]
        lines.append(",".join(f"{float(x):.8g}" for x in values) + f",{int(w.samples)}")
    return "\n".join(lines) + "\n"
