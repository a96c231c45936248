"""The simulated calibration scan: the published y-z track over the predicted sensor.

The tip is indented by delta (0 to ``scan_z_mm``, capped where the predicted normal range ends) and displaced
laterally by y (centred on the axis, ``scan_y_mm`` wide, capped at the predicted lateral range), in
``scan_step_mm`` steps. Assumptions, stated because they are not modelled further: the magnet's lateral
offset equals the tip's (the magnet sits near the top surface and moves with it), and normal and shear loads
superpose (the axial travel and Fz come from the nominal FE curve at delta, the lateral force is K_s y with
the nominal shear stiffness, each independent of the other). The chip's noise and quantisation and the
reference sensor's resolution are added; the result is deterministic for a given ``calibration.seed``.

Units: field in microtesla (uT), force in newton, lengths in mm, time in s.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..formats.scan_csv import Scan, scan_csv
from ..units import UT_PER_GAUSS
from . import field as fieldmod
from .calibration_thermal import DEFAULT_REFERENCE_C, recipe_coefficient_per_C
from .chip import chip_setting, noise
from .predict import predict

if TYPE_CHECKING:
    from ..design import Design
    from .predict import Prediction

__all__ = ["ScanPlan", "scan_plan", "scan_track", "simulate_scan"]



@dataclass(frozen=True)
class ScanPlan:
    """The extent of the calibration scan, the one the simulated scan runs and the checklist tells the bench to
    run: ``y_half_mm`` either side of the axis and 0..``depth_mm`` of indentation in ``step_mm`` steps
    (``columns`` x ``rows`` points); ``depth_end`` and ``y_end`` name what ends each span (the spec's scan extent,
    or the predicted range's limit when it ends first)."""

    y_half_mm: float
    depth_mm: float
    step_mm: float
    columns: int
    rows: int
    depth_end: str
    y_end: str

    @property
    def points(self) -> int:
        return self.columns * self.rows


def scan_plan(design: Design, prediction: Prediction | None = None) -> ScanPlan:
    """The scan's extent (:class:`ScanPlan`): ``scan_y_mm`` centred on the axis, capped at the predicted lateral
    range (the magnet radius or the chip's xy full scale), and 0..``scan_z_mm`` of indentation, capped at the
    indentation where the predicted normal range ends (``normal.travel_mm`` of magnet travel, through the nominal
    FE curve); one depth for the simulated scan, the checklist's scan step and the predicted range. Without a
    prediction, the spec's extent uncapped."""
    cal = design.spec.calibration
    step = cal.scan_step_mm
    half, y_end = cal.scan_y_mm / 2.0, "calibration.scan_y_mm"
    depth, depth_end = float(cal.scan_z_mm), "calibration.scan_z_mm"
    if prediction is not None:
        nominal = prediction.curves["nominal"]
        delta_end = float(np.interp(prediction.normal.travel_mm, nominal.magnet_displacement_mm,
                                    nominal.indentation_mm))
        shear = prediction.shear
        lateral_end = shear.range_by_material_N["nominal"] / shear.stiffness_N_per_mm["nominal"]
        if lateral_end < half:
            half, y_end = lateral_end, f"the predicted shear range ({shear.range_limit})"
        if delta_end < depth - 1e-9:
            depth, depth_end = delta_end, f"the predicted normal range ({prediction.normal.range_limit})"
    columns = math.floor(2.0 * half / step + 1e-9) + 1
    rows = math.floor(depth / step + 1e-9) + 1
    return ScanPlan(half, depth, step, columns, rows, depth_end, y_end)


def scan_track(design: Design, prediction: Prediction) -> tuple[np.ndarray, np.ndarray]:
    """The y-z track of the scan (:func:`scan_plan`): (y_mm, indentation_mm), each (N,), in raster order (one row
    of y per indentation step, y increasing along each row, indentation increasing row by row)."""
    plan = scan_plan(design, prediction)
    y = (np.arange(plan.columns) - (plan.columns - 1) / 2.0) * plan.step_mm
    delta = np.arange(plan.rows) * plan.step_mm
    dd, yy = np.meshgrid(delta, y, indexing="ij")
    return yy.ravel(), dd.ravel()


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    return np.round(x / step) * step if step > 0 else x


def scan_temperature(rows: int, temperature_C: float | tuple[float, float] | None,
                     passes: int = 1) -> np.ndarray | None:
    """The chip temperature (rows * passes,) degC of a simulated scan: None, a constant, or (start, end) ramped
    linearly over every row of every pass (so a two-pass scan reads each point at two temperatures)."""
    if temperature_C is None:
        return None
    start, end = np.broadcast_to(np.asarray(temperature_C, dtype=float), (2,))  # a constant: start = end
    n = rows * passes
    return start + (end - start) * np.arange(n) / max(n - 1, 1)


def simulate_scan(design: Design, prediction: Prediction | None = None, *, ideal: bool = False, polarity: int = 1,
                  background_uT: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  temperature_C: float | tuple[float, float] | None = None, passes: int = 1,
                  thermal_per_C: float | tuple[float, float, float] | None = None) -> Scan:
    """The simulated calibration scan of ``design`` (module doc): field in uT at the sensing point and the
    reference force in N along :func:`scan_track`.

    Noise: gaussian per axis with the predicted RMS (``predict.noise``: environment and chip; the chip's
    quantisation is then applied by rounding to its LSB, so the total matches ``total_xy_G``/``total_z_G``),
    clipped at the chip's full scale; the reference forces are rounded to ``reference_resolution_mN``.
    ``ideal=True``: the same track without noise, quantisation or clipping (the truth a fit should recover).
    ``polarity`` -1 flips the magnet (an array's alternating taxel); ``background_uT`` is a steady field added at
    the chip (an array's neighbours at rest, :mod:`.taxels`).
    Sample times are one chip conversion apart. Deterministic (``calibration.seed``).

    Temperature (:func:`scan_temperature`): ``temperature_C`` None (no column, the model's 25 C), a constant or a
    (start, end) ramp over the whole scan of ``passes`` repetitions of the track; the field (magnet and
    background alike) then scales by (1 + a (T - 25)) per axis, a = ``thermal_per_C`` (one value or one per axis,
    1/degC; default the magnet grade's remanence coefficient plus the chip's nominal drift), and the column is the
    chip's reading (quantised to its 1/45.2 C step unless ``ideal``).
    """
    pred = prediction if prediction is not None else predict(design)
    cal = design.spec.calibration
    y, delta = scan_track(design, pred)
    y, delta = np.tile(y, passes), np.tile(delta, passes)
    nominal = pred.curves["nominal"]
    u = np.interp(delta, nominal.indentation_mm, nominal.magnet_displacement_mm)  # axial travel, + down
    fz = np.interp(delta, nominal.indentation_mm, nominal.force_N)
    k_s = pred.shear.stiffness_N_per_mm["nominal"]
    magnet = fieldmod.Magnet.from_design(design)
    gap = design.d_rest_mm - u
    # The sensor at the origin, the magnet's centre at (0, y, gap + H/2): in the magnet's frame the sensing
    # point is at (0, -y, -(gap + H/2)).
    points = np.column_stack([np.zeros_like(y), -y, -(gap + magnet.height_mm / 2.0)])
    b = polarity * fieldmod.exact(magnet, points) * UT_PER_GAUSS + np.asarray(background_uT, float)
    temp = scan_temperature(len(y) // passes, temperature_C, passes)
    if temp is not None:
        a = recipe_coefficient_per_C(design) if thermal_per_C is None else thermal_per_C
        b = b * (1.0 + np.broadcast_to(np.asarray(a, float), (3,))[None, :] * (temp[:, None] - DEFAULT_REFERENCE_C))
    f = np.column_stack([np.zeros_like(y), k_s * y, fz])
    chip = chip_setting(design)
    if not ideal:
        nz = noise(design, chip)
        sigma = UT_PER_GAUSS * np.array([math.sqrt(max(nz[f"total_{a}_G"] ** 2 - nz[f"quantisation_{a}_G"] ** 2, 0.0))
                                     for a in ("xy", "xy", "z")])
        rng = np.random.default_rng(cal.seed)
        b = b + rng.normal(size=b.shape) * sigma
        lsb = np.array([chip.lsb_xy_uT, chip.lsb_xy_uT, chip.lsb_z_uT])
        b = np.round(b / lsb) * lsb
        full = UT_PER_GAUSS * np.array([chip.full_scale_xy_G, chip.full_scale_xy_G, chip.full_scale_z_G])
        b = np.clip(b, -full, full)
        f = _quantise(f, cal.reference_resolution_mN / 1000.0)
        if temp is not None:  # the chip's own reading: whole LSB of the temperature channel
            step = 1.0 / design.chip["temperature_lsb_per_C"].nominal
            temp = _quantise(temp - DEFAULT_REFERENCE_C, step) + DEFAULT_REFERENCE_C
    t = np.arange(len(y)) * chip.conversion_ms / 1000.0
    scan = Scan(t, b, f, temp, "simulated" if not ideal else "simulated (ideal)", "")
    return replace(scan, sha256=hashlib.sha256(scan_csv(scan).encode("utf-8")).hexdigest())
