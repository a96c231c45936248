"""calibration.json (format ``magfab-calibration/1``, docs/bundle.md section 2): the one validator.

:func:`validate` takes the parsed file (plain JSON values: dict, list, str, int, float) and gives a
:class:`Checked` with every value the readers need, or raises :class:`CalibrationError` naming the key path,
the value and what is allowed. magfab's calibration model, the firmware renderer and the readout package all
read the file through it. Standard library only: a module of the readout package (shipped verbatim in every
build), which magfab imports as :mod:`magfab.formats.calibration_json`.

What the format allows, and no more (a reader may carry less, e.g. the firmware's float32 and order limits):
order 0..12 with the monomials listed in the documented order; finite numbers; scales > 0; shear_sign +1 or
-1; the hull a convex, counter-clockwise polygon of at least 3 distinct points (a closing repeat of the first
point and collinear points allowed); ``mls`` (when present, and required by method "mls") of order 0..4 with
equally long point columns; ``errors``, ``scan`` and ``chip`` objects when present; ``thermal`` (optional: a file
without it has no temperature correction) with ``reference_C`` from -40 to 125 and one ``coefficient_per_C`` per
field axis within +/-:data:`THERMAL_MAX_PER_C`; no NaN or infinity anywhere.

And what the formula computes from those numbers together (:func:`check_formula`), so that a file each of whose
numbers is in bounds cannot divide by zero or overflow on the host or on the device (which evaluates in float32):
the thermal denominator 1 + a (T - T0) stays at least :data:`THERMAL_MIN_DENOMINATOR` over the chip's rated
temperature range; the scaled inputs u, v stay within +/-:data:`INPUT_MAX` over the valid region's bounding box
(and at the MLS points); every partial sum of the polynomial stays within :data:`FORCE_MAX_N` there, as do the MLS
points' forces; the MLS bandwidth is at least :data:`MLS_MIN_BANDWIDTH`. The firmware's record check
(mf_calib.c) refuses the same records.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any, Mapping, Tuple

from . import bounded
from .json_checks import FormatError, finite, is_finite, is_number

__all__ = ["FORMAT", "FORCES", "INPUTS", "MAX_ORDER", "MLS_MAX_ORDER", "AXES", "THERMAL_MAX_PER_C",
           "THERMAL_REFERENCE_C", "THERMAL_MIN_DENOMINATOR", "INPUT_MAX", "FORCE_MAX_N", "MLS_MIN_BANDWIDTH",
           "CalibrationError", "Checked", "MLSPoints", "Thermal",
           "abs_terms", "calibration_sha256", "canonical_json", "check_formula", "cross", "loads", "monomials",
           "region_box", "scaled_reach", "validate"]

FORMAT = "magfab-calibration/1"
FORCES = ("Fz_N", "Fr_N")
INPUTS = ("Bz_uT", "Br_uT")
MAX_ORDER = 12
MLS_MAX_ORDER = 4
#: The field axes of ``thermal.coefficient_per_C``.
AXES = ("Bx_uT", "By_uT", "Bz_uT")
#: Largest |coefficient| per degC a thermal correction may carry: ten times NdFeB's -0.12 %/C plus the chip's
#: drift; beyond it the number is a unit mistake (percent for a fraction), not a field's drift.
THERMAL_MAX_PER_C = 0.01
#: The chip's rated operating range, degC (MLX90393 datasheet: -40 to 125): a calibration's temperature outside it
#: is a mistake.
THERMAL_REFERENCE_C = (-40.0, 125.0)
#: Least value of the thermal denominator 1 + a (T - T0) over :data:`THERMAL_REFERENCE_C`, the range the chip
#: reports: the correction may at most double the field. NdFeB's -0.12 %/C over the whole 165 C changes it by 20 %,
#: so a halving is no drift of magnet or chip but a wrong T0 or a; and 1/d then stays within 2, far from the zero
#: a file with T0 125 C and a +0.01 reaches at 25 C. The firmware skips the correction and flags the sample
#: (MF_FLAG_OUTSIDE) where a temperature outside that range would take it below this (mf_calib.c).
THERMAL_MIN_DENOMINATOR = 0.5
#: Largest |u| and |v| (the scaled inputs (B - center) / scale) over the valid region's bounding box and at the
#: MLS points. The scaling maps the scanned region to about [-1, 1] (the fit's centre and half range), so a
#: thousand times that is a scaling made for another region or a unit slip (1e-300, 1e308), and it keeps u^8,
#: the firmware's highest power, at 1e24, far inside float32.
INPUT_MAX = 1e3
#: Largest sum of |c_m| max(1, |u|)^i max(1, |v|)^j over the valid region's bounding box, per force (N): it
#: bounds the polynomial's value and every partial sum of its Horner form, so the firmware's float32 evaluation
#: (up to 3.4e38) keeps a factor 3e8 for the tare and Fr Bx / Br; a force model that large is no force model. The
#: MLS points' forces are held to the same bound.
FORCE_MAX_N = 1e30
#: Least MLS bandwidth in (u, v) units: the fit chooses multiples of the scan's nearest-neighbour spacing (a few
#: hundredths); this keeps the local monomials ((u - uq) / h)^(2 order) of the farthest query below 1e76.
MLS_MIN_BANDWIDTH = 1e-6

Point = Tuple[float, float]  # evaluated at import: the readout's Python 3.8 has no tuple[...]


class CalibrationError(FormatError):
    """A calibration.json that does not hold what format magfab-calibration/1 requires."""

    file = "calibration.json"


def monomials(order: int) -> list:
    """Exponents [i, j] of (u, v) in the documented order: for k = 0..n, for i = k down to 0: [i, k - i]."""
    return [[i, k - i] for k in range(order + 1) for i in range(k, -1, -1)]


def canonical_json(data: Mapping[str, Any]) -> str:
    """The calibration as canonical JSON (sorted keys, no spaces, ASCII, finite numbers only)."""
    return json.dumps(dict(data), sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def calibration_sha256(data: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of :func:`canonical_json`: the hash the firmware reports in its info line (first 16 hex)."""
    return hashlib.sha256(canonical_json(data).encode("ascii")).hexdigest()


@dataclass(frozen=True)
class MLSPoints:
    """The ``mls`` object: local order, bandwidth (scaled (u, v) units) and the scan points (uT, N)."""

    order: int
    bandwidth: float
    bz_uT: tuple[float, ...]
    br_uT: tuple[float, ...]
    fz_N: tuple[float, ...]
    fr_N: tuple[float, ...]


@dataclass(frozen=True)
class Thermal:
    """The ``thermal`` object: the field is corrected B_k / (1 + a_k (T - reference_C)) per axis before the
    calibration. ``coefficient_per_C`` (a_x, a_y, a_z) in 1/degC; ``source`` "fit" or "recipe"."""

    reference_C: float
    coefficient_per_C: tuple[float, float, float]
    source: str


@dataclass(frozen=True)
class Checked:
    """A valid calibration.json's values. ``center`` and ``scale`` are (Bz, Br) in uT; ``coefficients`` maps
    Fz_N and Fr_N to one number per monomial; ``box`` is ((Bz lo, hi), (Br lo, hi)) in uT; ``hull`` the convex
    counter-clockwise polygon without a closing repeat, ``span`` its largest coordinate range (uT);
    ``canonical`` the :func:`canonical_json` text and ``sha256`` its hash."""

    method: str
    order: int
    monomials: tuple[tuple[int, int], ...]
    center: Point
    scale: Point
    coefficients: dict[str, tuple[float, ...]]
    shear_sign: int
    direction_min_uT: float
    tare_N: Point
    box: tuple[Point, Point]
    hull: tuple[Point, ...]
    span: float
    mls: MLSPoints | None
    errors: dict
    scan: dict
    chip: dict
    canonical: str
    sha256: str
    thermal: Thermal | None = None


def _interval(data: dict, name: str) -> Point:
    path = "valid_region." + name
    pair = data["valid_region"].get(name)
    if (not isinstance(pair, list) or len(pair) != 2 or not all(is_finite(x) for x in pair)
            or not pair[0] <= pair[1]):
        raise CalibrationError(path, pair, "must be [lo, hi] with finite lo <= hi")
    return float(pair[0]), float(pair[1])


def cross(o: Point, a: Point, b: Point) -> float:
    """(a - o) x (b - o): positive where o, a, b turn counter-clockwise."""
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _hull(data: dict) -> tuple[tuple[Point, ...], float]:
    path = "valid_region.hull"
    raw = data["valid_region"].get("hull")
    if not isinstance(raw, list):
        raise CalibrationError(path, raw, "must be a list of [Bz_uT, Br_uT] points")
    points = []
    for n, p in enumerate(raw):
        if not isinstance(p, list) or len(p) != 2 or not all(is_finite(x) for x in p):
            raise CalibrationError(f"{path}[{n}]", p, "must be [Bz_uT, Br_uT], two finite numbers")
        points.append((float(p[0]), float(p[1])))
    if len(points) > 1 and points[0] == points[-1]:
        points.pop()  # a closed ring: the first point repeated at the end
    if len(points) < 3:
        raise CalibrationError(path, raw, "must have at least 3 distinct points")
    area2 = sum(points[k - 1][0] * points[k][1] - points[k][0] * points[k - 1][1] for k in range(len(points)))
    span = max(max(p[0] for p in points) - min(p[0] for p in points),
               max(p[1] for p in points) - min(p[1] for p in points))
    if not area2 > 1e-12 * span * span:
        raise CalibrationError(path, raw, "must enclose a positive area counter-clockwise (it is clockwise or flat)")
    for k in range(len(points)):
        if cross(points[k - 2], points[k - 1], points[k]) < -1e-9 * span * span:
            raise CalibrationError(path, raw, f"must be convex (it turns clockwise at point {(k - 1) % len(points)})")
    return tuple(points), span


def _column(points: dict, name: str) -> tuple[float, ...]:
    node = points.get(name)
    if not isinstance(node, list) or not all(is_finite(x) for x in node):
        raise CalibrationError("mls.points." + name, node, "must be a list of finite numbers")
    return tuple(float(x) for x in node)


def _mls(data: dict) -> MLSPoints:
    mls = data["mls"]
    if not isinstance(mls, dict):
        raise CalibrationError("mls", mls, "must be an object with order, bandwidth and points")
    order = mls.get("order")
    if not isinstance(order, int) or isinstance(order, bool) or not 0 <= order <= MLS_MAX_ORDER:
        raise CalibrationError("mls.order", order, f"must be an integer from 0 to {MLS_MAX_ORDER}")
    bandwidth = finite(data, "mls.bandwidth", CalibrationError, positive=True)
    points = mls.get("points")
    if not isinstance(points, dict):
        raise CalibrationError("mls.points", points, "must be an object with Bz_uT, Br_uT, Fz_N, Fr_N")
    columns = [_column(points, c) for c in ("Bz_uT", "Br_uT", "Fz_N", "Fr_N")]
    terms = len(monomials(order))
    if len({len(c) for c in columns}) != 1 or len(columns[0]) < terms:
        raise CalibrationError("mls.points", [len(c) for c in columns],
                               f"columns Bz_uT, Br_uT, Fz_N, Fr_N must have the same length, at least {terms}")
    return MLSPoints(order, bandwidth, *columns)


def _thermal(data: dict) -> Thermal:
    node = data["thermal"]
    if not isinstance(node, dict):
        raise CalibrationError("thermal", node, "must be an object with reference_C and coefficient_per_C")
    t0 = finite(data, "thermal.reference_C", CalibrationError)
    lo, hi = THERMAL_REFERENCE_C
    if not lo <= t0 <= hi:
        raise CalibrationError("thermal.reference_C", t0, f"must be within the chip's rated {lo:g} to {hi:g} degC"
                               )
    coef = node.get("coefficient_per_C")
    if not isinstance(coef, dict):
        raise CalibrationError("thermal.coefficient_per_C", coef, "must map {} to numbers".format(", ".join(AXES)))
    a = []
    for axis in AXES:
        x = finite(data, "thermal.coefficient_per_C." + axis, CalibrationError)
        if not abs(x) <= THERMAL_MAX_PER_C:
            raise CalibrationError("thermal.coefficient_per_C." + axis, x,
                                   f"must be within +/-{THERMAL_MAX_PER_C:g} per degC (a fraction: -0.12 %/C is "
                                   "-0.0012)")
        a.append(x)
    source = node.get("source", "")
    if source not in ("fit", "recipe"):
        raise CalibrationError("thermal.source", source, "must be 'fit' or 'recipe'")
    return Thermal(t0, (a[0], a[1], a[2]), source)


def _coefficients(data: dict, terms: int) -> dict[str, tuple[float, ...]]:
    coefficients = data.get("coefficients")
    if not isinstance(coefficients, dict):
        raise CalibrationError("coefficients", coefficients, "must map Fz_N and Fr_N to coefficient lists")
    out = {}
    for force in FORCES:
        c = coefficients.get(force)
        path = "coefficients." + force
        if not isinstance(c, list) or len(c) != terms:
            raise CalibrationError(path, c, f"must be a list of {terms} numbers, one per monomial")
        for m, x in enumerate(c):
            if not is_finite(x):
                raise CalibrationError(f"{path}[{m}]", x, "must be a finite number")
        out[force] = tuple(float(x) for x in c)
    return out


def _order(data: dict) -> int:
    order = data.get("order")
    if not isinstance(order, int) or isinstance(order, bool) or not 0 <= order <= MAX_ORDER:
        raise CalibrationError("order", order, f"must be an integer from 0 to {MAX_ORDER}")
    expected = monomials(order)
    if data.get("monomials") != expected:
        raise CalibrationError("monomials", data.get("monomials"),
                               f"must list the order-{order} exponents in the documented order: {expected}")
    return order


def _values(data: object) -> Checked:
    """The values of a parsed calibration.json, each number checked on its own (not yet :func:`check_formula`)."""
    if not isinstance(data, dict):
        raise CalibrationError("", type(data).__name__, "must be a JSON object")
    if data.get("format") != FORMAT:
        raise CalibrationError("format", data.get("format"), f"this reader knows only {FORMAT!r}")
    if data.get("method") not in ("poly", "mls"):
        raise CalibrationError("method", data.get("method"), "must be 'poly' or 'mls'")
    order = _order(data)
    center = tuple(finite(data, f"scaling.{k}.center", CalibrationError) for k in INPUTS)
    scale = tuple(finite(data, f"scaling.{k}.scale", CalibrationError, positive=True) for k in INPUTS)
    coefficients = _coefficients(data, len(monomials(order)))
    sign = data.get("shear_sign")
    if not is_number(sign) or sign not in (1, -1):
        raise CalibrationError("shear_sign", sign, "must be +1 or -1")
    direction_min = finite(data, "direction_min_uT", CalibrationError, nonnegative=True)
    tare = tuple(finite(data, "tare_N." + f, CalibrationError) for f in FORCES)
    if not isinstance(data.get("valid_region"), dict):
        raise CalibrationError("valid_region", data.get("valid_region"), "must be an object with Bz_uT, Br_uT and hull")
    box = (_interval(data, "Bz_uT"), _interval(data, "Br_uT"))
    hull, span = _hull(data)
    for key in ("errors", "scan", "chip"):
        if key in data and not isinstance(data[key], dict):
            raise CalibrationError(key, data[key], "must be an object")
    mls = _mls(data) if "mls" in data else None
    thermal = _thermal(data) if "thermal" in data else None
    if data["method"] == "mls" and mls is None:
        raise CalibrationError("mls", None, "is missing: method 'mls' needs the MLS model and its scan points")
    try:
        canonical = canonical_json(data)
    except (TypeError, ValueError) as exc:  # NaN, infinity or a non-JSON value outside the keys checked above
        raise CalibrationError("", "(contents)", f"must be plain JSON with finite numbers ({exc})") from None
    return Checked(data["method"], order, tuple((i, j) for i, j in monomials(order)), center, scale,  # type: ignore[arg-type]
                   coefficients, int(sign), direction_min, tare, box, hull, span, mls,  # type: ignore[arg-type]
                   dict(data.get("errors", {})), dict(data.get("scan", {})), dict(data.get("chip", {})),
                   canonical, hashlib.sha256(canonical.encode("ascii")).hexdigest(), thermal)


def validate(data: object) -> Checked:
    """The values of a parsed calibration.json; :class:`CalibrationError` naming the first bad key, its own or
    what it makes the formula compute (:func:`check_formula`)."""
    return check_formula(_values(data))


def region_box(checked: Checked) -> tuple[Point, Point]:
    """((Bz lo, hi), (Br lo, hi)) uT bounding the valid region (inside the box and the hull): the box clipped to
    the hull's bounding box (the hull's alone when they do not overlap: then no reading is valid, but the
    firmware evaluates every reading, flagged)."""
    out = []
    for k in range(2):
        lo, hi = checked.box[k]
        hlo, hhi = min(p[k] for p in checked.hull), max(p[k] for p in checked.hull)
        lo, hi = max(lo, hlo), min(hi, hhi)
        out.append((lo, hi) if lo <= hi else (hlo, hhi))
    return out[0], out[1]


def _thermal_denominators(t: Thermal) -> None:
    lo, hi = THERMAL_REFERENCE_C
    for axis, a in zip(AXES, t.coefficient_per_C):
        d, at = min((1.0 + a * (temp - t.reference_C), temp) for temp in (lo, hi))  # linear in T: least at an end
        if not d >= THERMAL_MIN_DENOMINATOR:
            raise CalibrationError("thermal.coefficient_per_C." + axis, a,
                                   f"with reference_C {t.reference_C:g}, 1 + a (T - T0) falls to {d:.3g} at "
                                   f"{at:g} degC: must stay at least {THERMAL_MIN_DENOMINATOR:g} over the chip's "
                                   f"rated {lo:g} to {hi:g} degC")


def scaled_reach(checked: Checked) -> tuple[float, float]:
    """The largest |u| and |v| over :func:`region_box`, each refused beyond :data:`INPUT_MAX`."""
    reach = []
    for k, (name, (lo, hi)) in enumerate(zip(INPUTS, region_box(checked))):
        c, s = checked.center[k], checked.scale[k]
        r = max(abs(lo - c), abs(hi - c)) / s
        if not r <= INPUT_MAX:
            raise CalibrationError("scaling." + name, {"center": c, "scale": s},
                                   f"must map the valid region's {name} {lo:g} to {hi:g} into +/-{INPUT_MAX:g} "
                                   f"(it reaches {r:.3g})")
        reach.append(r)
    return reach[0], reach[1]


def abs_terms(checked: Checked, force: str, u: float, v: float) -> list:
    """|c_m| u^i v^j for each monomial of ``force`` (u, v >= 0): their sum bounds the polynomial where |u| <= u and
    |v| <= v."""
    return [abs(c) * u ** i * v ** j for c, (i, j) in zip(checked.coefficients[force], checked.monomials)]


def _force_bound(checked: Checked, reach: Point) -> None:
    """Sum |c_m| max(1, |u|)^i max(1, |v|)^j per force within :data:`FORCE_MAX_N` (:data:`FORCE_MAX_N`'s note)."""
    pu, pv = max(1.0, reach[0]), max(1.0, reach[1])
    for force in FORCES:
        terms = abs_terms(checked, force, pu, pv)
        total = sum(terms)
        if not total <= FORCE_MAX_N:
            m = max(range(len(terms)), key=lambda n: terms[n])
            raise CalibrationError(f"coefficients.{force}[{m}]", checked.coefficients[force][m],
                                   f"with |u|, |v| up to {reach[0]:.3g}, {reach[1]:.3g} over the valid region the "
                                   f"polynomial's terms reach {total:.3g} N: must stay within {FORCE_MAX_N:g} N "
                                   "(the firmware evaluates it in float32)")


def _mls_bounds(checked: Checked) -> None:
    m = checked.mls
    if m is None:
        return
    if not m.bandwidth >= MLS_MIN_BANDWIDTH:
        raise CalibrationError("mls.bandwidth", m.bandwidth, f"must be at least {MLS_MIN_BANDWIDTH:g} (scaled units)")
    columns = (("Bz_uT", m.bz_uT), ("Br_uT", m.br_uT))
    for k, (name, column) in enumerate(columns):
        c, s = checked.center[k], checked.scale[k]
        for n, x in enumerate(column):
            if not abs(x - c) / s <= INPUT_MAX:
                raise CalibrationError(f"mls.points.{name}[{n}]", x,
                                       f"must lie within +/-{INPUT_MAX:g} scales of scaling.{name}.center")
    for name, column in (("Fz_N", m.fz_N), ("Fr_N", m.fr_N)):
        for n, x in enumerate(column):
            if not abs(x) <= FORCE_MAX_N:
                raise CalibrationError(f"mls.points.{name}[{n}]", x, f"must be within +/-{FORCE_MAX_N:g} N")


def check_formula(checked: Checked) -> Checked:
    """``checked`` when what its formula computes stays bounded (module doc): the thermal denominators, the scaled
    inputs over the valid region, the polynomial's terms there and the MLS model's inputs; else
    :class:`CalibrationError` naming the key that takes it out of bounds and what is allowed."""
    if checked.thermal is not None:
        _thermal_denominators(checked.thermal)
    _force_bound(checked, scaled_reach(checked))
    _mls_bounds(checked)
    return checked


def loads(text: str) -> Checked:
    """Parse (nesting and keys bounded, :mod:`.bounded`) and :func:`validate` calibration.json text."""
    try:
        data = bounded.loads_json(text, "calibration.json")
    except bounded.InputFileError:
        raise
    except ValueError as exc:
        raise CalibrationError("", text[:40], f"is not valid JSON ({exc})") from None
    return validate(data)
