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
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from typing import Any, Mapping, Tuple

from . import bounded
from .json_checks import FormatError, finite, is_number

__all__ = ["FORMAT", "FORCES", "INPUTS", "MAX_ORDER", "MLS_MAX_ORDER", "AXES", "THERMAL_MAX_PER_C", "CalibrationError",
           "Checked", "MLSPoints", "Thermal",
           "calibration_sha256", "canonical_json", "cross", "loads", "monomials", "validate"]

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
    if (not isinstance(pair, list) or len(pair) != 2 or not all(is_number(x) and math.isfinite(x) for x in pair)
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
        if not isinstance(p, list) or len(p) != 2 or not all(is_number(x) and math.isfinite(x) for x in p):
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
    if not isinstance(node, list) or not all(is_number(x) and math.isfinite(x) for x in node):
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
            if not is_number(x) or not math.isfinite(x):
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


def validate(data: object) -> Checked:
    """The values of a parsed calibration.json; :class:`CalibrationError` naming the first bad key."""
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


def loads(text: str) -> Checked:
    """Parse (nesting and keys bounded, :mod:`.bounded`) and :func:`validate` calibration.json text."""
    try:
        data = bounded.loads_json(text, "calibration.json")
    except bounded.InputFileError:
        raise
    except ValueError as exc:
        raise CalibrationError("", text[:40], f"is not valid JSON ({exc})") from None
    return validate(data)
