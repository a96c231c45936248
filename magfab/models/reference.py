"""A reference MLX90393 for stray-field rejection: where it goes on the board and what it rejects.

A field that is the same at both chips (the Earth's, turned with the sensor; a far motor's) reaches the
sensing chip and a second chip that no sensing magnet moves. Subtracting the reference's change from the sensing
chip's reading removes it, up to the two chips' mismatch; a source near the board is not the same at both, and
what is left is its gradient across the chips' separation.

Where. The reference must not read the sensing magnets: their field there is a constant (removed with the zero),
but its *change* is not. Along the board's +y (away from the connector edge), from the taxels' hull, the site is the
nearest point where, for every magnet pressed through its normal travel or slid through its shear travel
(:class:`Travel`: the board places by what the geometry allows, pressed to d_min and slid by the elastomer's radius
less the magnet's; the prediction reports the change at its predicted travel), and for the magnets' rest field changing
over the environment's temperature span by the grade's remanence coefficient, the change of every component at the
reference stays below the chip's own RMS noise on that axis (:func:`magfab.models.chip.noise`). Exact superposition of
every magnet (:func:`magfab.models.field.exact`). What is subtracted is then below one noise sigma whatever the taxels
do.

What it rejects.

* A uniform field: both chips read it through their own sensitivity; what remains is their relative mismatch. The
  MLX90393 datasheet (rev 011, Table 9) bounds no part-to-part sensitivity; it bounds each chip's sensitivity over
  temperature to +/-3 % of its 25 C value (SENSTHD) and every cross-axis sensitivity to < 1 %. Two chips may sit
  at opposite ends of that band, so the mismatch taken is twice SENSTHD (an assumption: the bench's rotation
  step measures the real one), and the ratio ``1 / (mismatch + cross-axis)``, worst case.
* A dipole (a motor, a steel part) at distance D from the sensing chip: the exact difference of its field at the two
  chips (:func:`magfab.models.drift.dipole_field_G`, tested against magpylib's ``Dipole``), at the orientation of
  its moment and the direction from the board that make it worst, and the median over them. For D much larger than the
  separation s the ratio is about D / (3 s); for D comparable to s the reference reads a different field and subtracting
  it can make the error larger (a ratio below 1): the finding says so.

The reference's own noise adds to the sensing chip's; the firmware low-passes the reference (an exponential average
of ``2**REFERENCE_SHIFT`` readings, which a stray field changing slower than a few hertz passes) so the noise grows
by ``sqrt(1 + k / (2 - k))`` with ``k = 2**-REFERENCE_SHIFT``.

Units: lengths mm, fields gauss (the field models' unit), moments A m^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from . import field as fieldmod
from .chip import chip_setting, noise
from .drift import dipole_field_G, rotation_error, stray_error

if TYPE_CHECKING:
    from ..design import Design
    from .drift import Drift
    from .predict import Prediction

__all__ = ["ReferenceChip", "Site", "Rejection", "Travel", "site", "rejection", "budget", "REFERENCE_SHIFT",
           "noise_growth"]

#: The firmware's reference filter: an exponential average with weight 2**-REFERENCE_SHIFT per reading.
REFERENCE_SHIFT = 3
#: Distances swept from the hull's edge for the site, mm (then bisected to SITE_TOL_MM).
SITE_MAX_MM = 200.0
SITE_TOL_MM = 0.25
#: Directions from the board of a stray dipole, and orientations of its moment, tried for the worst case.
_SPHERE = 26


@dataclass(frozen=True)
class Site:
    """The reference chip's place (board frame, mm, the chip's sensing plane) and what the magnets do there (G)."""

    xy_mm: tuple[float, float]
    separation_mm: float  # from the nearest sensing chip
    motion_G: tuple[float, float]  # the largest change (xy, z) as any magnet moves through its range
    thermal_G: tuple[float, float]  # the rest field's change (xy, z) over the temperature span
    rest_G: tuple[float, float, float]  # the magnets' rest field there (a constant the zero removes)
    noise_G: tuple[float, float]  # the chip's RMS noise (xy, z) the changes are held under

    def as_json(self) -> dict[str, object]:
        return {"xy_mm": [round(v, 3) for v in self.xy_mm], "separation_mm": round(self.separation_mm, 3),
                "motion_G": _r(self.motion_G), "thermal_G": _r(self.thermal_G), "rest_G": _r(self.rest_G),
                "noise_G": _r(self.noise_G)}


@dataclass(frozen=True)
class Rejection:
    """What subtracting the reference leaves of a stray field, as ratios (field without / with the reference)."""

    uniform: float
    mismatch: float  # the chips' relative sensitivity mismatch assumed (fraction)
    cross_axis: float  # the datasheet's cross-axis bound (fraction)
    dipole_mm: tuple[float, ...]  # distances of the stray dipole from the sensing chip
    dipole: tuple[float, ...]  # worst ratio at each distance (below 1: the reference makes it worse)
    dipole_median: tuple[float, ...]  # the median over the dipole's directions and orientations
    noise_growth: float  # the sensing channel's noise with the filtered reference subtracted, x

    def as_json(self) -> dict[str, object]:
        return {"uniform": round(self.uniform, 3), "mismatch": round(self.mismatch, 5),
                "cross_axis": round(self.cross_axis, 5), "noise_growth": round(self.noise_growth, 4),
                "dipole": [{"distance_mm": d, "worst": round(r, 4), "median": round(m, 4)}
                           for d, r, m in zip(self.dipole_mm, self.dipole, self.dipole_median)]}


def _r(values) -> list[float]:
    return [round(float(v), 5) for v in values]


def noise_growth(shift: int = REFERENCE_SHIFT) -> float:
    """The factor on the sensing channel's RMS noise once the exponentially averaged reference is subtracted."""
    k = 2.0**-shift
    return math.sqrt(1.0 + k / (2.0 - k))


def _magnets(design: Design) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) magnet centres at rest and (N,) polarities, board frame mm."""
    z = design.z_magnet_low_mm + design.magnet_height_mm / 2.0
    return (np.array([[t.x_mm, t.y_mm, z] for t in design.taxels]),
            np.array([float(t.polarity) for t in design.taxels]))


@dataclass(frozen=True)
class Travel:
    """How far each magnet moves (mm): pressed towards its chip, slid sideways."""

    normal_mm: float
    shear_mm: float

    @classmethod
    def predicted(cls, design: Design, pred: Prediction) -> Travel:
        """The prediction's: the normal range's travel, the shear range over the softest material's stiffness."""
        return cls(pred.normal.travel_mm, pred.shear.range_N / min(pred.shear.stiffness_N_per_mm.values()))

    @classmethod
    def bound(cls, design: Design) -> Travel:
        """What the geometry allows, before any prediction: pressed to d_min, slid by the elastomer's radius less
        the magnet's (the tip torn off past that). At least the predicted travel; the board places by this."""
        s = design.spec.sensor
        return cls(s.d_max_mm - s.d_min_mm, design.elastomer_radius_mm - design.magnet_radius_mm)


def _changes(design: Design, travel: Travel, points: np.ndarray, span_C: float) -> np.ndarray:
    """(P, 7) the largest motion change (xy, z), the thermal change (xy, z) and the rest field (3) at ``points``
    (P, 3), G."""
    magnet = fieldmod.Magnet.from_design(design)
    centres, signs = _magnets(design)
    moves = [(0.0, 0.0, -travel.normal_mm)] + [(sx * travel.shear_mm, sy * travel.shear_mm, 0.0)
                                               for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    alpha = abs(_remanence_coefficient(design))
    rest = np.zeros((len(points), 3))
    motion = np.zeros((len(points), 2))
    for c, s in zip(centres, signs):
        at_rest = s * fieldmod.exact(magnet, points - c)
        rest += at_rest
        for move in moves:
            d = s * fieldmod.exact(magnet, points - c - np.array(move)) - at_rest
            motion = np.maximum(motion, np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.abs(d[:, 2])]))
    thermal = alpha * span_C * np.column_stack([np.hypot(rest[:, 0], rest[:, 1]), np.abs(rest[:, 2])])
    return np.column_stack([motion, thermal, rest])


@dataclass(frozen=True)
class ReferenceChip:
    """The reference chip: its centre (design frame, mm, y up), I2C address and straps, the chip to order."""

    index: int  # after the taxels: the firmware reads it last
    x_mm: float
    y_mm: float
    distance_mm: float  # beyond the taxels' hull along +y
    separation_mm: float  # from the nearest sensing chip
    i2c_address: int
    option_code: str
    address_straps: tuple[int, int]  # (A1, A0): 0 = GND, 1 = supply

    @property
    def designator(self) -> str:
        return f"U{self.index + 1}"

    def as_dict(self) -> dict[str, object]:
        return {"index": self.index, "designator": self.designator, "x_mm": round(self.x_mm, 3),
                "y_mm": round(self.y_mm, 3), "distance_mm": round(self.distance_mm, 3),
                "separation_mm": round(self.separation_mm, 3), "i2c_address": self.i2c_address,
                "option_code": self.option_code, "address_straps": list(self.address_straps)}


def _remanence_coefficient(design: Design) -> float:
    """The grade's remanence temperature coefficient, per C (magnets.toml)."""
    return design.magnet_grade.br_temperature_coefficient_pct_per_C.nominal / 100.0


def site(design: Design, travel: Travel, span_C: float, distance_mm: float | None = None) -> Site:
    """The reference's site (module doc) for magnets moving by ``travel``: the nearest along +y from the hull where
    every change is under the noise, or ``distance_mm`` beyond the hull's edge when given (the figures then say how
    loud the magnets are there)."""
    n = noise(design, chip_setting(design))
    limit = np.array([n["total_xy_G"], n["total_z_G"]])
    xs = [t.x_mm for t in design.taxels]
    x0, y_edge = (min(xs) + max(xs)) / 2.0, max(t.y_mm for t in design.taxels)

    def point(s: float) -> np.ndarray:
        return np.array([[x0, y_edge + s, design.z_sense_mm]])

    def excess(s: float) -> float:
        ch = _changes(design, travel, point(s), span_C)[0]
        return float(max(np.max(ch[0:2] / limit), np.max(ch[2:4] / limit)))

    if distance_mm is None:
        lo, hi = design.pad_radius_mm, SITE_MAX_MM  # the reference stands beside the pad, never under it
        if excess(hi) > 1.0:
            distance_mm = hi
        else:
            while hi - lo > SITE_TOL_MM:
                mid = (lo + hi) / 2.0
                lo, hi = (mid, hi) if excess(mid) > 1.0 else (lo, mid)
            distance_mm = math.ceil(hi / SITE_TOL_MM) * SITE_TOL_MM
    p = point(distance_mm)
    ch = _changes(design, travel, p, span_C)[0]
    chips = np.array([[t.x_mm, t.y_mm] for t in design.taxels])
    sep = float(np.min(np.hypot(*(chips - p[0, :2]).T)))
    return Site((float(p[0, 0]), float(p[0, 1])), sep, tuple(ch[0:2]), tuple(ch[2:4]), tuple(ch[4:7]),
                tuple(limit))


def _directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread over the sphere (a Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1.0 + math.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def rejection(design: Design, where: Site,
              distances_mm: tuple[float, ...] = (30.0, 60.0, 100.0, 300.0, 1000.0)) -> Rejection:
    """The predicted rejection ratios (module doc) for a reference at ``where``: a uniform field, and a dipole at each
    of ``distances_mm`` from the sensing chip (taxel 0's), worst over its direction and orientation."""
    chip = design.chip
    drift = chip["sensitivity_drift_pct"]
    mismatch = 2.0 * max(abs(drift.low), abs(drift.high)) / 100.0
    cross = chip["cross_axis_sensitivity_pct"].nominal / 100.0
    t0 = design.taxels[0]
    sense = np.array([t0.x_mm, t0.y_mm, design.z_sense_mm])
    ref = np.array([where.xy_mm[0], where.xy_mm[1], design.z_sense_mm])
    dirs = _directions(_SPHERE)
    ratios, medians = [], []
    for dist in distances_mm:
        at = sense + dist * dirs  # (D, 3)
        keep = np.linalg.norm(at - ref, axis=1) > 1.0  # never on the reference itself
        at_b, m_b = np.broadcast_arrays(at[keep][:, None, :], dirs[None, :, :])
        b_sense = dipole_field_G(m_b, at_b, sense)
        b_ref = dipole_field_G(m_b, at_b, ref)
        ratio = np.linalg.norm(b_sense, axis=-1) / np.linalg.norm(b_sense - b_ref, axis=-1)
        ratios.append(float(np.min(ratio)))
        medians.append(float(np.median(ratio)))
    return Rejection(1.0 / (mismatch + cross), mismatch, cross, tuple(float(d) for d in distances_mm),
                     tuple(ratios), tuple(medians), noise_growth())


def budget(design: Design, pred: Prediction, drift_budget: Drift, chip: ReferenceChip) -> dict[str, object]:
    """predictions.json's ``reference``: the placed ``chip`` (:func:`magfab.reference_chip.reference_chip`), what
    the magnets do there at the predicted travel, the predicted rejection, and the drift budget's rotation and stray
    errors left after it (mN)."""
    env = drift_budget.conditions
    span = float(env["temperature_max_C"]) - float(env["temperature_min_C"])
    placed = site(design, Travel.predicted(design, pred), span, distance_mm=chip.distance_mm)
    distances = (30.0, 100.0, 300.0, 1000.0)
    stray_mm = float(env["stray_distance_mm"])
    rej = rejection(design, placed, tuple(sorted(set(distances) | {stray_mm})))
    turned = replace(rotation_error(design, pred, field_G=float(env["earth_field_G"]) / rej.uniform),
                     what=f"{drift_budget.rotation.what}, the reference subtracted ({rej.uniform:.0f}x)")
    out: dict[str, object] = {
        "chip": chip.as_dict(), "site": placed.as_json(), "rejection": rej.as_json(),
        "quiet": bool(placed.motion_G[0] <= placed.noise_G[0] and placed.motion_G[1] <= placed.noise_G[1]),
        "rotation": {"without": drift_budget.rotation.as_json(), "with": turned.as_json()},
        "stray": None}
    if drift_budget.stray is not None:
        k = rej.dipole_mm.index(stray_mm)
        moment = float(env["stray_moment_Am2"])
        left = {}
        for name, ratio in (("with_median", rej.dipole_median[k]), ("with_worst", rej.dipole[k])):
            reduced = stray_error(design, pred, moment / ratio, stray_mm)
            assert reduced is not None  # the budget's stray moment is > 0, and stays so divided by a rejection
            left[name] = replace(reduced, what=(
                f"{drift_budget.stray.what}, the reference subtracted ({ratio:.2g}x, {name[5:]} over its "
                "direction and orientation)")).as_json()
        out["stray"] = {"without": drift_budget.stray.as_json(), **left}
    return out
