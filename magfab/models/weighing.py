"""Calibration from a few known weights: the sensor's model fitted to them, then the calibration built from the model.

A weight of m grams resting on the tip, with the board tilted by theta on the weight stand, pushes with
F = m g0 (0, sin theta, cos theta) N in the sensor's frame (+z presses the tip towards the chip; the stand tilts the
board about its x axis so that the weight's downhill pull is along +y). Each weighing is the mean field the chip read
under that load and its spread. From a handful of them (:func:`fit_weights`) the uncertain parameters of the sensor's
own model are fitted, each within its sourced band as a prior:

- ``log_mu``: the silicone's shear modulus, as the log of its ratio to the prediction's nominal (forces scale with it
  at a given indentation, as Curve.scaled); prior the material band (soft .. stiff) as +/- 2 sigma;
- ``log_br``: the magnet's remanence, log ratio to the grade's nominal (the field scales with it); prior the grade's
  band (recipes/magnets.toml) as +/- 2 sigma;
- ``d_mm``: the rest distance's change (the stack-up: pad, pocket roof, glue, Hall point, seating, magnet height);
  prior the acceptance test's terms (:func:`magfab.models.acceptance.tolerance_bands`), root-sum-square, as 2 sigma;
- ``tilt_x_deg``, ``tilt_y_deg``: the magnetisation's tilt off the chip's normal about x and y; prior the acceptance
  test's magnetisation angle plus the pocket's play, as 2 sigma;
- ``offset_x_mm``, ``offset_y_mm``: the magnet's lateral offset from the Hall point; prior the acceptance test's
  summed offsets, as 2 sigma;
- ``shape_1``, ``shape_2``: the normal curve's shape, the force at an indentation being the model's times
  (1 + shape_1 t + shape_2 t^2), t the indentation over the curve's end. The prediction's hyperelastic law is one
  fit of the material's data; another law fitted to the same data bends the curve differently (:data:`SHAPE_SIGMA`);
- ``log_shear``: the shear stiffness's own ratio to the prediction's beyond the shear modulus (the small-strain shear
  model against the large-strain normal one): :data:`SHEAR_SIGMA`;
- one background vector per stand angle: the steady field at the chip that is not the magnet's, the Earth's field
  (which turns with the board) and the chip's offset; prior :data:`BACKGROUND_SIGMA_UT` per axis.

The field is the exact cylinder's (:func:`magfab.models.field.exact`), so the weighings fix the magnet's travel
under each load; the mechanics then needs only the curve from force to travel, which the shape terms let the
weighings correct. The fit is a maximum a posteriori least squares (scipy's ``least_squares``): each reading's
residual over its standard error and the model's own error (:data:`MODEL_ERROR`), each parameter's distance from its
prior over the prior's sigma. The parameters' covariance is the Laplace approximation at the optimum.

From the fitted model the calibration is built as from a scan (:func:`model_scan`: the scan track of
:func:`magfab.models.scan.scan_track`, the model's field at the model's forces, without noise), and its error over
the whole region is predicted from the posterior (:func:`predicted_error`): parameter sets drawn from it, each
taken as the true sensor, the calibration applied to its field with the chip's noise added.

Units: field in uT, force in N, lengths in mm, angles in degrees at the API.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ScanError
from ..formats.scan_csv import Scan, scan_csv
from ..formats.weights_csv import Weighing
from ..units import G0, UT_PER_GAUSS
from . import acceptance
from . import field as fieldmod
from .calibration import fit as calibration_fit
from .calibration import fits_mls
from .chip import chip_setting, noise
from .scan import scan_plan, scan_track
from .weight_plan import (
    ANGLES_DEG,
    MIN_FIRST,
    MIN_TILT_DEG,
    RESKIN_MIN,
    first_weighings,
    reskin_plan,
    stiffness_of,
    weight_plan,
)

if TYPE_CHECKING:
    from ..design import Design
    from .calibration import Calibration
    from .predict import Prediction

__all__ = ["Weighing", "SensorModel", "WeightFit", "PARAMS", "fit_weights", "model_scan", "predicted_error",
           "weight_plan", "load_of", "region_points", "region_errors", "force_errors", "noise_uT",
           "calibration_scan", "ErrorBound", "RESKIN_KEPT", "reskin_plan", "first_weighings", "stiffness_of",
           "stated_error", "weight_fit_of", "ANGLES_DEG", "MIN_FIRST", "checked_fit"]

#: The fitted parameters, in order (module doc); then one background vector per stand angle.
PARAMS = ("log_mu", "log_br", "d_mm", "tilt_x_deg", "tilt_y_deg", "offset_x_mm", "offset_y_mm", "shape_1", "shape_2",
          "log_shear")
#: What a new skin keeps from the sensor's weight calibration of an earlier skin: the magnet's remanence and pose, and
#: the silicone's curve shape and shear ratio (the same product in a new batch); its shear modulus and the rest
#: distance are fitted again (the records' ``reskin`` event, docs/sensors.md).
RESKIN_KEPT = ("log_br", "tilt_x_deg", "tilt_y_deg", "offset_x_mm", "offset_y_mm", "shape_1", "shape_2", "log_shear")
#: The prior sigma of each shape term: the normal curve's force at the end of its indentation may differ from the
#: model's law by this fraction (assumption; the simulated study, bench/weights.py, measures the two laws' difference).
SHAPE_SIGMA = 0.10
#: The prior sigma of the shear stiffness's own log ratio (assumption: the shear model against the normal one).
SHEAR_SIGMA = 0.15
#: The prior sigma of the background field per axis, uT: the Earth's field (25-65 uT in magnitude, NOAA's World
#: Magnetic Model; the acceptance test's bound is 65 uT) plus the chip's offset.
BACKGROUND_SIGMA_UT = 40.0
#: The model's own error on the field change a load makes, as a fraction of that change (the field model is exact;
#: the mechanics' curve is corrected by the shape terms): it keeps the fit from trusting one weighing beyond the model.
MODEL_ERROR = 0.001
#: Cells along each side of the region's grid (:func:`region_points`) each draw is scored on.
REGION_SIDE = 40
#: The model's error the posterior's covariance is taken with (the fit itself weighs the readings by
#: :data:`MODEL_ERROR`): the allowance for the model's form, chiefly the other hyperelastic law's curve between the
#: weighings. Chosen on the simulated study (bench/weights.py: MagOne, sensors 0-29 of seed 0), where 0.001 covered
#: 75 % of the drawn sensors' actual Fz error and 0.003 covered 97 %; checked on other designs and seeds there.
BOUND_MODEL_ERROR = 0.003
#: The largest mean squared residual per reading (in the fit's own error scale) of weighings the model explains; past
#: it the weighings are refused (the wrong sensor, grade, weights or angles): about 5 sigma RMS, against the 0.1-0.6
#: of the simulated study's sensors.
MAX_CHI2 = 25.0
#: The farthest a fitted parameter may sit from its prior's mean, in prior sigmas (the band is 2): past it the
#: sensor is outside its design's bands (a MagOne magnet seated 1 mm high is fitted 8.7 sigma out; an N52 magnet in
#: its N35 design 3.8 sigma, which the acceptance test's rest band then refuses).
MAX_PRIOR_SIGMAS = 4.0
#: How many parameter sets :func:`predicted_error` draws from the posterior.
DRAWS = 64
#: The share of posterior draws whose region RMS the stated error bound covers.
BOUND_QUANTILE = 0.9


def load_of(mass_g: ArrayLike, angle_deg: ArrayLike) -> np.ndarray:
    """The force (Fx, Fy, Fz) in N, (N, 3), of masses in grams resting on the tip on the stand at angles in degrees."""
    m = np.atleast_1d(np.asarray(mass_g, float)) * G0 / 1000.0
    a = np.radians(np.atleast_1d(np.asarray(angle_deg, float)))
    m, a = np.broadcast_arrays(m, a)
    return np.column_stack([np.zeros_like(m), m * np.sin(a), m * np.cos(a)])



@dataclass(frozen=True)
class Prior:
    """Each parameter's prior mean and sigma (in :data:`PARAMS` order) and where its band comes from."""

    mean: np.ndarray
    sigma: np.ndarray
    sources: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class SensorModel:
    """The sensor's model as the fit sees it: the prediction's nominal normal curve (indentation, force, magnet
    travel), its nominal shear stiffness, the magnet, the rest distance and the priors."""

    indentation_mm: np.ndarray
    force_N: np.ndarray
    travel_mm: np.ndarray
    shear_N_per_mm: float
    magnet: fieldmod.Magnet
    d_rest_mm: float
    prior: Prior
    #: The floor of a weighing's standard error per axis, uT: the chip's quantisation (one count over sqrt 12), which a
    #: mean of readings does not average away when the noise is below a count (a quiet chip, a simulated one).
    floor_uT: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def of(cls, design: Design, prediction: Prediction) -> SensorModel:
        """The model of ``design`` from its prediction, with the priors of its tolerance bands (module doc)."""
        curve = prediction.curves["nominal"]
        ok = np.isfinite(curve.force_N) & np.isfinite(curve.magnet_displacement_mm)
        chip = chip_setting(design)
        return cls(np.asarray(curve.indentation_mm, float)[ok], np.asarray(curve.force_N, float)[ok],
                   np.asarray(curve.magnet_displacement_mm, float)[ok],
                   float(prediction.shear.stiffness_N_per_mm["nominal"]), fieldmod.Magnet.from_design(design),
                   float(design.d_rest_mm), _prior(design, prediction),
                   np.array([chip.lsb_xy_uT, chip.lsb_xy_uT, chip.lsb_z_uT]) / math.sqrt(12.0))

    def with_curve(self, indentation_mm: np.ndarray, force_N: np.ndarray, travel_mm: np.ndarray) -> SensorModel:
        """The same sensor with another normal curve (a truth of another law, in the simulated study)."""
        return replace(self, indentation_mm=np.asarray(indentation_mm, float), force_N=np.asarray(force_N, float),
                       travel_mm=np.asarray(travel_mm, float))

    # ---- the forward model ----

    def normal_force(self, theta: np.ndarray, indentation_mm: np.ndarray) -> np.ndarray:
        """Fz (N) at each indentation under parameters ``theta``."""
        t = np.asarray(indentation_mm, float) / self.indentation_mm[-1]
        f = np.interp(indentation_mm, self.indentation_mm, self.force_N)
        return math.exp(theta[0]) * f * (1.0 + theta[7] * t + theta[8] * t * t)

    def shear_stiffness(self, theta: np.ndarray) -> float:
        return self.shear_N_per_mm * math.exp(theta[0] + theta[9])

    def indentation_of(self, theta: np.ndarray, fz_N: np.ndarray) -> np.ndarray:
        """The indentation at each normal force (the curve inverted on a fine grid; NaN past its end)."""
        grid = np.linspace(0.0, self.indentation_mm[-1], 801)
        f = self.normal_force(theta, grid)
        f = np.maximum.accumulate(f)  # a shape term cannot make the curve turn back: held flat where it would
        fz = np.asarray(fz_N, float)
        out = np.interp(fz, f, grid)
        return np.where((fz < 0.0) | (fz > f[-1]), np.nan, out)

    def field_at(self, theta: np.ndarray, indentation_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
        """The magnet's field at the chip, uT (N, 3), with the tip indented by ``indentation_mm`` and moved by
        ``y_mm`` along +y (as :func:`magfab.models.scan.simulate_scan`), under ``theta`` (background not added)."""
        u = np.interp(indentation_mm, self.indentation_mm, self.travel_mm)
        gap = self.d_rest_mm + theta[2] - u
        magnet = replace(self.magnet, remanence_T=self.magnet.remanence_T * math.exp(theta[1]))
        h = magnet.height_mm
        # the sensor relative to the magnet's centre, in the chip's frame, then in the tilted magnet's frame
        rel = np.column_stack([np.full_like(gap, -theta[5]), -(np.asarray(y_mm, float) + theta[6]), -(gap + h / 2.0)])
        rot = _rotation(math.radians(theta[3]), math.radians(theta[4]))
        b = np.full(rel.shape, np.nan)
        ok = np.isfinite(rel).all(axis=1)  # an indentation past the curve's end has no field
        b[ok] = fieldmod.exact(magnet, rel[ok] @ rot) @ rot.T  # rot^T p for each row; the field turned back
        return b * UT_PER_GAUSS

    def predict(self, theta: np.ndarray, mass_g: np.ndarray, angle_deg: np.ndarray, angles: Sequence[float]
                ) -> np.ndarray:
        """The field each weighing reads (uT, (N, 3)) under ``theta``, its background that of its stand angle (the
        order of ``angles``)."""
        f = load_of(mass_g, angle_deg)
        delta = self.indentation_of(theta, f[:, 2])
        y = f[:, 1] / self.shear_stiffness(theta)
        b = self.field_at(theta, delta, y)
        k = np.array([list(angles).index(a) for a in np.asarray(angle_deg, float)])
        bg = np.asarray(theta[len(PARAMS):], float).reshape(len(angles), 3)
        return b + bg[k]


def _rotation(ax: float, ay: float) -> np.ndarray:
    """The magnet's orientation: turned by ``ax`` about x, then by ``ay`` about y (radians)."""
    cx, sx, cy, sy = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    return ry @ rx


def _prior(design: Design, prediction: Prediction) -> Prior:
    """The priors (module doc) from the acceptance test's tolerance bands and the prediction's material band."""
    bands = acceptance.tolerance_bands(design, prediction)
    mu = prediction.curves
    soft, stiff = float(mu["soft"].mu_kPa), float(mu["stiff"].mu_kPa)
    nominal = float(mu["nominal"].mu_kPa)
    br_lo, br_hi, br_nom = bands["remanence_T"]
    mean = np.array([math.log(math.sqrt(soft * stiff) / nominal), math.log(math.sqrt(br_lo * br_hi) / br_nom),
                     bands["rest_distance_mm"][0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    sigma = np.array([math.log(stiff / soft) / 4.0, max(math.log(br_hi / br_lo) / 4.0, 1e-3),
                      max(bands["rest_distance_mm"][1] / 2.0, 1e-3), bands["tilt_deg"] / 2.0, bands["tilt_deg"] / 2.0,
                      bands["offset_mm"] / 2.0, bands["offset_mm"] / 2.0, SHAPE_SIGMA, SHAPE_SIGMA, SHEAR_SIGMA])
    sources = {
        "log_mu": f"the material band {soft:.4g}-{stiff:.4g} kPa (recipes/materials.toml) as +/- 2 sigma",
        "log_br": f"the grade's remanence {br_lo:.4g}-{br_hi:.4g} T (recipes/magnets.toml) as +/- 2 sigma",
        "d_mm": "the acceptance test's stack-up of the rest distance, root-sum-square, as 2 sigma",
        **dict.fromkeys(("tilt_x_deg", "tilt_y_deg"),
                        "the acceptance test's magnetisation angle and pocket play, as 2 sigma"),
        **dict.fromkeys(("offset_x_mm", "offset_y_mm"), "the acceptance test's summed lateral offsets, as 2 sigma"),
        **dict.fromkeys(("shape_1", "shape_2"),
                        f"assumption: the normal curve's shape within {SHAPE_SIGMA:.0%} (SHAPE_SIGMA)"),
        "log_shear": f"assumption: the shear stiffness within {SHEAR_SIGMA:.0%} of the model's (SHEAR_SIGMA)",
    }
    return Prior(mean, sigma, sources)


@dataclass(frozen=True)
class WeightFit:
    """The fitted parameters (:data:`PARAMS` then the backgrounds of ``angles``), their covariance, and how well the
    weighings agree with the fitted model (``chi2`` per reading, 1 when they agree within their errors)."""

    theta: np.ndarray
    covariance: np.ndarray
    angles: tuple[float, ...]
    chi2: float
    residual_uT: np.ndarray

    def named(self) -> dict[str, dict[str, float]]:
        """Each model parameter's value and standard deviation, in its unit (the log ratios as ratios)."""
        out: dict[str, dict[str, float]] = {}
        sd = np.sqrt(np.diag(self.covariance))
        for i, name in enumerate(PARAMS):
            v, s = float(self.theta[i]), float(sd[i])
            if name.startswith("log_"):
                out[name[4:] + "_ratio"] = {"value": math.exp(v), "sd": math.exp(v) * s}
            else:
                out[name] = {"value": v, "sd": s}
        return out


def fit_weights(model: SensorModel, weighings: Sequence[Weighing], *, fixed: Mapping[str, float] | None = None
                ) -> WeightFit:
    """The maximum a posteriori parameters for ``weighings`` (module doc). ``fixed``: parameters held at a value
    (a re-skin keeps an earlier fit's magnet and board: :data:`PARAMS` names)."""
    from scipy.optimize import least_squares  # lazy: scipy is slow to import

    fixed = dict(fixed or {})
    angles = tuple(sorted({float(w.angle_deg) for w in weighings}))
    mass = np.array([w.mass_g for w in weighings], float)
    angle = np.array([w.angle_deg for w in weighings], float)
    measured = np.array([w.field_uT for w in weighings], float)
    se = np.hypot(np.array([w.standard_error_uT for w in weighings], float), model.floor_uT)
    n_all = len(PARAMS) + 3 * len(angles)
    mean = np.concatenate([model.prior.mean, np.zeros(3 * len(angles))])
    sigma = np.concatenate([model.prior.sigma, np.full(3 * len(angles), BACKGROUND_SIGMA_UT)])
    free = [i for i in range(n_all) if i >= len(PARAMS) or PARAMS[i] not in fixed]
    base = mean.copy()
    for name, value in fixed.items():
        base[PARAMS.index(name)] = value

    def full(x: np.ndarray) -> np.ndarray:
        theta = base.copy()
        theta[free] = x
        return theta

    def residuals(x: np.ndarray, error: float = MODEL_ERROR) -> np.ndarray:
        theta = full(x)
        b = model.predict(theta, mass, angle, angles)
        rest = model.field_at(theta, np.zeros(1), np.zeros(1))  # the model's error scales with the change from rest
        scale = np.sqrt(se ** 2 + (error * np.abs(b - rest)) ** 2 + 1e-6)
        r = (b - measured) / scale
        r = np.where(np.isfinite(r), r, 1e3)  # a load past the curve's end: far off
        return np.concatenate([r.ravel(), (x - mean[free]) / sigma[free]])

    x0 = mean[free].copy()
    sol = least_squares(residuals, x0, method="trf", x_scale=sigma[free], diff_step=1e-6)
    # the covariance with the model-form allowance (BOUND_MODEL_ERROR), at the optimum
    jac = least_squares(lambda x: residuals(x, BOUND_MODEL_ERROR), sol.x, method="trf", x_scale=sigma[free],
                        diff_step=1e-6, max_nfev=1).jac
    try:
        cov_free = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        cov_free = np.linalg.pinv(jac.T @ jac)
    cov = np.zeros((n_all, n_all))
    cov[np.ix_(free, free)] = cov_free
    theta = full(sol.x)
    b = model.predict(theta, mass, angle, angles)
    r = sol.fun[:measured.size]
    return WeightFit(theta, cov, angles, float(np.mean(r ** 2)), b - measured)


def model_scan(model: SensorModel, fit: WeightFit, design: Design, prediction: Prediction) -> Scan:
    """The scan the fitted model predicts along the scan track (no noise): the field at the chip (the stand's
    0-degree background added, as the sensor reads in use) and the model's forces."""
    theta = fit.theta
    y, delta = scan_track(design, prediction)
    b = model.field_at(theta, delta, y) + _background(theta, fit.angles, 0.0)
    f = np.column_stack([np.zeros_like(y), model.shear_stiffness(theta) * y, model.normal_force(theta, delta)])
    t = np.arange(len(y)) * chip_setting(design).conversion_ms / 1000.0
    return Scan(t, b, f, None, "weights model", "")


def _background(theta: np.ndarray, angles: Sequence[float], angle: float) -> np.ndarray:
    """The background vector of ``theta`` at the stand angle of ``angles`` nearest ``angle``."""
    bg = theta[len(PARAMS):].reshape(len(angles), 3)
    return bg[int(np.argmin(np.abs(np.asarray(angles) - angle)))]


def noise_uT(design: Design) -> np.ndarray:
    """The chip's RMS field noise per axis at the design's settings, uT."""
    nz = noise(design, chip_setting(design))
    return UT_PER_GAUSS * np.array([nz["total_xy_G"], nz["total_xy_G"], nz["total_z_G"]])


@dataclass(frozen=True)
class ErrorBound:
    """The calibration's predicted error over the region: the RMS of Fz and of the shear at the median and at the
    :data:`BOUND_QUANTILE` of the posterior's draws, N."""

    fz_rms_N: tuple[float, float]
    shear_rms_N: tuple[float, float]
    draws: int


def region_points(design: Design, prediction: Prediction, side: int = REGION_SIDE) -> tuple[np.ndarray, np.ndarray]:
    """The region the scan track spans as (indentation, y), at the centres of a ``side`` x ``side`` grid of cells
    over it: dense, the same every time, and off the track's own points (which step from its edges)."""
    plan = scan_plan(design, prediction)
    centres = (np.arange(side) + 0.5) / side
    dd, yy = np.meshgrid(centres * plan.depth_mm, (2.0 * centres - 1.0) * plan.y_half_mm, indexing="ij")
    return dd.ravel(), yy.ravel()


def force_errors(calibration: Calibration, b: np.ndarray, f: np.ndarray, rest: np.ndarray) -> dict[str, float]:
    """Fz and shear RMS and worst error (N) of ``calibration`` on readings ``b`` (uT) of true forces ``f`` (N), tared
    at the readings ``rest`` as the readout tares."""
    got, _ = calibration.zeroed(rest).evaluate(b)
    ez = got[:, 2] - f[:, 2]
    es = np.hypot(got[:, 0] - f[:, 0], got[:, 1] - f[:, 1])
    return {"fz_rms_N": float(np.sqrt(np.mean(ez ** 2))), "fz_worst_N": float(np.max(np.abs(ez))),
            "shear_rms_N": float(np.sqrt(np.mean(es ** 2))), "shear_worst_N": float(np.max(es))}


def region_errors(model: SensorModel, theta: np.ndarray, background_uT: np.ndarray, calibration: Calibration,
                  points: tuple[np.ndarray, np.ndarray], noise: np.ndarray | None, rng: np.random.Generator
                  ) -> dict[str, float]:
    """:func:`force_errors` of ``calibration`` at ``points`` (indentation, y) on the sensor ``theta`` (the chip's
    ``noise`` added when given)."""
    delta, y = points
    b = model.field_at(theta, delta, y) + background_uT
    if noise is not None:
        b = b + rng.standard_normal(b.shape) * noise
    f = np.column_stack([np.zeros_like(y), model.shear_stiffness(theta) * y, model.normal_force(theta, delta)])
    return force_errors(calibration, b, f, model.field_at(theta, np.zeros(1), np.zeros(1)) + background_uT)


def predicted_error(model: SensorModel, fit: WeightFit, calibration: Calibration, design: Design,
                    prediction: Prediction, *, draws: int = DRAWS, seed: int = 0) -> ErrorBound:
    """The calibration's error over the region predicted from the posterior (module doc)."""
    rng = np.random.default_rng(seed)
    chol = _sqrt_psd(fit.covariance)
    points = region_points(design, prediction)
    noise = noise_uT(design)
    ez, es = [], []
    for _ in range(draws):
        theta = fit.theta + chol @ rng.standard_normal(len(fit.theta))
        err = region_errors(model, theta, _background(theta, fit.angles, 0.0), calibration, points, noise, rng)
        ez.append(err["fz_rms_N"])
        es.append(err["shear_rms_N"])
    q = BOUND_QUANTILE
    return ErrorBound((float(np.median(ez)), float(np.quantile(ez, q))),
                      (float(np.median(es)), float(np.quantile(es, q))), draws)


def _sqrt_psd(cov: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh((cov + cov.T) / 2.0)
    return v * np.sqrt(np.clip(w, 0.0, None))


def calibration_scan(design: Design, prediction: Prediction, weighings: Sequence[Weighing], *,
                     fixed: Mapping[str, float] | None = None, source: str = "weighings", sha256: str = ""
                     ) -> tuple[Scan, WeightFit, ErrorBound]:
    """The scan a weight calibration is fitted to (:func:`model_scan` of the model fitted to ``weighings``), carrying
    in ``Scan.model`` the fit (each parameter's value and standard deviation, the kept ones named) and the
    calibration's predicted error over the region (:func:`predicted_error`, of the calibration the build fits to
    this scan); ``source`` and ``sha256`` name the weighings file."""
    model = SensorModel.of(design, prediction)
    _check_coverage(weighings, fixed, source)
    fit = checked_fit(model, weighings, fixed=fixed, source=source)
    scan = model_scan(model, fit, design, prediction)
    cal = calibration_fit(scan, design, mls=fits_mls(design)).calibration  # as the build will fit it
    bound = predicted_error(model, fit, cal, design, prediction)
    info = {
        "basis": "weights: the sensor's model fitted to known weights (magfab.models.weighing), the calibration "
                 "fitted to the model's scan",
        "weighings": len(weighings), "weighings_sha256": sha256, "chi2_per_reading": round(fit.chi2, 4),
        "theta": {name: round(float(fit.theta[i]), 8) for i, name in enumerate(PARAMS)},
        "parameters": {k: {"value": round(v["value"], 6), "sd": round(v["sd"], 6)} for k, v in fit.named().items()},
        "kept": sorted(fixed or {}),
        "priors": {name: {"mean": round(float(model.prior.mean[i]), 8), "sigma": round(float(model.prior.sigma[i]), 8),
                          "source": model.prior.sources[name]} for i, name in enumerate(PARAMS)},
        "predicted_error_mN": {
            "Fz_rms": {"median": round(1000 * bound.fz_rms_N[0], 2), "p90": round(1000 * bound.fz_rms_N[1], 2)},
            "shear_rms": {"median": round(1000 * bound.shear_rms_N[0], 2),
                          "p90": round(1000 * bound.shear_rms_N[1], 2)},
            "note": f"over the scan region, from {bound.draws} parameter sets drawn from the fit's posterior, the "
                    "chip's noise added; p90: 9 in 10 draws are within it",
        },
    }
    scan = replace(scan, source=f"{source} (weight calibration, {len(weighings)} weighings)", model=info)
    return replace(scan, sha256=hashlib.sha256(scan_csv(scan).encode("utf-8")).hexdigest()), fit, bound


def checked_fit(model: SensorModel, weighings: Sequence[Weighing], *, fixed: Mapping[str, float] | None = None,
                source: str = "weighings") -> WeightFit:
    """:func:`fit_weights`, refused (:class:`ScanError`, one line naming ``source``) for a load no skin of the design
    carries, weighings the fitted model does not explain (:data:`MAX_CHI2`) and a parameter fitted outside its band
    (:data:`MAX_PRIOR_SIGMAS`)."""
    _check_loads(model, weighings, source)
    fit = fit_weights(model, weighings, fixed=fixed)
    if not fit.chi2 <= MAX_CHI2:
        worst = int(np.argmax(np.abs(fit.residual_uT).max(axis=1)))
        raise ScanError(f"{source}: the weighings do not fit this design's model (mean squared residual "
                        f"{fit.chi2:.3g} per reading, at most {MAX_CHI2:g}; worst: weighing {worst + 1}, "
                        f"{weighings[worst].mass_g:g} g at {weighings[worst].angle_deg:g} deg, off by "
                        f"{np.abs(fit.residual_uT[worst]).max():.0f} uT): the wrong sensor, magnet grade, masses or "
                        "angles")
    _check_bands(model, fit, source)
    return fit


def _check_loads(model: SensorModel, weighings: Sequence[Weighing], source: str) -> None:
    """ScanError for a weighing whose normal load is past the end of the stiffest skin's normal curve (the material
    band's stiff end): no skin of this design could have carried it."""
    stiffest = model.force_N[-1] * math.exp(model.prior.mean[0] + 2.0 * model.prior.sigma[0])
    fz = load_of([w.mass_g for w in weighings], [w.angle_deg for w in weighings])[:, 2]
    over = np.nonzero(fz > stiffest)[0]
    if over.size:
        k, w = int(over[0]), weighings[int(over[0])]
        raise ScanError(f"{source}: weighing {k + 1}, {w.mass_g:g} g at {w.angle_deg:g} deg, pushes {fz[k]:.3g} N; "
                        f"this design's stiffest skin carries at most {stiffest:.3g} N over its calibrated depth "
                        "(docs/models.md, M25: the plan's weights)")


def _check_coverage(weighings: Sequence[Weighing], fixed: Mapping[str, float] | None, source: str) -> None:
    """ScanError for weighings that cannot give the fit what it takes, counting distinct loads (a weighing repeated
    adds none): a first calibration (nothing kept from an earlier skin) of fewer than :data:`MIN_FIRST` loads or none
    on a stand tilted :data:`MIN_TILT_DEG` or more (the shear cannot be told from the normal); a new skin of fewer
    than :data:`RESKIN_MIN`."""
    loads = {(round(w.mass_g, 3), w.angle_deg) for w in weighings}
    if fixed:
        if len(loads) < RESKIN_MIN:
            raise ScanError(f"{source}: {len(weighings)} weighings of {len(loads)} distinct loads: a new skin needs at "
                            f"least {RESKIN_MIN} (the cap alone and the heaviest weight flat, the heaviest on the "
                            "steepest stand)")
        return
    tilted = sum(1 for _, angle in loads if angle >= MIN_TILT_DEG)
    if len(loads) < MIN_FIRST or not tilted:
        raise ScanError(f"{source}: {len(weighings)} weighings of {len(loads)} distinct loads, {tilted} of them on a "
                        f"stand tilted {MIN_TILT_DEG:g} deg or more: a first weight calibration needs at least "
                        f"{MIN_FIRST}, one or more of them tilted that far (the build's plan, calibration/"
                        f"weigh_plan.json); {RESKIN_MIN} do for a new skin on a board whose record keeps a weight "
                        "calibration")


def _check_bands(model: SensorModel, fit: WeightFit, source: str) -> None:
    """ScanError when a fitted parameter is more than :data:`MAX_PRIOR_SIGMAS` of its prior from the band's centre."""
    z = (fit.theta[:len(PARAMS)] - model.prior.mean) / model.prior.sigma
    k = int(np.argmax(np.abs(z)))
    if abs(z[k]) > MAX_PRIOR_SIGMAS:
        lo, hi = model.prior.mean[k] - 2 * model.prior.sigma[k], model.prior.mean[k] + 2 * model.prior.sigma[k]
        raise ScanError(f"{source}: the weighings fit {PARAMS[k]} = {fit.theta[k]:.3g}, {abs(z[k]):.1f} sigma from its "
                        f"band {lo:.3g} to {hi:.3g} (at most {MAX_PRIOR_SIGMAS:g}): the wrong sensor or magnet grade, "
                        "or a misassembled sensor")


def weight_fit_of(calibration_json: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """A weight calibration's fit, as calibration.json keeps it (``scan.model``, :func:`calibration_scan`); None for a
    calibration fitted to a scan (or a document that holds no such object)."""
    scan = calibration_json.get("scan")
    model = scan.get("model") if isinstance(scan, Mapping) else None
    return model if isinstance(model, Mapping) else None


def stated_error(calibration_json: Mapping[str, Any]) -> dict[str, float]:
    """A weight calibration's predicted error over the region (the p90 of :func:`calibration_scan`'s bound), mN, as
    ``predicted_error_Fz_mN`` and ``predicted_error_shear_mN``; nothing for a calibration fitted to a scan."""
    err = (weight_fit_of(calibration_json) or {}).get("predicted_error_mN")
    if not isinstance(err, Mapping):
        return {}
    return {"predicted_error_Fz_mN": float(err["Fz_rms"]["p90"]),
            "predicted_error_shear_mN": float(err["shear_rms"]["p90"])}
