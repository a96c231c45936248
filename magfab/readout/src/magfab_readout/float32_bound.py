"""How far the firmware's float32 forces can be from a float64 evaluation of the same calibration.json.

The firmware (mf_calib.c) evaluates docs/bundle.md section 2 in float32: the field corrected for temperature, Br,
the scaled inputs u and v, the polynomial in Horner form (rows in v, then u), the tare, and Fx, Fy = Fr Bx / Br,
By / Br. :func:`float32_error_N` bounds, a priori and from the calibration's own numbers, the difference from
float64 over every reading whose corrected field lies in the valid region's bounding box
(:func:`calibration_json.region_box`) at any temperature of the chip's rated range. It is a running-error analysis
in the standard model, each float32 operation's result the exact one times (1 + d) with
|d| <= :data:`UNIT` (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., SIAM 2002: section 3.1,
gamma_k = k u / (1 - k u); section 5.1, Horner's rule, |p(x) - fl(p(x))| <= gamma_2n sum |a_i| |x|^i):

- the field: count x LSB, both float32 (gamma_2 relative); the temperature correction B / (1 + a (T - T0)) with a
  and T0 as float32 and the denominator at least ``THERMAL_MIN_DENOMINATOR``;
- Br = sqrt(Bx^2 + By^2): the components' error plus three roundings;
- u = (Bz - c) / s as (Bz - c) x (1 / s), c and 1 / s float32: an absolute error, Bz's relative error times |Bz|
  (the subtraction can cancel) plus the roundings of c, 1 / s and the two operations;
- the polynomial: the input errors propagated through sum |c_ij| |u|^i |v|^j (its value at |u| + du, |v| + dv
  less its value at |u|, |v|, which bounds |p(u + du, v + dv) - p(u, v)| since each term grows with |u| and |v|),
  and the evaluation's gamma_(2n+3) times that sum (2n + 2 roundings along any term's path in the nested Horner
  form, one for the coefficient's float32);
- the tare (float32) and its subtraction; Fx = (sign Fr / Br) Bx: Fr's error, and |Fr| times the relative error of
  Bx / Br.

:data:`UNIT` is one unit in the last place (2^-23), twice round-to-nearest's 2^-24, so that the bound holds for a
float library that is faithful but not correctly rounded (avr-libc's routines are not documented as correctly
rounded). Near ``direction_min_uT`` the two evaluations can take different branches (a lateral force or none), and
near the valid region's edge different inside flags: there the bound does not apply, and readings within
:func:`direction_band` of ``direction_min_uT`` are left out.
"""

from __future__ import annotations

from typing import Tuple

from .calibration_json import (
    FORCES,
    THERMAL_MIN_DENOMINATOR,
    THERMAL_REFERENCE_C,
    Checked,
    abs_terms,
    region_box,
    scaled_reach,
)

__all__ = ["UNIT", "float32_error_N", "direction_band", "gamma"]

#: The relative error allowed each float32 operation (module doc): one unit in the last place.
UNIT = 2.0 ** -23


def gamma(k: int) -> float:
    """Higham's gamma_k: the relative error bound of k roundings, k u / (1 - k u)."""
    return k * UNIT / (1.0 - k * UNIT)


def _field_error(checked: Checked) -> float:
    """The relative error of each corrected field component Bx, By, Bz as the firmware holds it."""
    e = gamma(2)  # count x LSB, both float32
    t = checked.thermal
    if t is None:
        return e
    a = max(abs(x) for x in t.coefficient_per_C)
    t_abs = max(abs(x) for x in THERMAL_REFERENCE_C)
    dt = max(abs(x - t.reference_C) for x in THERMAL_REFERENCE_C)
    # 1 + a (T - T0): T and T0 float32 (their subtraction can cancel), a float32, the product and the sum rounded
    error_d = a * ((t_abs + abs(t.reference_C)) * gamma(2) + dt * gamma(2)) + gamma(1) * (1.0 + a * dt)
    e_d = error_d / THERMAL_MIN_DENOMINATOR
    return (1.0 + e) * (1.0 + UNIT) / (1.0 - e_d) - 1.0


def direction_band(checked: Checked) -> Tuple[float, float]:
    """The Br interval (uT) around ``direction_min_uT`` where float32 and float64 may disagree on whether a lateral
    force is given (Br's relative error either side)."""
    e_br = (1.0 + _field_error(checked)) * (1.0 + UNIT) ** 2 - 1.0
    d = checked.direction_min_uT
    return d * (1.0 - 2.0 * e_br), d * (1.0 + 2.0 * e_br)


def float32_error_N(checked: Checked) -> Tuple[float, float]:
    """(Fz, Fx and Fy) in N: the largest difference between the firmware's float32 forces and float64 ones of
    ``checked`` over the valid region's box and the chip's temperature range (module doc), readings near
    ``direction_min_uT`` (:func:`direction_band`) apart."""
    e_b = _field_error(checked)
    e_br = (1.0 + e_b) * (1.0 + UNIT) ** 2 - 1.0  # two squares, their sum, the root (which halves its input's)
    reach = scaled_reach(checked)
    errors = []
    for k, (lo, hi) in enumerate(region_box(checked)):
        c, s, b = checked.center[k], checked.scale[k], max(abs(lo), abs(hi))
        # (B - c) x (1 / s): B's error and c's rounding (absolute), then the subtraction, 1 / s and the product
        errors.append(((b * (e_br if k else e_b) + abs(c) * UNIT) / s) * (1.0 + gamma(3)) + reach[k] * gamma(3))
    (ru, rv), (du, dv) = reach, errors
    n = checked.order
    out = {}
    for force in FORCES:
        at = sum(abs_terms(checked, force, ru, rv))
        past = sum(abs_terms(checked, force, ru + du, rv + dv))
        tare = abs(checked.tare_N[FORCES.index(force)])
        # propagated input error + the Horner evaluation + the tare's float32 and its subtraction
        out[force] = (past - at) + gamma(2 * n + 3) * past + UNIT * tare + UNIT * (past + tare)
    fr_max = sum(abs_terms(checked, "Fr_N", ru + du, rv + dv)) + abs(checked.tare_N[1])
    ratio = (1.0 + e_b) * (1.0 + UNIT) ** 2 / (1.0 - e_br) - 1.0  # Bx / Br: the division and the product
    return out["Fz_N"], out["Fr_N"] * (1.0 + ratio) + fr_max * ratio
