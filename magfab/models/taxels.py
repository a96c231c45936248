"""An array's taxels seen by each other's chips: the static field of the neighbours at rest, what the host needs
to remove a moving neighbour (:mod:`magfab.formats.array_json`), and the calibration of each taxel.

Every taxel is the single design's magnet over its own chip (:attr:`magfab.design.Design.taxels`), magnetised
along +z or flipped (``polarity``). A chip reads its own magnet plus every other magnet (exact superposition
of :func:`magfab.models.field.exact`; flipping a magnet negates its field). The host removes the others' field
at rest (``offset_uT``, exact) and, where the crosstalk budget asks, their motion (a dipole at the neighbour's
distance, its travel read from its own chip through the own field's tables): array.json, docs/bundle.md
section 5. Each taxel's calibration is fitted to its scan with the offset removed, so the axisymmetric fit in
(Bz, Br) is not bent by a neighbour's steady lateral field.

Units: lengths mm, fields uT at the API (the field models work in gauss).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..formats import array_json
from ..units import UT_PER_GAUSS
from . import field as fieldmod
from .calibration import fit
from .scan import simulate_scan

if TYPE_CHECKING:
    from ..design import Design
    from ..formats.scan_csv import Scan
    from .predict import Prediction

__all__ = ["ArrayField", "ArrayCalibration", "array_field", "field_at_chips", "simulate_taxel_scan",
           "calibrate_taxels", "compensated", "ARRAY_FORMAT"]

#: Points of the own-field tables along the magnet's travel from rest to d_min.
TABLE_POINTS = 33
#: Points of the own-field tables across the magnet's lateral offset, from 0 to half the elastomer's radius.
LATERAL_POINTS = 13


def _magnet_centres(design: Design) -> np.ndarray:
    """(N, 3) magnet centres at rest, board frame, mm."""
    z = design.z_magnet_low_mm + design.magnet_height_mm / 2.0
    return np.array([[t.x_mm, t.y_mm, z] for t in design.taxels])


def _chips(design: Design) -> np.ndarray:
    """(N, 3) sensing points, board frame, mm."""
    return np.array([[t.x_mm, t.y_mm, design.z_sense_mm] for t in design.taxels])


def field_at_chips(design: Design, centres: np.ndarray | None = None) -> np.ndarray:
    """(N chips, N magnets, 3) field in uT at each chip from each magnet (its polarity applied), the magnets at
    ``centres`` (N, 3) board frame mm (default: at rest)."""
    magnet = fieldmod.Magnet.from_design(design)
    centres = _magnet_centres(design) if centres is None else centres
    chips = _chips(design)
    out = np.zeros((len(chips), len(centres), 3))
    for j, t in enumerate(design.taxels):
        out[:, j, :] = t.polarity * fieldmod.exact(magnet, chips - centres[j]) * UT_PER_GAUSS
    return out


@dataclass(frozen=True)
class ArrayField:
    """The taxels' field on each other's chips, as array.json holds it (module doc; board frame, mm, uT)."""

    chips_mm: np.ndarray  # (N, 3) sensing points
    centres_mm: np.ndarray  # (N, 3) magnet centres at rest
    offset_uT: np.ndarray  # (N, 3) the other magnets' field at each chip at rest
    rest_uT: np.ndarray  # (N, 3) each chip's own magnet at rest
    travel_mm: np.ndarray  # (M,) the magnet's axial travel from rest towards its chip
    own_Bz_uT: np.ndarray  # (M,) the own field's Bz at the chip over that travel, polarity +1
    lateral_mm: np.ndarray  # (K,) the magnet's lateral offset
    own_lateral_uT: np.ndarray  # (M, K, 2) the own field's (Bx, Bz) at the chip, magnet at travel i shifted +x by k
    magnet_mm: tuple[float, float]  # radius, height: the lateral part's distributed dipoles fill this cylinder
    neighbour_uT: np.ndarray  # (N, N, M, 3) change at chip k as magnet j travels (its polarity applied; 0 for k = j)
    moment_uT_mm3: float  # the magnet's dipole moment as mu0 m / 4 pi

    def as_json(self) -> dict[str, object]:
        r = lambda a: np.round(a, 6).tolist()
        return {"chips_mm": r(self.chips_mm), "centres_mm": r(self.centres_mm), "offset_uT": r(self.offset_uT),
                "rest_uT": r(self.rest_uT), "travel_mm": r(self.travel_mm), "own_Bz_uT": r(self.own_Bz_uT),
                "lateral_mm": r(self.lateral_mm),
                "own_lateral_uT": r(self.own_lateral_uT), "magnet_mm": r(self.magnet_mm),
                "neighbour_uT": r(self.neighbour_uT),
                "moment_uT_mm3": round(self.moment_uT_mm3, 6)}


def array_field(design: Design) -> ArrayField:
    """The offsets, rest fields and own-field tables of ``design``'s taxels."""
    B = field_at_chips(design)
    own = np.eye(len(B), dtype=bool)
    magnet = fieldmod.Magnet.from_design(design)
    travel = np.linspace(0.0, design.d_rest_mm - design.spec.sensor.d_min_mm, TABLE_POINTS)
    below = -(design.d_rest_mm - travel + magnet.height_mm / 2.0)  # the chip in the magnet's frame
    axis = fieldmod.exact(magnet, np.column_stack([np.zeros_like(travel), np.zeros_like(travel), below]))
    moment = magnet.remanence_T * 1e6 * math.pi * magnet.radius_mm**2 * magnet.height_mm / (4.0 * math.pi)
    n = len(B)
    neighbour = np.zeros((n, n, len(travel), 3))
    centres = _magnet_centres(design)
    for i, t in enumerate(travel):
        lowered = field_at_chips(design, centres - [0.0, 0.0, t])
        neighbour[:, :, i, :] = np.where(own[:, :, None], 0.0, lowered - B)
    lateral = np.linspace(0.0, design.elastomer_radius_mm / 2.0, LATERAL_POINTS)
    grid = np.array([[-s, 0.0, z] for z in below for s in lateral])
    table = fieldmod.exact(magnet, grid)[:, [0, 2]].reshape(len(travel), len(lateral), 2) * UT_PER_GAUSS
    return ArrayField(_chips(design), centres, np.where(own[:, :, None], 0.0, B).sum(axis=1) + 0.0,
                      B[own] + 0.0, travel, axis[:, 2] * UT_PER_GAUSS, lateral, table + 0.0,
                      (magnet.radius_mm, magnet.height_mm), neighbour + 0.0, moment)


def simulate_taxel_scan(design: Design, prediction: Prediction, k: int, field: ArrayField | None = None) -> Scan:
    """The simulated calibration scan of taxel ``k``: the single taxel's scan (:func:`.scan.simulate_scan`, its own
    magnet flipped with the taxel's polarity) plus the neighbours' field at rest, as the chip reads it (the noise
    of its seed ``calibration.seed + k``, quantised, clipped at full scale as the single scan is)."""
    field = field or array_field(design)
    taxel = design.taxels[k]
    seeded = design.spec.model_copy(update={"calibration": design.spec.calibration.model_copy(
        update={"seed": (design.spec.calibration.seed + k) % 2**31})})
    return simulate_scan(replace(design, spec=seeded), prediction, polarity=taxel.polarity,
                         background_uT=tuple(field.offset_uT[k]))


ARRAY_FORMAT = array_json.FORMAT


@dataclass(frozen=True)
class ArrayCalibration:
    """Every taxel's fit (to its compensated scan) and the compensation they were fitted under."""

    field: ArrayField
    fits: tuple  # one magfab.models.calibration.FitResult per taxel, in taxel order
    scans: tuple  # the scans they were fitted to, as the chips read them (before compensation)
    dynamic: bool  # whether the host applies the K terms (the crosstalk budget asks for them)

    def file_name(self, k: int) -> str:
        return f"taxel_{k:02d}.json"

    def as_json(self, design: Design) -> dict[str, object]:
        """calibration/array.json: the taxels (index, address, order code, polarity, position, calibration file),
        and the compensation (offset_uT, rest_uT, K per taxel pair, whether K is applied)."""
        taxels = [{**t.as_dict(), "calibration": self.file_name(t.index)} for t in design.taxels]
        return {"format": ARRAY_FORMAT, "taxels": taxels, "dynamic": self.dynamic, **self.field.as_json()}

    def compensator(self, design: Design) -> array_json.Compensator:
        return array_json.validate(self.as_json(design))


def compensated(scan: Scan, field: ArrayField, k: int) -> Scan:
    """Taxel ``k``'s scan with the neighbours' static field removed (what its calibration is fitted to). A
    calibration scan loads one taxel, so the others rest and their K terms vanish."""
    return replace(scan, B_uT=scan.B_uT - field.offset_uT[k])


def calibrate_taxels(design: Design, prediction: Prediction, scans: tuple | None = None, *, mls: bool = False,
                     dynamic: bool = False) -> ArrayCalibration:
    """Fit every taxel of ``design``: to ``scans`` (one per taxel, as recorded) or to simulated ones."""
    field = array_field(design)  # 30 ms for five taxels: cheaper to make again than to pass along
    if scans is None:
        scans = tuple(simulate_taxel_scan(design, prediction, t.index, field) for t in design.taxels)
    fits = tuple(fit(compensated(s, field, k), design, mls=mls) for k, s in enumerate(scans))
    return ArrayCalibration(field, fits, tuple(scans), dynamic)
