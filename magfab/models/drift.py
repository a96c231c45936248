"""Drift: the force errors that come from outside the force model, predicted before building.

Three sources move the field the chip reads without a force on the tip:

* **temperature**: the magnet's remanence falls by alpha(Br) per degree (recipes/magnets.toml, per grade), the chip's
  sensitivity drifts within SENSTHD and its offset within OFFSTHD (recipes/chips.toml; the datasheet gives bands over
  its operating range, magfab spreads them evenly over the 60 C from 25 C to its hot end, see the recipes' sources);
* **the Earth's field**: turning the sensor by an angle theta changes the field on an axis by up to
  2 |B_earth| sin(theta / 2) (2 |B_earth| turned over), with |B_earth| 0.25-0.65 G depending on the place
  (recipes/bench.toml [environment]; the spec's ``environment.earth_field_G`` for a known place);
* **a stray dipole** of moment m at distance r (a motor, a magnetised steel part): at its worst orientation it puts
  mu0 m / (2 pi r^3) on any one axis (:func:`dipole_worst_G`).

Each becomes a force error through the calibration's inverse: the calibration made at the calibration temperature
maps the field to force along the predicted curve (:class:`Channel`; normal: the stiff material and the weakest
magnet, the same worst case as the resolution; shear: linear at the least predicted shear sensitivity), so a field
read as B + dB is taken for the force F(B + dB), and the error is F(B + dB) - F(B) -- the curve itself, not its
tangent (the magnet's part grows with B, which grows faster than the force towards the end of the range).

**Compensation** (what the firmware does with the chip's temperature): the field is divided by
(1 + alpha * dT_read) with the grade's recipe alpha and the chip's nominal sensitivity coefficient (0: the datasheet
gives only a band); the offset is not corrected. What it leaves: the true magnet's alpha anywhere in sintered
NdFeB's spread (recipe), the chip's sensitivity and offset bands, the temperature reading's error relative to the
calibration temperature (the datasheet's +/-3 C linearity TLIN taken as a parabola over the operating range, whose
difference between two nearby temperatures is small, plus half a 1/45.2 C step) and the stated magnet-to-chip lag
(``environment.temperature_lag_C``). Every bound enters with its worst sign (every corner of the bands is
evaluated), so the figures are worst cases, not RMS.

Units: field G, force N (errors mN), temperature C, moment A m^2, distance mm.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..recipes import catalogue
from ..spec import Environment
from ..units import GAUSS_PER_TESLA, M_PER_MM, MN_PER_N, UT_PER_GAUSS
from .field.magnet import MU0

if TYPE_CHECKING:
    from ..design import Design
    from ..spec import Environment
    from .predict import Prediction

__all__ = ["Coefficients", "coefficients", "environment", "Channel", "normal_channel", "shear_channel",
           "force_error_mN", "temperature_read_G", "temperature_error_mN", "TemperatureBudget", "temperature_budget",
           "earth_field_G", "Disturbance", "rotation_error", "dipole_field_G", "dipole_worst_G", "stray_error", "Drift",
           "drift", "N_TEMPERATURES", "CASES"]

#: Temperatures the span is evaluated at (the calibration temperature is added).
N_TEMPERATURES = 21


# ---------------------------------------------------------------------------------------------------
# The sourced coefficients and the stated conditions


@dataclass(frozen=True)
class Coefficients:
    """Temperature coefficients from the recipes; ``*_per_C`` are bounds (worst sign chosen later) unless named.

    ``magnet_pct_per_C``: the grade's alpha(Br) the firmware divides by; ``magnet_spread_pct_per_C``: where the true
    magnet's may lie (low, high); ``chip_sensitivity_pct_per_C``: SENSTHD over its span; ``chip_offset_*_G_per_C``:
    OFFSTHD in field units; ``sensor_linearity_C``: TLIN; ``sensor_step_C``: one LSB of the temperature channel;
    ``operating_C``: the chip's operating range (TLIN's span)."""

    magnet_pct_per_C: float
    magnet_spread_pct_per_C: tuple[float, float]
    chip_sensitivity_pct_per_C: float
    chip_offset_xy_G_per_C: float
    chip_offset_z_G_per_C: float
    sensor_linearity_C: float
    sensor_step_C: float
    operating_C: tuple[float, float]


def coefficients(design: Design) -> Coefficients:
    """:class:`Coefficients` for the design's grade and chip (recipes/magnets.toml, recipes/chips.toml)."""
    grade = design.magnet_grade
    chip = design.chip
    span = chip["sensitivity_drift_span_C"].nominal
    spread = grade.br_temperature_coefficient_spread_pct_per_C
    drift_lsb = max(abs(chip["offset_thermal_drift_lsb"].low), abs(chip["offset_thermal_drift_lsb"].high))
    gain = int(chip["offset_thermal_drift_gain_sel"].nominal)  # the datasheet's OFFSTHD is in LSB at this gain, RES 0
    lsb_xy = chip[f"sensitivity_xy_gain{gain}_uT_per_lsb"].nominal / UT_PER_GAUSS
    lsb_z = chip[f"sensitivity_z_gain{gain}_uT_per_lsb"].nominal / UT_PER_GAUSS
    sens = max(abs(chip["sensitivity_drift_pct"].low), abs(chip["sensitivity_drift_pct"].high))
    tlin = chip["temperature_linearity_C"]
    return Coefficients(
        magnet_pct_per_C=grade.br_temperature_coefficient_pct_per_C.nominal,
        magnet_spread_pct_per_C=(spread.low, spread.high),
        chip_sensitivity_pct_per_C=sens / span,
        chip_offset_xy_G_per_C=drift_lsb * lsb_xy / span,
        chip_offset_z_G_per_C=drift_lsb * lsb_z / span,
        sensor_linearity_C=max(abs(tlin.low), abs(tlin.high)),
        sensor_step_C=1.0 / chip["temperature_lsb_per_C"].nominal,
        operating_C=(chip["operating_temperature_min_C"].nominal, chip["operating_temperature_max_C"].nominal),
    )


def environment(design: Design) -> Environment:
    """The spec's ``[environment]``, or the lab bench its defaults describe when the section is omitted."""
    return design.spec.environment or Environment()


def earth_field_G(design: Design) -> tuple[float, float, float]:
    """(least, stated, strongest) total intensity of the Earth's field, G: the recipe's band, and the spec's
    ``environment.earth_field_G`` as the stated value (the band's strongest when omitted)."""
    band = catalogue("bench")["environment"]["earth_field_G"]
    stated = environment(design).earth_field_G
    return band.low, band.high if stated is None else float(stated), band.high


# ---------------------------------------------------------------------------------------------------
# The calibration's inverse along one axis


@dataclass(frozen=True)
class Channel:
    """One axis of the calibration: the field ``field_G`` (ascending) at the forces ``force_N``, its inverse
    :meth:`force_N` (linear past either end, at the end's slope) and ``end_N``, the end of the axis' range."""

    name: str
    field_G: np.ndarray
    force: np.ndarray
    end_N: float

    def force_N(self, b_G: object) -> np.ndarray:
        """Force read for the field ``b_G`` (G), N: the curve, extended linearly past its ends."""
        b, x, y = np.asarray(b_G, dtype=float), self.field_G, self.force
        inside = np.interp(b, x, y)
        lo = y[0] + (b - x[0]) * (y[1] - y[0]) / (x[1] - x[0])
        hi = y[-1] + (b - x[-1]) * (y[-1] - y[-2]) / (x[-1] - x[-2])
        return np.where(b < x[0], lo, np.where(b > x[-1], hi, inside))

    def field_at(self, force_N: object) -> np.ndarray:
        """Field at the force ``force_N`` (N) on the curve, G."""
        return np.interp(np.asarray(force_N, dtype=float), self.force, self.field_G)


def normal_channel(pred: Prediction, material: str = "stiff", grade: str = "low") -> Channel:
    """The normal axis: Bz against Fz along the predicted curve for ``material`` and ``grade`` (default the worst
    case the resolution is quoted for), within the normal range. Raises ValueError for a curve whose field does not
    rise with the force (no inverse)."""
    a = pred.arrays
    u_all = np.asarray(a["u"], dtype=float)
    bz_all = np.asarray(a[f"bz_{grade}"], dtype=float)
    f_all = np.asarray(pred.curves[material].force_N, dtype=float)
    u_end = float(pred.normal.travel_mm)  # the range ends here, between two steps of the curve
    keep = np.asarray(a["in_range"], dtype=bool) & (u_all < u_end - 1e-9)
    bz = np.append(bz_all[keep], np.interp(u_end, u_all, bz_all))
    force = np.append(f_all[keep], np.interp(u_end, u_all, f_all))
    if bz.size < 2 or np.any(np.diff(bz) <= 0) or np.any(np.diff(force) <= 0):
        raise ValueError("the normal curve's field must rise with the force for the calibration to be inverted")
    return Channel("normal", bz, force, float(force[-1]))


def shear_channel(pred: Prediction) -> Channel:
    """The shear axis: linear at the least predicted shear sensitivity (G/N, the worst case) up to the shear
    range."""
    s = float(pred.shear.sensitivity_G_per_N[0])
    end = float(pred.shear.range_N)
    return Channel("shear", np.array([0.0, s * end]), np.array([0.0, end]), end)


def force_error_mN(channel: Channel, force_N: object, field_read_G: object) -> np.ndarray:
    """Force error F_read - F_true, mN, when the true force ``force_N`` is read with the field ``field_read_G``."""
    return MN_PER_N * (channel.force_N(field_read_G) - np.asarray(force_N, dtype=float))


# ---------------------------------------------------------------------------------------------------
# Temperature


def temperature_read_G(b_G: object, dT_C: object, *, alpha_pct: float | np.ndarray,
                       sensitivity_pct: float | np.ndarray = 0.0, offset_G_per_C: float | np.ndarray = 0.0,
                       magnet_dT_C: object | None = None,
                       compensation: tuple[float, object] | None = None) -> np.ndarray:
    """The field read at a chip temperature ``dT_C`` from the calibration's, G, for a field ``b_G`` at the
    calibration temperature: the magnet (at ``magnet_dT_C``, default the chip's) scaled by 1 + alpha dT, the chip's
    sensitivity by 1 + s dT and its offset o dT (coefficients in %/C and G/C: numbers, or arrays that broadcast
    against the field, one row per corner of the bands). ``compensation`` = (alpha_pct the
    firmware uses, the temperature difference it reads): the reading divided by 1 + alpha dT_read."""
    b, dT = np.asarray(b_G, dtype=float), np.asarray(dT_C, dtype=float)
    dTm = dT if magnet_dT_C is None else np.asarray(magnet_dT_C, dtype=float)
    read = b * (1.0 + alpha_pct / 100.0 * dTm) * (1.0 + sensitivity_pct / 100.0 * dT) + offset_G_per_C * dT
    if compensation is not None:
        alpha_fw, dT_read = compensation
        read = read / (1.0 + alpha_fw / 100.0 * np.asarray(dT_read, dtype=float))
    return read


def temperature_error_mN(channel: Channel, force_N: object, dT_C: object, *, alpha_pct: float,
                         sensitivity_pct: float = 0.0, offset_G_per_C: float = 0.0, magnet_dT_C: object | None = None,
                         compensation: tuple[float, object] | None = None) -> np.ndarray:
    """Force error (mN) at the true force ``force_N`` on ``channel`` for given coefficients (not the bands' worst):
    :func:`temperature_read_G` read through the calibration's inverse; what a simulated run with these coefficients
    should show."""
    b = channel.field_at(force_N)
    read = temperature_read_G(b, dT_C, alpha_pct=alpha_pct, sensitivity_pct=sensitivity_pct,
                              offset_G_per_C=offset_G_per_C, magnet_dT_C=magnet_dT_C, compensation=compensation)
    return force_error_mN(channel, force_N, read)


def _sensor_error_C(c: Coefficients, t_C: np.ndarray, t_cal_C: float, bow: float) -> np.ndarray:
    """The temperature reading's error relative to the calibration temperature, C: TLIN as a parabola over the
    operating range whose best-fit line leaves +/-TLIN, plus half an LSB, both at their worst (``bow`` +/-1 picks
    the sign)."""
    lo, hi = c.operating_C
    mid, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    x, x0 = (t_C - mid) / half, (t_cal_C - mid) / half
    return bow * (2.0 * c.sensor_linearity_C * np.abs(x**2 - x0**2) + 0.5 * c.sensor_step_C)


def _corners(c: Coefficients, offset_G_per_C: float, lag_C: float, fitted: bool = False) -> np.ndarray:
    """Every corner of the bands: rows (alpha %/C, sensitivity %/C, offset G/C, lag C, TLIN sign). ``fitted``: the
    magnet's and the chip's scale coefficients were measured (a calibration scan over temperature), so only the
    recipe alpha and a chip sensitivity of 0 remain."""
    alphas = (c.magnet_pct_per_C,) if fitted else c.magnet_spread_pct_per_C
    sens = (0.0,) if fitted else (-c.chip_sensitivity_pct_per_C, c.chip_sensitivity_pct_per_C)
    rows = itertools.product(alphas, sens, (-offset_G_per_C, offset_G_per_C), (-lag_C, lag_C), (-1.0, 1.0))
    return np.array(list(rows), dtype=float)


def _worst(err: np.ndarray) -> np.ndarray:
    """The signed error of largest magnitude along axis 0."""
    return np.take_along_axis(err, np.argmax(np.abs(err), axis=0)[None], axis=0)[0]


#: The temperature budget's cases: no compensation, compensation with the recipes' coefficients, and with the
#: coefficients fitted to a calibration scan over temperature.
CASES = ("without", "with", "fitted")


def _span_errors(c: Coefficients, ch: Channel, force_N: float, offset: float, t_C: np.ndarray, t_cal: float,
                 lag: float, case: str) -> np.ndarray:
    """Worst signed force error (mN) at ``force_N`` on ``ch`` at each chip temperature ``t_C``, over every corner,
    for one of :data:`CASES`."""
    compensated = case != "without"
    k = _corners(c, offset, lag if compensated else 0.0, fitted=case == "fitted")
    dT = (t_C - t_cal)[None, :]
    b = ch.field_at(force_N)
    comp = None
    if compensated:
        dT_read = dT + _sensor_error_C(c, t_C, t_cal, 1.0)[None, :] * k[:, 4:5]
        comp = (c.magnet_pct_per_C, dT_read)
    read = temperature_read_G(b, dT, alpha_pct=k[:, 0:1], sensitivity_pct=k[:, 1:2], offset_G_per_C=k[:, 2:3],
                              magnet_dT_C=dT + k[:, 3:4], compensation=comp)
    return _worst(force_error_mN(ch, force_N, read))


@dataclass(frozen=True)
class TemperatureBudget:
    """Force errors from temperature, mN (signed worst cases over the coefficients' bands).

    ``per_C``: for +1 C from the calibration temperature, keys ``normal_rest``, ``normal_end``, ``shear_rest``,
    ``shear_end``, each {case: ...} for :data:`CASES` (with: the coefficients' uncertainty and the offset; fitted: the
    offset; the sensor's error and the lag are not per degree and appear in the span); ``per_C_parts``: the
    uncompensated normal error at rest per source (magnet, chip_sensitivity, chip_offset), and ``per_C_field_G`` the
    field change each makes, G; ``temperatures_C`` and ``span``: the same four points
    at each temperature of the spec's span, without and with compensation; ``worst``: the largest |error| over the
    span per point and case."""

    calibration_C: float
    temperatures_C: tuple[float, ...]
    per_C: Mapping[str, Mapping[str, float]]
    per_C_parts: Mapping[str, float]
    span: Mapping[str, Mapping[str, tuple[float, ...]]]
    worst: Mapping[str, Mapping[str, float]]
    per_C_field_G: Mapping[str, float]  # the field change at rest per source for +1 C, G (against the noise)

    def as_json(self) -> dict[str, object]:
        return {"calibration_C": self.calibration_C, "per_C_mN": {k: dict(v) for k, v in self.per_C.items()},
                "per_C_parts_normal_rest_mN": dict(self.per_C_parts),
                "per_C_parts_normal_rest_field_G": dict(self.per_C_field_G),
                "temperatures_C": list(self.temperatures_C),
                "span_mN": {k: {c: list(v) for c, v in d.items()} for k, d in self.span.items()},
                "worst_over_span_mN": {k: dict(v) for k, v in self.worst.items()}}


def _points(pred: Prediction, normal: Channel, shear: Channel,
            c: Coefficients) -> dict[str, tuple[Channel, float, float]]:
    """The four points the budget is given at: (channel, true force N, offset bound G/C)."""
    return {"normal_rest": (normal, 0.0, c.chip_offset_z_G_per_C),
            "normal_end": (normal, normal.end_N, c.chip_offset_z_G_per_C),
            "shear_rest": (shear, 0.0, c.chip_offset_xy_G_per_C),
            "shear_end": (shear, shear.end_N, c.chip_offset_xy_G_per_C)}


def temperature_budget(design: Design, pred: Prediction, temperatures_C: object | None = None,
                       normal: Channel | None = None) -> TemperatureBudget:
    """The temperature part of the drift budget (:class:`TemperatureBudget`) over the spec's span (or
    ``temperatures_C``, chip temperatures in C), for the calibration ``normal`` (default :func:`normal_channel`)."""
    env, c = environment(design), coefficients(design)
    normal = normal or normal_channel(pred)
    shear = shear_channel(pred)
    t_cal = float(env.calibration_temperature_C)
    if temperatures_C is None:
        grid = np.linspace(env.temperature_min_C, env.temperature_max_C, N_TEMPERATURES)
        temperatures_C = np.unique(np.append(grid, t_cal))
    t = np.asarray(temperatures_C, dtype=float)
    one = np.array([t_cal + 1.0])
    per_C, span, worst = {}, {}, {}
    for name, (ch, f, off) in _points(pred, normal, shear, c).items():
        per_C[name] = {case: float(_span_errors(c, ch, f, off, one, t_cal, 0.0, case)[0]) for case in CASES}
        span[name] = {case: tuple(float(x) for x in _span_errors(c, ch, f, off, t, t_cal, env.temperature_lag_C, case))
                      for case in CASES}
        worst[name] = {case: float(np.max(np.abs(v))) for case, v in span[name].items()}
    b0 = normal.field_at(0.0)
    parts = {"magnet": temperature_read_G(b0, 1.0, alpha_pct=c.magnet_pct_per_C),
             "chip_sensitivity": temperature_read_G(b0, 1.0, alpha_pct=0.0,
                                                    sensitivity_pct=-c.chip_sensitivity_pct_per_C),
             "chip_offset": temperature_read_G(b0, 1.0, alpha_pct=0.0, offset_G_per_C=-c.chip_offset_z_G_per_C)}
    per_C_parts = {k: float(force_error_mN(normal, 0.0, v)) for k, v in parts.items()}
    per_C_field = {k: float(v - b0) for k, v in parts.items()}
    return TemperatureBudget(t_cal, tuple(float(x) for x in t), per_C, per_C_parts, span, worst, per_C_field)


# ---------------------------------------------------------------------------------------------------
# Uniform and dipole fields


@dataclass(frozen=True)
class Disturbance:
    """A field change on one axis (``field_G``, G) and the force errors it causes, mN: normal at rest and at the end
    of the range, shear (linear: the same everywhere); ``what`` says where the field comes from."""

    what: str
    field_G: float
    normal_rest_mN: float
    normal_end_mN: float
    shear_mN: float

    def as_json(self) -> dict[str, object]:
        return {"what": self.what, "field_G": self.field_G, "normal_rest_mN": self.normal_rest_mN,
                "normal_end_mN": self.normal_end_mN, "shear_mN": self.shear_mN}


def _disturbance(pred: Prediction, what: str, field_G: float, normal: Channel | None = None) -> Disturbance:
    """The force errors of a field change ``field_G`` (G) on an axis, at its worst sign."""
    normal = normal or normal_channel(pred)
    shear = shear_channel(pred)

    def worst(ch: Channel, f: float) -> float:
        b = ch.field_at(f)
        e = force_error_mN(ch, f, np.array([b - field_G, b + field_G]))
        # the larger error; on a tie (a linear channel: equal to the last bit, which rounding decides) the one the
        # field's fall makes, so a figure's sign does not turn with the numerical library's rounding
        return float(e[1] if abs(e[1]) > abs(e[0]) * (1.0 + 1e-9) else e[0])

    return Disturbance(what, float(field_G), worst(normal, 0.0), worst(normal, normal.end_N), worst(shear, 0.0))


def rotation_error(design: Design, pred: Prediction, field_G: float | None = None,
                   rotation_deg: float | None = None, normal: Channel | None = None) -> Disturbance:
    """Turning the sensor by ``rotation_deg`` (default the spec's) in the Earth's field of ``field_G`` G (default the
    spec's or the strongest): the field on an axis changes by up to 2 |B| sin(theta / 2)."""
    env = environment(design)
    b = earth_field_G(design)[1] if field_G is None else float(field_G)
    theta = env.rotation_deg if rotation_deg is None else float(rotation_deg)
    change = 2.0 * b * math.sin(math.radians(theta) / 2.0)
    return _disturbance(pred, f"turning the sensor {theta:g} deg in a {b:g} G Earth field", change, normal)


def dipole_field_G(moment_Am2: object, source_mm: object, observer_mm: object) -> np.ndarray:
    """Field of a point dipole, G: moment vector(s) (..., 3) in A m^2 at ``source_mm``, at ``observer_mm``
    (..., 3, mm; broadcast). B = mu0 / (4 pi) (3 (m . r^) r^ - m) / |r|^3."""
    m = np.asarray(moment_Am2, dtype=float)
    r = (np.asarray(observer_mm, dtype=float) - np.asarray(source_mm, dtype=float)) * M_PER_MM
    d = np.linalg.norm(r, axis=-1, keepdims=True)
    u = r / d
    b = MU0 / (4.0 * math.pi) * (3.0 * np.sum(m * u, axis=-1, keepdims=True) * u - m) / d**3
    return b * GAUSS_PER_TESLA


def dipole_worst_G(moment_Am2: float, distance_mm: float) -> float:
    """Largest field a dipole of ``moment_Am2`` at ``distance_mm`` puts on any one axis, G: |3 (u.e) u - e| <= 2,
    reached when the moment, the axis and the line to the dipole are aligned: mu0 m / (2 pi r^3)."""
    r = distance_mm * M_PER_MM
    return MU0 * moment_Am2 / (2.0 * math.pi * r**3) * GAUSS_PER_TESLA


def stray_error(design: Design, pred: Prediction, moment_Am2: float | None = None,
                distance_mm: float | None = None, normal: Channel | None = None) -> Disturbance | None:
    """A stray dipole (default the spec's ``environment.stray_*``) at its worst orientation; None when no moment is
    stated (magfab has no sourced typical moment: the user measures or estimates theirs)."""
    env = environment(design)
    m = env.stray_moment_Am2 if moment_Am2 is None else float(moment_Am2)
    r = env.stray_distance_mm if distance_mm is None else float(distance_mm)
    if m <= 0.0:
        return None
    return _disturbance(pred, f"a {m:g} A m^2 dipole at {r:g} mm, worst orientation", dipole_worst_G(m, r), normal)


# ---------------------------------------------------------------------------------------------------
# The budget


@dataclass(frozen=True)
class Drift:
    """The drift budget (module doc): temperature, rotation in the Earth's field (the stated place and turn, and
    turned over at the band's least and strongest field), the stray source if stated, each against the resolution
    (mN) and the chip's noise (G RMS)."""

    coefficients: Coefficients
    conditions: Mapping[str, Any]  # the [environment] table as JSON values, the Earth field filled in
    temperature: TemperatureBudget
    rotation: Disturbance
    rotation_band: tuple[Disturbance, Disturbance]
    stray: Disturbance | None
    resolution_mN: Mapping[str, float]  # normal, shear
    noise_G: Mapping[str, float]  # z, xy
    channel: Channel = field(repr=False, compare=False)  # the normal calibration the figures were made with

    def _against_noise(self, x: Disturbance) -> dict[str, object]:
        """A disturbance's figures, with its field over the chip's RMS noise on z and on x/y."""
        return {**x.as_json(), "field_over_noise_z": x.field_G / self.noise_G["z"],
                "field_over_noise_xy": x.field_G / self.noise_G["xy"]}

    def as_json(self) -> dict[str, object]:
        c = self.coefficients
        return {
            "conditions": dict(self.conditions),
            "coefficients": {"magnet_pct_per_C": c.magnet_pct_per_C,
                             "magnet_spread_pct_per_C": list(c.magnet_spread_pct_per_C),
                             "chip_sensitivity_pct_per_C": c.chip_sensitivity_pct_per_C,
                             "chip_offset_xy_G_per_C": c.chip_offset_xy_G_per_C,
                             "chip_offset_z_G_per_C": c.chip_offset_z_G_per_C,
                             "sensor_linearity_C": c.sensor_linearity_C, "sensor_step_C": c.sensor_step_C,
                             "operating_C": list(c.operating_C)},
            "temperature": self.temperature.as_json(),
            "rotation": self._against_noise(self.rotation),
            "rotation_band": [self._against_noise(d) for d in self.rotation_band],
            "stray": None if self.stray is None else self._against_noise(self.stray),
            "resolution_mN": dict(self.resolution_mN),
            "noise_G": dict(self.noise_G),
            "calibration_curve": "normal: the stiff material and the weakest magnet (the resolution's worst case); "
                                 "shear: linear at the least shear sensitivity",
        }


def drift(design: Design, pred: Prediction) -> Drift:
    """The whole drift budget for ``design`` and its prediction."""
    env = environment(design)
    normal = normal_channel(pred)
    low, stated, high = earth_field_G(design)
    conditions = dict(env.model_dump(mode="json"))
    conditions["earth_field_G"] = stated
    conditions["earth_field_band_G"] = [low, high]
    conditions["stated"] = design.spec.environment is not None
    return Drift(
        coefficients=coefficients(design), conditions=conditions,
        temperature=temperature_budget(design, pred, normal=normal),
        rotation=rotation_error(design, pred, normal=normal),
        rotation_band=(rotation_error(design, pred, low, 180.0, normal),
                       rotation_error(design, pred, high, 180.0, normal)),
        stray=stray_error(design, pred, normal=normal),
        resolution_mN={"normal": float(pred.normal.resolution_mN), "shear": float(pred.shear.resolution_mN)},
        noise_G={"z": float(pred.noise.total_z_G), "xy": float(pred.noise.total_xy_G),
                 "chip_z": float(pred.noise.chip_z_G), "chip_xy": float(pred.noise.chip_xy_G)},
        channel=normal,
    )
