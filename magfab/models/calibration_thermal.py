"""The calibration's temperature correction: the field read at T is divided by (1 + a (T - T0)) per axis before
the force calibration (calibration.json ``thermal``, docs/bundle.md section 2; the firmware does the same).

**The model.** The magnet's field at a fixed pose is linear in its magnetisation (magnetostatics), so the
remanence's temperature coefficient (recipes/magnets.toml ``br_temperature_coefficient_pct_per_C``, -0.12 %/C
for NdFeB) scales the whole field vector by one factor, whatever the load; the chip's sensitivity drift
(recipes/chips.toml ``sensitivity_drift_pct``, nominal 0) is a gain per axis (the x and y plates and the z
reading differ). Together B_read(T) = B(T0) (1 + a_k (T - T0)) on axis k: one term per axis. The linear form is
what the two datasheets give (a coefficient per degree); over a 25 C excursion |a dT| is 3 % and the magnet's
own curvature is below that squared. The elastomer's stiffness change with temperature is not modelled (it moves
the force, not the field, and the scan's forces absorb it at T0 only).

**The fit.** When the scan's ``temperature_C`` spans at least :data:`MIN_SPAN_C`, (a_xy, a_z) are found with
the force polynomial by variable projection: for each trial a, the fields are corrected, the order-n polynomial
is solved by least squares for Fz and Fr, and scipy's ``least_squares`` moves a to the least force residual. The
x and y axes share one coefficient: the scan's lateral load changes Br only, and the chip's x and y plates are
alike (one sensitivity in the datasheet). The uncertainty is the usual s^2 (J^T J)^-1 of that projected problem
combined with the change of a from order n to n + 1 (the force map's own model error).
The temperature must not follow the scan's position alone: a single pass whose temperature ramps row by row is
absorbed by the polynomial (the force map bends instead, and a comes out wrong with a small s^2 (J^T J)^-1);
scanning twice, cold and warm, separates them. So the part of the temperature the field's polynomial cannot
explain must reach :data:`MIN_INDEPENDENT_C` (RMS), and the uncertainty must stay below the recipe's magnitude;
otherwise the recipe values are used and the note says why.
Without a temperature column, or with a smaller span, the recipe values are used with T0 the scan's mean
temperature, or :data:`DEFAULT_REFERENCE_C` (the simulated scan's and the chip's reference) when it has none.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..formats import calibration_json, json_checks
from ..formats.calibration_json import AXES

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["MIN_SPAN_C", "MIN_INDEPENDENT_C", "DEFAULT_REFERENCE_C", "ThermalFit", "recipe_coefficient_per_C",
           "fit_thermal", "correct", "thermal_from_json"]

#: Least temperature span, degC, a scan needs before its coefficients are fitted: a few degrees, twice the
#: chip's temperature noise band; below it the force residual cannot see a 0.1 %/C drift.
MIN_SPAN_C = 4.0
#: Least RMS of the scan's temperature left once the field's polynomial has explained what it can, degC: a quarter
#: of :data:`MIN_SPAN_C`. A single warming pass leaves ~0.2 C (the temperature is a function of the position), a
#: scan repeated cold and warm ~3.8 C (MagOne, 15 C).
MIN_INDEPENDENT_C = 1.0
#: The calibration's temperature when the scan has none: the chip's own reference (datasheet Table 7, T25) and the
#: simulated scan's (the magnet's model remanence).
DEFAULT_REFERENCE_C = 25.0


@dataclass(frozen=True)
class ThermalFit:
    """The correction a calibration carries: ``reference_C`` T0, ``coefficient_per_C`` (a_x, a_y, a_z) in 1/degC,
    ``source`` "fit" or "recipe", ``uncertainty_per_C`` (1 sigma, per axis; None for the recipe), ``span_C`` of
    the scan's temperatures (0 without), ``recipe_per_C`` the recipe's value, and a one-line ``note``."""

    reference_C: float
    coefficient_per_C: tuple[float, float, float]
    source: str
    uncertainty_per_C: tuple[float, float, float] | None
    span_C: float
    recipe_per_C: float
    note: str

    def as_json(self) -> dict[str, object]:
        """calibration.json's ``thermal`` object."""
        doc: dict[str, object] = {
            "reference_C": float(self.reference_C), "source": self.source,
            "coefficient_per_C": {a: float(x) for a, x in zip(AXES, self.coefficient_per_C)},
            "span_C": float(self.span_C), "recipe_per_C": float(self.recipe_per_C), "note": self.note,
            "model": "B_k / (1 + a_k (T - reference_C)) per axis before the calibration",
        }
        if self.uncertainty_per_C is not None:
            doc["uncertainty_per_C"] = {a: float(x) for a, x in zip(AXES, self.uncertainty_per_C)}
        return doc


def recipe_coefficient_per_C(design) -> float:
    """The magnet grade's remanence coefficient plus the chip's nominal sensitivity drift, 1/degC."""
    magnet = design.magnet_grade.br_temperature_coefficient_pct_per_C.nominal
    # sensitivity_drift_pct is a band over the whole range (+/-3 %, nominal 0): its nominal adds nothing
    chip = design.chip["sensitivity_drift_pct"].nominal
    return (magnet + chip) / 100.0


def correct(B_uT: np.ndarray, temperature_C: np.ndarray | None, reference_C: float,
            coefficient_per_C: tuple[float, float, float]) -> np.ndarray:
    """The field (N, 3) uT as at ``reference_C``: B_k / (1 + a_k (T - T0)); unchanged without temperatures."""
    b = np.asarray(B_uT, dtype=float)
    if temperature_C is None:
        return b.copy()
    dt = np.asarray(temperature_C, dtype=float)[:, None] - reference_C
    return b / (1.0 + np.asarray(coefficient_per_C, dtype=float)[None, :] * dt)


def _basis(u: np.ndarray, v: np.ndarray, order: int) -> np.ndarray:
    pu, pv = [np.ones_like(u)], [np.ones_like(v)]
    for _ in range(order):
        pu.append(pu[-1] * u)
        pv.append(pv[-1] * v)
    return np.column_stack([pu[i] * pv[k - i] for k in range(order + 1) for i in range(k, -1, -1)])


def _residual(a: np.ndarray, b: np.ndarray, dt: np.ndarray, y: np.ndarray, order: int,
              scale: tuple[float, float, float, float]) -> np.ndarray:
    """The force residual (2N,) N of the order-n polynomial fitted to the fields corrected with a = (a_xy, a_z)
    per degC (a is in %/C here, for a well-scaled solver)."""
    axy, az = a[0] / 100.0, a[1] / 100.0
    bz = b[:, 2] / (1.0 + az * dt)
    br = np.hypot(b[:, 0], b[:, 1]) / (1.0 + axy * dt)
    cz, sz, cr, sr = scale
    m = _basis((bz - cz) / sz, (br - cr) / sr, order)
    coef = np.linalg.lstsq(m, y, rcond=None)[0]
    return (m @ coef - y).ravel()


def fit_thermal(B_uT: np.ndarray, F_N: np.ndarray, temperature_C: np.ndarray | None, design,
                order: int) -> ThermalFit:
    """The scan's thermal correction (module doc): fitted from the forces (``F_N`` (N, 3), N; ``B_uT`` (N, 3),
    uT) with an order-``order`` polynomial when ``temperature_C`` (N,) spans :data:`MIN_SPAN_C`, else the
    recipe's."""
    recipe = recipe_coefficient_per_C(design)
    recipe3 = (recipe, recipe, recipe)
    if temperature_C is None:
        return ThermalFit(DEFAULT_REFERENCE_C, recipe3, "recipe", None, 0.0, recipe,
                          f"recipe values ({100 * recipe:+.3g} %/C): the scan has no temperature column, its "
                          f"temperature taken as {DEFAULT_REFERENCE_C:g} C")
    t = np.asarray(temperature_C, dtype=float)
    t0 = float(np.mean(t))
    span = float(np.max(t) - np.min(t))
    if span < MIN_SPAN_C:
        return ThermalFit(t0, recipe3, "recipe", None, span, recipe,
                          f"recipe values ({100 * recipe:+.3g} %/C): the scan spans {span:.3g} C, fitted from "
                          f"{MIN_SPAN_C:g} C up; reference {t0:.4g} C")
    b = np.asarray(B_uT, dtype=float)
    y = np.column_stack([F_N[:, 2], np.hypot(F_N[:, 0], F_N[:, 1])])
    dt = t - t0
    bz, br = b[:, 2], np.hypot(b[:, 0], b[:, 1])
    scale = ((bz.max() + bz.min()) / 2, max((bz.max() - bz.min()) / 2, 1e-9),
             (br.max() + br.min()) / 2, max((br.max() - br.min()) / 2, 1e-9))
    m = _basis((bz - scale[0]) / scale[1], (br - scale[2]) / scale[3], order)
    independent = float(np.std(dt - m @ np.linalg.lstsq(m, dt, rcond=None)[0]))
    if independent < MIN_INDEPENDENT_C:
        return ThermalFit(t0, recipe3, "recipe", None, span, recipe,
                          f"recipe values ({100 * recipe:+.3g} %/C): over {span:.3g} C the temperature followed the "
                          f"scan's position (only {independent:.2g} C RMS of it apart from the field; a fit needs "
                          f"{MIN_INDEPENDENT_C:g}): scan twice, cold and warm; reference {t0:.4g} C")
    (axy, az), sigma = _solve(b, dt, y, order, scale, recipe)
    (bxy, bz_), _ = _solve(b, dt, y, order + 1, scale, recipe)
    unc_xy, unc_z = math.hypot(sigma[0], axy - bxy), math.hypot(sigma[1], az - bz_)
    unc = (unc_xy, unc_xy, unc_z)
    if not max(unc) <= abs(recipe):
        return ThermalFit(t0, recipe3, "recipe", None, span, recipe,
                          f"recipe values ({100 * recipe:+.3g} %/C): the fit over {span:.3g} C did not determine "
                          f"the coefficients (+/-{100 * max(unc):.2g} %/C); reference {t0:.4g} C")
    return ThermalFit(t0, (axy, axy, az), "fit", unc, span, recipe,
                      f"fitted over {span:.3g} C: xy {100 * axy:+.4f} +/- {100 * unc[0]:.2g} %/C, z "
                      f"{100 * az:+.4f} +/- {100 * unc[2]:.2g} %/C (recipe {100 * recipe:+.3g}); reference "
                      f"{t0:.4g} C")


def _solve(b: np.ndarray, dt: np.ndarray, y: np.ndarray, order: int, scale: tuple[float, float, float, float],
           start: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """((a_xy, a_z), their s^2 (J^T J)^-1 sigmas) per degC at polynomial order ``order``."""
    from scipy.optimize import least_squares

    sol = least_squares(_residual, x0=[100 * start, 100 * start], args=(b, dt, y, order, scale), method="lm",
                        x_scale=[0.1, 0.1])
    r = sol.fun
    dof = max(1, r.size - 2 * _basis(np.zeros(1), np.zeros(1), order).shape[1] - 2)
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * float(r @ r) / dof
        sigma = np.sqrt(np.abs(np.diag(cov))) / 100.0
    except np.linalg.LinAlgError:
        sigma = np.array([math.inf, math.inf])
    return (float(sol.x[0]) / 100.0, float(sol.x[1]) / 100.0), (float(sigma[0]), float(sigma[1]))


def thermal_from_json(doc: Mapping[str, object], t: calibration_json.Thermal | None) -> ThermalFit | None:
    """The ``thermal`` object back as a :class:`ThermalFit` (its informative keys when present). The format leaves
    those keys to the writer, so a hand-edited file may hold anything there: each that is present must be what
    :meth:`ThermalFit.as_json` writes, else :class:`~magfab.formats.calibration_json.CalibrationError` names it."""
    if t is None:
        return None
    node = doc["thermal"]
    assert isinstance(node, Mapping)

    def number(key: str, value: object) -> float:
        if not json_checks.is_finite(value):
            raise calibration_json.CalibrationError(f"thermal.{key}", value, "must be a finite number")
        return float(value)

    unc = node.get("uncertainty_per_C")
    if unc is not None and not isinstance(unc, Mapping):
        raise calibration_json.CalibrationError("thermal.uncertainty_per_C", unc, "must map {} to numbers".format(
            ", ".join(calibration_json.AXES)))
    note = node.get("note", "")
    if not isinstance(note, str):
        raise calibration_json.CalibrationError("thermal.note", note, "must be a string")
    return ThermalFit(t.reference_C, t.coefficient_per_C, t.source,
                      None if unc is None else tuple(number(f"uncertainty_per_C.{a}", unc.get(a))
                                                     for a in calibration_json.AXES),  # type: ignore[arg-type]
                      number("span_C", node.get("span_C", 0.0)),
                      number("recipe_per_C", node.get("recipe_per_C", t.coefficient_per_C[2])), note)
