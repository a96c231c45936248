"""The weight calibration tried on simulated sensors whose truth is not the fitted model (bench/weights.py).

Each drawn sensor (:func:`draw_sensor`) takes its parameters from the same bands the fit's priors come from
(:mod:`.weighing`), and its response from a model the fit does not use:

- the normal curve of the *other* hyperelastic law of the same silicone fitted to the same sourced data (the
  prediction's law is Yeoh where recipes/materials.toml fits one: the truth is then neo-Hookean, and the reverse),
  scaled by the drawn shear modulus; its shear stiffness is that law's prediction's too;
- the magnet tilted and offset by the drawn amounts (the fit has these as parameters, within their priors);
- the Earth's field as a vector of 25-65 uT in the lab, turning with the board on the stand, and a chip offset;
- the chip's noise on every reading (the prediction's RMS per axis), averaged over a weighing's samples.

Against it (:func:`trial`): the weight calibration (the plan of :func:`magfab.models.weighing.weight_plan`), a
full-scan calibration of the same sensor (its scan along the track with the chip's noise and the reference's
resolution, fitted by :func:`magfab.models.calibration.fit` as a real scan is), and for a re-skin a new skin of
the same sensor (a new shear modulus and rest distance) calibrated from three weighings with the magnet's
parameters kept from the first fit. Each calibration is then scored on held-out points drawn uniformly over the
region (not the track's points), with the chip's noise: RMS and worst of Fz and of the shear.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..design import derive
from ..formats.scan_csv import Scan
from ..spec import MaterialLawChoice
from . import calibration as calmod
from .predict import law_in_force, predict
from .scan import scan_track
from .weighing import (
    PARAMS,
    RESKIN_KEPT,
    SensorModel,
    Weighing,
    WeightFit,
    first_weighings,
    fit_weights,
    force_errors,
    load_of,
    model_scan,
    noise_uT,
    predicted_error,
    region_points,
    reskin_plan,
    stiffness_of,
    weight_plan,
)
from .weight_plan import over_softest

if TYPE_CHECKING:
    from ..design import Design
    from .calibration import Calibration
    from .predict import Prediction

__all__ = ["Truth", "draw_sensor", "trial", "TrialResult", "truth_model"]

#: Readings averaged per weighing (half a second at the chip's ~540 Hz).
SAMPLES = 250
#: The Earth's field's magnitude in the lab, uT (NOAA World Magnetic Model: 25-65 uT over the globe).
EARTH_UT = (25.0, 65.0)
#: The chip's zero-field offset, sigma per axis, uT (assumption: of the order of the offset's thermal drift band).
CHIP_OFFSET_UT = 10.0
#: The cap's mass on the tip, g (the weight jig's cap, printed).
CAP_G = 5.0


@dataclass(frozen=True)
class Truth:
    """A drawn sensor: its model (the other law's curve), parameters (:data:`PARAMS`), the Earth's field in the
    lab and the chip's offset (uT)."""

    model: SensorModel
    theta: np.ndarray
    earth_uT: np.ndarray
    offset_uT: np.ndarray

    def background(self, angle_deg: float) -> np.ndarray:
        """The field at the chip not the magnet's, with the board tilted by ``angle_deg`` about x on the stand."""
        a = math.radians(angle_deg)
        rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), math.sin(a)], [0.0, -math.sin(a), math.cos(a)]])
        return rx @ self.earth_uT + self.offset_uT

    def field(self, indentation_mm: np.ndarray, y_mm: np.ndarray, angle_deg: float = 0.0) -> np.ndarray:
        return self.model.field_at(self.theta, indentation_mm, y_mm) + self.background(angle_deg)

    def reading(self, mass_g: float, angle_deg: float) -> np.ndarray:
        """The field (uT, (3,), no noise) with ``mass_g`` resting on the tip and the board at ``angle_deg``."""
        f = load_of(mass_g, angle_deg)
        delta = self.model.indentation_of(self.theta, f[:, 2])
        return self.field(delta, f[:, 1] / self.model.shear_stiffness(self.theta), angle_deg)[0]

    def reskinned(self, rng: np.random.Generator) -> Truth:
        """The same board and magnet under a new skin: a new silicone batch and rest distance drawn across their
        bands, the magnet's parameters kept."""
        new = replace(self, theta=self.theta.copy())
        for name in ("log_mu", "d_mm"):
            i = PARAMS.index(name)
            new.theta[i] = self.model.prior.mean[i] + self.model.prior.sigma[i] * rng.uniform(-2.0, 2.0)
        return new


def truth_model(design: Design, prediction: Prediction, model: SensorModel,
                other: Prediction | None = None) -> SensorModel:
    """The fitted model with the other hyperelastic law's nominal curve and shear stiffness (module doc); ``other``:
    the design's prediction under that law, when the caller has it."""
    p = other if other is not None else predict(other_law(design))
    c = p.curves["nominal"]
    ok = np.isfinite(c.force_N) & np.isfinite(c.magnet_displacement_mm)
    # rescaled to the fitted law's nominal shear modulus: a drawn ratio means the same silicone batch under either law
    scale = c.mu_kPa / float(prediction.curves["nominal"].mu_kPa)
    return replace(model.with_curve(np.asarray(c.indentation_mm)[ok], np.asarray(c.force_N)[ok] / scale,
                                    np.asarray(c.magnet_displacement_mm)[ok]),
                   shear_N_per_mm=float(p.shear.stiffness_N_per_mm["nominal"]) / scale)


def other_law(design: Design) -> Design:
    """``design`` under the other hyperelastic law (neo-Hookean where the prediction's is Yeoh, and the reverse)."""
    other = MaterialLawChoice.NEO_HOOKEAN if law_in_force(design).value == "yeoh" else MaterialLawChoice.YEOH
    return derive(design.spec.model_copy(update={"predict": design.spec.predict.model_copy(
        update={"material_law": other})}))


def draw_sensor(model: SensorModel, truth: SensorModel, rng: np.random.Generator, centred: bool = False) -> Truth:
    """A sensor drawn uniformly across the bands the priors are made from (each prior's +/- 2 sigma, module doc);
    the shape and shear terms are the other law's, not drawn. ``centred``: the magnet on the chip's axis, untilted."""
    theta = model.prior.mean + model.prior.sigma * rng.uniform(-2.0, 2.0, len(PARAMS))  # across each band
    theta[[7, 8, 9]] = 0.0
    if centred:
        theta[[3, 4, 5, 6]] = 0.0
    direction = rng.standard_normal(3)
    earth = direction / np.linalg.norm(direction) * rng.uniform(*EARTH_UT)
    return Truth(truth, theta, earth, rng.normal(0.0, CHIP_OFFSET_UT, 3))


def weighings(sensor: Truth, plan: Sequence[tuple[float, float]], noise: np.ndarray, rng: np.random.Generator,
              samples: int = SAMPLES) -> list[Weighing]:
    """What the bench records for ``plan`` on ``sensor``: each weighing's mean over ``samples`` noisy readings."""
    out = []
    for mass, angle in plan:
        mean = sensor.reading(mass, angle) + rng.standard_normal(3) * noise / math.sqrt(samples)
        out.append(Weighing(mass, angle, (float(mean[0]), float(mean[1]), float(mean[2])),
                            (float(noise[0]), float(noise[1]), float(noise[2])), samples))
    return out


def full_scan(sensor: Truth, design: Design, prediction: Prediction, noise: np.ndarray,
              rng: np.random.Generator) -> Scan:
    """The sensor's scan along the track, as a bench with a force sensor records it: the chip's noise on the field,
    the reference's resolution on the forces."""
    y, delta = scan_track(design, prediction)
    m, th = sensor.model, sensor.theta
    b = sensor.field(delta, y) + rng.standard_normal((len(y), 3)) * noise
    f = np.column_stack([np.zeros_like(y), m.shear_stiffness(th) * y, m.normal_force(th, delta)])
    step = design.spec.calibration.reference_resolution_mN / 1000.0
    f = np.round(f / step) * step
    return Scan(np.arange(len(y)) * 1e-3, b, f, None, "simulated truth", "")


def held_out(sensor: Truth, design: Design, prediction: Prediction, noise: np.ndarray, rng: np.random.Generator
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The held-out points: the region's grid (:func:`magfab.models.weighing.region_points`, off the track's points),
    as (field read with noise, true force, field at rest)."""
    delta, y = region_points(design, prediction)
    m, th = sensor.model, sensor.theta
    b = sensor.field(delta, y) + rng.standard_normal((len(y), 3)) * noise
    f = np.column_stack([np.zeros(len(y)), m.shear_stiffness(th) * y, m.normal_force(th, delta)])
    return b, f, sensor.field(np.zeros(1), np.zeros(1))


@dataclass(frozen=True)
class TrialResult:
    """One drawn sensor's errors: the weight calibration's, the full scan's, the re-skin's (and the re-skin's full
    scan), the weight calibration's predicted bound (Fz RMS at the bound's quantile) and its fit."""

    weights: dict[str, float]
    full: dict[str, float]
    reskin: dict[str, float]
    reskin_full: dict[str, float]
    bound_fz_rms_N: float
    bound_shear_rms_N: float
    fit: WeightFit
    sensor: Truth
    reach: float  # the plan's heaviest normal load over the drawn skin's normal range (:func:`_reach`)


def _calibrate(scan: Scan, design: Design) -> Calibration:
    return calmod.fit(scan, design, mls=False).calibration


def trial(design: Design, prediction: Prediction, model: SensorModel, truth: SensorModel, rng: np.random.Generator,
          *, centred: bool = False, plan_of: Callable[[float], Sequence[tuple[float, float]]] | None = None,
          adaptive: bool = True) -> TrialResult:
    """One drawn sensor (:func:`draw_sensor`) through both calibrations and a re-skin (module doc). ``plan_of``: the
    plan for a skin of a given stiffness over the softest (:func:`magfab.jig.jig_plans`: the weight jig's coins;
    default the standard 1-2-5 weights on a :data:`CAP_G` cap). ``adaptive``: the first two weighings of the
    softest skin's plan (:func:`~magfab.models.weight_plan.first_weighings`) are fitted, and the plan is the one for
    the stiffness they give (:func:`~magfab.models.weight_plan.stiffness_of`), as the two-stage bench makes it;
    without, the plan is the softest skin's. A new skin's three weighings are the softest skin's plan's re-skin steps
    (safe for any skin)."""
    noise = noise_uT(design)
    sensor = draw_sensor(model, truth, rng, centred)
    plans = plan_of or (lambda stiffness: weight_plan(prediction, CAP_G, stiffness))

    soft = list(plans(1.0))
    plan = soft
    if adaptive:
        first = weighings(sensor, first_weighings(soft), noise, rng)
        plan = list(plans(stiffness_of(fit_weights(model, first), model, prediction)))
    fit = fit_weights(model, weighings(sensor, plan, noise, rng))
    cal_w = _calibrate(model_scan(model, fit, design, prediction), design)
    cal_f = _calibrate(full_scan(sensor, design, prediction, noise, rng), design)
    bound = predicted_error(model, fit, cal_w, design, prediction, seed=int(rng.integers(2**31)))
    test = held_out(sensor, design, prediction, noise, rng)
    new = sensor.reskinned(rng)  # a new skin on the same board and magnet
    kept = {name: float(fit.theta[PARAMS.index(name)]) for name in RESKIN_KEPT}
    refit = fit_weights(model, weighings(new, reskin_plan(soft), noise, rng), fixed=kept)
    cal_r = _calibrate(model_scan(model, refit, design, prediction), design)
    cal_rf = _calibrate(full_scan(new, design, prediction, noise, rng), design)
    test_r = held_out(new, design, prediction, noise, rng)
    return TrialResult(force_errors(cal_w, *test), force_errors(cal_f, *test), force_errors(cal_r, *test_r),
                       force_errors(cal_rf, *test_r), bound.fz_rms_N[1], bound.shear_rms_N[1], fit, sensor,
                       _reach(sensor, plan, prediction))


def _reach(sensor: Truth, plan: Sequence[tuple[float, float]], prediction: Prediction) -> float:
    """The plan's heaviest normal load over the drawn skin's normal range (the softest skin's, times the skin's
    stiffness over the softest): past 1 the plan would press the skin past its range."""
    stiffness = over_softest(float(sensor.theta[0]), prediction)
    fz = load_of([m for m, _ in plan], [a for _, a in plan])[:, 2]
    return float(fz.max() / (stiffness * prediction.normal.range_N))
