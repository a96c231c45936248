"""Force calibration (BRIEF eq. 12-14): scan data in, calibration.json out.

The pipeline::

    scan = read_scan_csv("scan.csv")          # or simulate_scan(design): the provisional calibration
    result = fit(scan, design)                 # every candidate, k-fold held-out errors, the choice
    result.calibration.evaluate(B_uT)          # -> forces (N, 3) in N, in-region flags (N,)
    json.dumps(result.calibration.to_json())   # calibration.json, docs/bundle.md section 2
    chart(result)                              # held-out RMS error against evaluation cost

**The model.** Fz and Fr = sqrt(Fx^2 + Fy^2) are each a full bivariate polynomial of order n in the scaled
field u = (Bz - c_z) / s_z, v = (Br - c_r) / s_r, Br = sqrt(Bx^2 + By^2), with the centre c and half-width s
of the scan's own range, so |u|, |v| <= 1 over the scan. Unscaled, the order-6 design matrix holds
Bz^6 ~ 10^30 uT^6 next to 1 and is numerically singular; scaled its condition number stays below ~10^4
(the candidates' table carries both). The shear is split by the field's lateral direction (eq. 14) with a
sign found from the data (below the magnet the radial field points towards the axis, so the chip's and the
force's lateral directions agree or are opposite depending on how the chip's axes are mounted).

**Moving least squares** (Loweth, de Boer & Toropov 2011), the host-only accurate option: at each query
point a polynomial of order ``MLS_ORDER`` is fitted to every scan point, weighted exp(-d^2 / 2h^2) by its
distance d in (u, v); the bandwidth h is chosen by k-fold cross-validation from a grid of multiples of the
scan's median point spacing (so the MLS held-out error is mildly optimistic: the same folds chose h).
A caveat found on the simulated scan: its reference error is pure quantisation, a fixed function of the true
force, repeated along every row (Fz) and column (Fy) of the track, which random folds cannot hold out; a
small bandwidth follows that pattern, so MLS beats the order-4 polynomial against the reference (held-out)
but not against the true force (bench/calibrate.py prints both). A real reference's noise breaks the pattern.
Evaluation needs the scan points, which calibration.json carries inline under ``mls.points`` (Bz, Br, Fz,
Fr: four columns, full precision), so the file stays self-contained; the firmware ignores them and evaluates
the global polynomial ``coefficients`` that every calibration carries.

**Held-out error.** The scan rows are dealt at random (``calibration.seed``) into ``calibration.folds``
folds; each fold is predicted by a fit to the others. Per force (Fz, Fr): RMS and largest held-out error
and the RMS residual of the fit to all rows, in N.

**Choice.** ``calibration.method = "auto"`` takes the cheapest candidate (lowest polynomial order up to
``calibration.order``, MLS last) whose held-out RMS for both Fz and Fr is within ``tolerance_mN``; when none
is, the most accurate one, with :attr:`FitResult.meets_tolerance` False and a one-line ``message`` for the
caller to turn into a warning.

**The guard.** Readings outside the scanned region of (Bz, Br) -- the range box and the convex hull of the
scan points (simplified to the least-area enclosing polygon of at most ``HULL_MAX_VERTICES`` vertices, since
the firmware tests every reading against it) -- are flagged ``in_region = False``; the model's value is still
returned, never silently trusted.

**The simulated scan** (:func:`simulate_scan`) is the published y-z track: the tip is indented by delta
(0 to ``scan_z_mm``, capped where the predicted normal range ends) and displaced laterally by y (centred on
the axis, ``scan_y_mm`` wide, capped at the predicted lateral range), in ``scan_step_mm`` steps. Assumptions,
stated because they are not modelled further: the magnet's lateral offset equals the tip's (the magnet
sits near the top surface and moves with it), and normal and shear loads superpose (the axial travel and
Fz come from the nominal FE curve at delta, the lateral force is K_s y with the nominal shear stiffness,
each independent of the other). The chip's noise and quantisation and the reference sensor's resolution are
added; the result is deterministic for a given ``calibration.seed``.

Units: field in microtesla (uT; 1 G = 100 uT), force in newton, lengths in mm, time in s.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np

from . import field as fieldmod

if TYPE_CHECKING:
    from ..design import Design
    from .predict import Prediction

__all__ = [
    "FORMAT", "UT_PER_G", "MIN_ROWS", "ORDERS", "MLS_ORDER", "SCAN_COLUMNS", "FORCE_COLUMNS", "HULL_MAX_VERTICES",
    "CalibrationError", "ScanError", "Scan", "read_scan_csv", "scan_csv", "scan_track", "simulate_scan",
    "monomials", "Scaling", "ValidRegion", "MLSModel", "Calibration", "Candidate", "FitResult",
    "fit", "choose", "poly_ops", "mls_ops", "guard_ops", "evaluation_time_s", "chart",
]

FORMAT = "magfab-calibration/1"
UT_PER_G = 100.0
#: Smallest scan a calibration accepts: the order-6 fit has 28 coefficients and is cross-validated.
MIN_ROWS = 50
#: Polynomial orders every fit tries (the table and the chart show them all).
ORDERS = (1, 2, 3, 4, 5, 6)
#: Order of the local polynomial of moving least squares.
MLS_ORDER = 2
#: MLS bandwidths tried, as multiples of the scan's median nearest-neighbour spacing in (u, v).
MLS_BANDWIDTHS = tuple(float(x) for x in np.geomspace(1.5, 48.0, 11))
#: The shear direction is undefined below this many RMS xy field noise (the chip's and the environment's).
DIRECTION_MIN_SIGMAS = 3.0
#: Required scan columns; the force columns are required for a calibration (not for a recording).
SCAN_COLUMNS = ("time_s", "Bx_uT", "By_uT", "Bz_uT")
FORCE_COLUMNS = ("Fx_N", "Fy_N", "Fz_N")
TEMPERATURE_COLUMN = "temperature_C"
FORCES = ("Fz_N", "Fr_N")


class CalibrationError(ValueError):
    """Bad calibration input (a calibration.json that is not format ``magfab-calibration/1``, a scan too
    small to fit): one line naming the key or line, the value and what is allowed."""


class ScanError(CalibrationError):
    """A malformed scan CSV: one line naming the file, the line number, the column and what is allowed."""


# ---------------------------------------------------------------------------------------------------
# Scan data


@dataclass(frozen=True)
class Scan:
    """A calibration scan, one row per sample.

    ``time_s`` (N,) s, non-decreasing; ``B_uT`` (N, 3) field at the sensor in the chip's axes, uT;
    ``F_N`` (N, 3) reference force on the tip in the sensor frame (+z presses the tip towards the chip), N,
    or None for a recording without a reference; ``temperature_C`` (N,) degC or None; ``source`` the file
    name or "simulated"; ``sha256`` of the CSV bytes as read (simulated: of :func:`scan_csv` of the scan).
    """

    time_s: np.ndarray
    B_uT: np.ndarray
    F_N: np.ndarray | None
    temperature_C: np.ndarray | None = None
    source: str = "simulated"
    sha256: str = ""

    @property
    def rows(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def Br_uT(self) -> np.ndarray:
        """Lateral field magnitude sqrt(Bx^2 + By^2), uT, (N,)."""
        return np.hypot(self.B_uT[:, 0], self.B_uT[:, 1])

    @property
    def Fr_N(self) -> np.ndarray:
        """Lateral force magnitude sqrt(Fx^2 + Fy^2), N, (N,)."""
        if self.F_N is None:
            raise CalibrationError(f"scan {self.source}: no force columns ({', '.join(FORCE_COLUMNS)})")
        return np.hypot(self.F_N[:, 0], self.F_N[:, 1])


def scan_csv(scan: Scan, comments: Sequence[str] = ()) -> str:
    """The scan as CSV text (docs/bundle.md section 1), every value in Python's round-trip repr, so
    :func:`read_scan_csv` gives back the same numbers. ``comments`` become leading ``# `` lines."""
    cols = [scan.time_s, *scan.B_uT.T]
    names = list(SCAN_COLUMNS)
    if scan.temperature_C is not None:
        cols.append(scan.temperature_C)
        names.append(TEMPERATURE_COLUMN)
    if scan.F_N is not None:
        cols.extend(scan.F_N.T)
        names.extend(FORCE_COLUMNS)
    out = io.StringIO()
    for c in comments:
        out.write("# " + " ".join(str(c).splitlines()) + "\n")
    out.write(",".join(names) + "\n")
    for row in zip(*(np.asarray(c, dtype=float).tolist() for c in cols)):
        out.write(",".join(map(repr, row)) + "\n")
    return out.getvalue()


def _load(source: "str | os.PathLike[str] | bytes") -> tuple[bytes, str]:
    """(bytes, name) of a scan: a path, CSV text (a str holding a newline, or a comma and naming no file) or
    CSV bytes."""
    if isinstance(source, bytes):
        return source, "scan"
    if isinstance(source, str) and ("\n" in source or ("," in source and not os.path.exists(source))):
        return source.encode("utf-8"), "scan"
    path = Path(source)
    try:
        return path.read_bytes(), path.name
    except OSError as exc:
        raise ScanError(f"{path}: cannot read the scan file ({exc.strerror or exc})") from None


def _number(text: str, name: str, line: int, column: str) -> float:
    try:
        x = float(text)
    except ValueError:
        x = math.nan
        shown = repr(text.strip()[:24]) if text.strip() else "an empty field"
    else:
        shown = text.strip()
    if not math.isfinite(x):
        raise ScanError(f"{name}: line {line}, column {column!r}: {shown} is not a finite number; "
                        "every value must be a finite decimal number (e.g. 12.5 or -3e-2)")
    return x


def _header(lines: list[tuple[int, str]], name: str, require_force: bool) -> tuple[int, list[str]]:
    if not lines:
        raise ScanError(f"{name}: line 1: no header row (the file is empty or holds only comments); expected "
                        f"a header naming {', '.join(SCAN_COLUMNS + FORCE_COLUMNS)}")
    number, text = lines[0]
    names = [c.strip() for c in text.split(",")]
    seen: set[str] = set()
    for c in names:
        if c in seen:
            raise ScanError(f"{name}: line {number} (header): column {c!r} appears twice; each column once")
        seen.add(c)
    with_force = require_force or any(c in seen for c in FORCE_COLUMNS)
    needed = SCAN_COLUMNS + (FORCE_COLUMNS if with_force else ())
    missing = [c for c in needed if c not in seen]
    if missing:
        raise ScanError(f"{name}: line {number} (header): missing column {missing[0]!r}; required columns are "
                        f"{', '.join(needed)} (any order; {TEMPERATURE_COLUMN} optional, others ignored)")
    return number, names


def read_scan_csv(source: "str | os.PathLike[str] | bytes", *, require_force: bool = True,
                  min_rows: int = MIN_ROWS) -> Scan:
    """A scan from a CSV file (path), CSV text (a str with a newline) or CSV bytes; docs/bundle.md section 1.

    Raises :class:`ScanError` (one line: file, line number, column, what is allowed) for a missing file or
    column, a non-numeric or non-finite value, a row of the wrong length, decreasing time or fewer than
    ``min_rows`` rows. ``require_force=False`` accepts a recording without the force columns (``F_N`` None).
    """
    raw, name = _load(source)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ScanError(f"{name}: byte {exc.start} is not UTF-8; the scan must be UTF-8 text") from None
    lines = [(i, s) for i, s in enumerate(text.splitlines(), 1) if s.strip() and not s.lstrip().startswith("#")]
    hline, names = _header(lines, name, require_force)
    wanted = [c for c in SCAN_COLUMNS + (TEMPERATURE_COLUMN,) + FORCE_COLUMNS if c in names]
    index = {c: names.index(c) for c in wanted}
    values: dict[str, list[float]] = {c: [] for c in wanted}
    last_t, last_line = -math.inf, hline
    for number, s in lines[1:]:
        fields = s.split(",")
        if len(fields) != len(names):
            raise ScanError(f"{name}: line {number}: {len(fields)} values, but the header (line {hline}) names "
                            f"{len(names)} columns; every row needs one value per column")
        for c in wanted:
            values[c].append(_number(fields[index[c]], name, number, c))
        t = values["time_s"][-1]
        if t < last_t:
            raise ScanError(f"{name}: line {number}, column 'time_s': {t!r} is less than {last_t!r} on line "
                            f"{last_line}; time_s must be non-decreasing")
        last_t, last_line = t, number
    rows = len(lines) - 1
    if rows < min_rows:
        end = lines[-1][0]
        raise ScanError(f"{name}: line {end}: the scan ends after {rows} data rows; a calibration needs at "
                        f"least {min_rows} (the order-{ORDERS[-1]} fit has {len(monomials(ORDERS[-1]))} "
                        "coefficients and is cross-validated)")
    arr = {c: np.asarray(v, dtype=float) for c, v in values.items()}
    forces = np.column_stack([arr[c] for c in FORCE_COLUMNS]) if FORCE_COLUMNS[0] in arr else None
    return Scan(arr["time_s"], np.column_stack([arr[c] for c in SCAN_COLUMNS[1:]]), forces,
                arr.get(TEMPERATURE_COLUMN), name, hashlib.sha256(raw).hexdigest())


# ---------------------------------------------------------------------------------------------------
# The simulated scan


def scan_track(design: "Design", prediction: "Prediction") -> tuple[np.ndarray, np.ndarray]:
    """The y-z track of the scan: (y_mm, indentation_mm), each (N,), in raster order (one row of y per
    indentation step, y increasing along each row, indentation increasing row by row).

    y spans ``scan_y_mm`` centred on the axis, capped at the predicted lateral range (the magnet radius or
    the chip's xy full scale); the indentation spans 0..``scan_z_mm``, capped at the indentation where the
    predicted normal range ends (``normal.travel_mm`` of magnet travel, through the nominal FE curve).
    """
    cal = design.spec.calibration
    data = prediction.data
    nominal = prediction.curves["nominal"]
    travel_end = float(data["normal"]["travel_mm"])  # type: ignore[index]
    delta_end = float(np.interp(travel_end, nominal.magnet_displacement_mm, nominal.indentation_mm))
    k_s = float(data["shear"]["stiffness_N_per_mm"]["nominal"])  # type: ignore[index]
    lateral_end = float(data["shear"]["range_by_material_N"]["nominal"]) / k_s  # type: ignore[index]
    step = cal.scan_step_mm
    half = min(cal.scan_y_mm / 2.0, lateral_end)
    ny = int(math.floor(2.0 * half / step + 1e-9)) + 1
    y = (np.arange(ny) - (ny - 1) / 2.0) * step
    z_end = min(cal.scan_z_mm, delta_end)
    nz = int(math.floor(z_end / step + 1e-9)) + 1
    delta = np.arange(nz) * step
    dd, yy = np.meshgrid(delta, y, indexing="ij")
    return yy.ravel(), dd.ravel()


def _quantise(x: np.ndarray, step: float) -> np.ndarray:
    return np.round(x / step) * step if step > 0 else x


def simulate_scan(design: "Design", prediction: "Prediction | None" = None, *, ideal: bool = False) -> Scan:
    """The simulated calibration scan of ``design`` (module doc): field in uT at the sensing point and the
    reference force in N along :func:`scan_track`.

    Noise: gaussian per axis with the predicted RMS (``predict.noise``: environment and chip; the chip's
    quantisation is then applied by rounding to its LSB, so the total matches ``total_xy_G``/``total_z_G``),
    clipped at the chip's full scale; the reference forces are rounded to ``reference_resolution_mN``.
    ``ideal=True``: the same track without noise, quantisation or clipping (the truth a fit should recover).
    Sample times are one chip conversion apart. Deterministic (``calibration.seed``).
    """
    from .predict import chip_setting, noise, predict

    pred = prediction if prediction is not None else predict(design)
    cal = design.spec.calibration
    y, delta = scan_track(design, pred)
    nominal = pred.curves["nominal"]
    u = np.interp(delta, nominal.indentation_mm, nominal.magnet_displacement_mm)  # axial travel, + down
    fz = np.interp(delta, nominal.indentation_mm, nominal.force_N)
    k_s = float(pred.data["shear"]["stiffness_N_per_mm"]["nominal"])  # type: ignore[index]
    magnet = fieldmod.Magnet.from_spec(design.spec)
    gap = design.d_rest_mm - u
    # The sensor at the origin, the magnet's centre at (0, y, gap + H/2): in the magnet's frame the sensing
    # point is at (0, -y, -(gap + H/2)).
    points = np.column_stack([np.zeros_like(y), -y, -(gap + magnet.height_mm / 2.0)])
    b = fieldmod.exact(magnet, points) * UT_PER_G
    f = np.column_stack([np.zeros_like(y), k_s * y, fz])
    chip = chip_setting(design)
    if not ideal:
        nz = noise(design, chip)
        sigma = UT_PER_G * np.array([math.sqrt(max(nz[f"total_{a}_G"] ** 2 - nz[f"quantisation_{a}_G"] ** 2, 0.0))
                                     for a in ("xy", "xy", "z")])
        rng = np.random.default_rng(cal.seed)
        b = b + rng.normal(size=b.shape) * sigma
        lsb = np.array([chip.lsb_xy_uT, chip.lsb_xy_uT, chip.lsb_z_uT])
        b = np.round(b / lsb) * lsb
        full = UT_PER_G * np.array([chip.full_scale_xy_G, chip.full_scale_xy_G, chip.full_scale_z_G])
        b = np.clip(b, -full, full)
        f = _quantise(f, cal.reference_resolution_mN / 1000.0)
    t = np.arange(len(y)) * chip.conversion_ms / 1000.0
    scan = Scan(t, b, f, None, "simulated" if not ideal else "simulated (ideal)", "")
    return replace(scan, sha256=hashlib.sha256(scan_csv(scan).encode("utf-8")).hexdigest())


# ---------------------------------------------------------------------------------------------------
# The model: scaling, monomials, polynomial, moving least squares


def monomials(order: int) -> list[tuple[int, int]]:
    """Exponents (i, j) of u^i v^j, docs/bundle.md order: for k = 0..n, for i = k down to 0: (i, k - i)."""
    return [(i, k - i) for k in range(order + 1) for i in range(k, -1, -1)]


def _basis(u: np.ndarray, v: np.ndarray, order: int) -> np.ndarray:
    """Design matrix (N, terms) of :func:`monomials` at (u, v)."""
    pu = [np.ones_like(u)]
    pv = [np.ones_like(v)]
    for _ in range(order):
        pu.append(pu[-1] * u)
        pv.append(pv[-1] * v)
    return np.column_stack([pu[i] * pv[j] for i, j in monomials(order)])


@dataclass(frozen=True)
class Scaling:
    """u = (Bz - bz_center) / bz_scale, v = (Br - br_center) / br_scale; all in uT."""

    bz_center: float
    bz_scale: float
    br_center: float
    br_scale: float

    @classmethod
    def of(cls, bz: np.ndarray, br: np.ndarray) -> "Scaling":
        """Mid-range and half-range of the data (1 uT where the data has no spread), so |u|, |v| <= 1."""
        def axis(x: np.ndarray) -> tuple[float, float]:
            lo, hi = float(np.min(x)), float(np.max(x))
            half = (hi - lo) / 2.0
            return (lo + hi) / 2.0, half if half > 1e-9 * max(abs(lo), abs(hi), 1.0) else 1.0
        return cls(*axis(bz), *axis(br))

    def __call__(self, bz: np.ndarray, br: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (bz - self.bz_center) / self.bz_scale, (br - self.br_center) / self.br_scale


def _solve_poly(u: np.ndarray, v: np.ndarray, y: np.ndarray, order: int) -> np.ndarray:
    """Least-squares coefficients (terms, k) of the order-``order`` polynomial through y (N, k)."""
    return np.linalg.lstsq(_basis(u, v, order), y, rcond=None)[0]


def _mls(u: np.ndarray, v: np.ndarray, y: np.ndarray, uq: np.ndarray, vq: np.ndarray, order: int,
         h: float) -> np.ndarray:
    """Moving least squares at (uq, vq) (Q,) from data (u, v) (N,), y (N, k): (Q, k).

    At each query a polynomial of ``order`` in the local coordinates ((u - uq)/h, (v - vq)/h) is fitted
    with weights exp(-d^2 / 2h^2); its constant term is the value. Weights are taken relative to the
    nearest point's, so a query far outside the data still gets a (flagged) answer rather than 0/0.
    """
    mono = monomials(order)
    m = len(mono)
    out = np.empty((len(uq), y.shape[1]))
    chunk = max(1, int(2_000_000 // max(1, len(u) * m)))
    for s in range(0, len(uq), chunk):
        du = (u[None, :] - uq[s:s + chunk, None]) / h
        dv = (v[None, :] - vq[s:s + chunk, None]) / h
        d2 = du * du + dv * dv
        w = np.exp(-0.5 * (d2 - d2.min(axis=1, keepdims=True)))
        pu, pv = [np.ones_like(du)], [np.ones_like(dv)]
        for _ in range(order):
            pu.append(pu[-1] * du)
            pv.append(pv[-1] * dv)
        p = np.stack([pu[i] * pv[j] for i, j in mono], axis=-1)  # (q, N, m)
        pw = np.swapaxes(p * w[..., None], 1, 2)  # (q, m, N)
        normal = pw @ p
        rhs = pw @ y
        ridge = 1e-12 * np.trace(normal, axis1=1, axis2=2)[:, None, None] * np.eye(m)
        out[s:s + chunk] = np.linalg.solve(normal + ridge, rhs)[:, 0, :]
    return out


# ---------------------------------------------------------------------------------------------------
# Evaluation cost, in floating-point operations (add, multiply, divide, sqrt, exp: one each)


def guard_ops(hull_vertices: int) -> int:
    """Operations of the region guard per reading: the range box (4 compares) and, per hull edge, a cross
    product and its sign (2 sub, 2 mul, 1 sub, 1 compare). The same for every candidate, so kept apart."""
    return 4 + 6 * hull_vertices


def poly_ops(order: int) -> int:
    """Operations per evaluation of the global polynomial (docs/bundle.md section 2, Horner form):
    Br (2 mul, 1 add, 1 sqrt), scaling (2 sub, 2 mul), 2 forces x terms x (1 mul + 1 add), the shear split
    (1 compare, 1 div, 2 mul) and the tare (2 sub); the guard (:func:`guard_ops`) not included."""
    return 8 + 4 * len(monomials(order)) + 5


def mls_ops(points: int, order: int = MLS_ORDER) -> int:
    """Operations per MLS evaluation over ``points`` scan points: per point the scaled distance (2 sub,
    2 mul, 1 add, 1 mul), the weight (1 sub, 1 mul, 1 exp), the local monomials (m - 1 mul), the weighted
    normal matrix (m (m + 1) / 2 x 2) and two right-hand sides (2 m x 2); then a Cholesky-type solve (m^3 / 3
    + 2 x 2 m^2), and the input, split and tare as for the polynomial."""
    m = len(monomials(order))
    per_point = 6 + 3 + (m - 1) + m * (m + 1) + 4 * m
    return points * per_point + m**3 // 3 + 4 * m * m + 8 + 5


# ---------------------------------------------------------------------------------------------------
# The guard


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0])


def _enclosing(poly: np.ndarray, max_vertices: int) -> np.ndarray:
    """A convex CCW polygon of at most ``max_vertices`` vertices holding the convex CCW polygon ``poly``
    (n, 2): greedily drop the edge whose removal -- extending its two neighbours to meet -- adds the least
    area. Each step keeps convexity and containment (the result is an intersection of ``poly``'s half-planes)."""
    p = [np.asarray(v, dtype=float) for v in poly]
    while len(p) > max(3, max_vertices):
        n = len(p)
        best: tuple[float, int, np.ndarray] | None = None
        for i in range(n):
            a, b, c, d = p[i - 1], p[i], p[(i + 1) % n], p[(i + 2) % n]
            m = np.column_stack([b - a, d - c])  # b + t (b - a) = c + s (c - d): t (b - a) + s (d - c) = c - b
            if abs(np.linalg.det(m)) < 1e-300:
                continue
            t, s = np.linalg.solve(m, c - b)
            if t <= 0 or s <= 0:  # the neighbours do not meet beyond the edge
                continue
            x = b + t * (b - a)
            area = 0.5 * abs(float(_cross(b, c, x)))
            if best is None or area < best[0]:
                best = (area, i, x)
        if best is None:
            break
        _, i, x = best
        j = (i + 1) % n
        p[i] = x
        del p[j]
    return np.array(p)


#: Most vertices the region's polygon may have. The guard costs 6 operations per vertex on every reading
#: (MagOne's 32-vertex hull: 196 operations, more than the order-4 polynomial's 73 and ~1.5 ms of soft float
#: on a 16 MHz AVR), so a hull with more vertices (the noise makes dozens) is replaced by the least-area
#: enclosing polygon of this many (MagOne: +0.3 % area).
HULL_MAX_VERTICES = 8


@dataclass(frozen=True)
class ValidRegion:
    """The scanned region of (Bz, Br), uT: the range box and a convex polygon (counter-clockwise vertices)
    holding every scan point: the convex hull, or the least-area enclosing polygon of ``HULL_MAX_VERTICES``
    built from it when the hull has more vertices."""

    bz_uT: tuple[float, float]
    br_uT: tuple[float, float]
    hull: tuple[tuple[float, float], ...]

    @classmethod
    def of(cls, bz: np.ndarray, br: np.ndarray, max_vertices: int = HULL_MAX_VERTICES) -> "ValidRegion":
        from scipy.spatial import ConvexHull

        sc = Scaling.of(bz, br)
        scaled = np.column_stack(sc(bz, br))  # the hull in (u, v): both axes of order 1
        try:
            idx = ConvexHull(scaled).vertices  # counter-clockwise in 2-D
        except (RuntimeError, ValueError) as exc:  # QhullError (a RuntimeError): no area, e.g. all on a line
            raise CalibrationError(f"the scan's (Bz, Br) points span no area ({str(exc).splitlines()[0]}); "
                                   "a calibration needs a 2-D scan (normal and lateral load)") from None
        poly = _enclosing(scaled[idx], max_vertices)
        hull = tuple((sc.bz_center + sc.bz_scale * float(u), sc.br_center + sc.br_scale * float(v)) for u, v in poly)
        return cls((float(bz.min()), float(bz.max())), (float(br.min()), float(br.max())), hull)

    def contains(self, bz: np.ndarray, br: np.ndarray) -> np.ndarray:
        """True where (Bz, Br) (uT, any shape) is inside the box and the hull (edges included, to a
        relative 1e-9 of the region's size); False for NaN."""
        bz, br = np.asarray(bz, dtype=float), np.asarray(br, dtype=float)
        ok = (bz >= self.bz_uT[0]) & (bz <= self.bz_uT[1]) & (br >= self.br_uT[0]) & (br <= self.br_uT[1])
        h = np.asarray(self.hull, dtype=float)
        tol = 1e-9 * ((self.bz_uT[1] - self.bz_uT[0]) * (self.br_uT[1] - self.br_uT[0]) + 1.0)
        q = np.stack([bz, br], axis=-1)
        for k in range(len(h)):
            ok &= _cross(h[k], h[(k + 1) % len(h)], q) >= -tol
        return ok


# ---------------------------------------------------------------------------------------------------
# The calibration


@dataclass(frozen=True)
class MLSModel:
    """What moving least squares needs at evaluation: the local order, the bandwidth h (in the scaled
    (u, v) units) and the scan points (Bz, Br in uT; Fz, Fr in N; each (N,))."""

    order: int
    bandwidth: float
    bz_uT: np.ndarray
    br_uT: np.ndarray
    fz_N: np.ndarray
    fr_N: np.ndarray


@dataclass(frozen=True)
class Calibration:
    """calibration.json as an object (docs/bundle.md section 2). ``coefficients`` (terms, 2): the global
    polynomial's, columns Fz, Fr in N, rows in :func:`monomials` order. ``tare_N`` (Fz, Fr) in N.
    ``errors``, ``scan`` and ``chip`` are the JSON objects of the same name."""

    method: str
    order: int
    scaling: Scaling
    coefficients: np.ndarray
    shear_sign: int
    direction_min_uT: float
    region: ValidRegion
    errors: Mapping[str, object]
    scan: Mapping[str, object]
    chip: Mapping[str, object]
    tare_N: tuple[float, float] = (0.0, 0.0)
    mls: MLSModel | None = None

    def model(self, B_uT: object, method: str | None = None) -> np.ndarray:
        """Untared (Fz, Fr), N, (N, 2), at field readings B_uT (N, 3) uT, by ``method`` (default: the
        calibration's own; "poly" gives what the firmware computes)."""
        b = _readings(B_uT)
        br = np.hypot(b[:, 0], b[:, 1])
        u, v = self.scaling(b[:, 2], br)
        method = method or self.method
        if method == "mls":
            if self.mls is None:
                raise CalibrationError("method 'mls' asked of a calibration without MLS data")
            mu, mv = self.scaling(self.mls.bz_uT, self.mls.br_uT)
            good = np.isfinite(u) & np.isfinite(v)
            out = np.full((len(u), 2), np.nan)
            out[good] = _mls(mu, mv, np.column_stack([self.mls.fz_N, self.mls.fr_N]), u[good], v[good],
                             self.mls.order, self.mls.bandwidth)
            return out
        if method != "poly":
            raise CalibrationError(f"method must be 'poly' or 'mls'; instead received {method!r}")
        return _basis(u, v, self.order) @ self.coefficients

    def evaluate(self, B_uT: object, method: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Force (Fx, Fy, Fz) in N, (N, 3), and in_region (N,) bool, from field readings B_uT (N, 3) uT
        (a single (3,) reading gives (3,) and a bool array of shape ()).

        docs/bundle.md section 2: Fz and Fr from the model, the tare subtracted from each, then the shear
        split Fx = shear_sign Fr Bx / Br, Fy = shear_sign Fr By / Br (0 where Br < direction_min_uT).
        Readings outside the valid region (or not finite) get the model's value and in_region False.
        """
        b = _readings(B_uT)
        raw = self.model(b, method)
        fz = raw[:, 0] - self.tare_N[0]
        fr = raw[:, 1] - self.tare_N[1]
        br = np.hypot(b[:, 0], b[:, 1])
        ok = br >= self.direction_min_uT
        q = np.divide(self.shear_sign * fr, br, out=np.zeros_like(fr), where=ok)
        f = np.column_stack([q * b[:, 0], q * b[:, 1], fz])
        inside = self.region.contains(b[:, 2], br) & np.isfinite(b).all(axis=1)
        if np.ndim(B_uT) == 1:
            return f[0], inside[0]
        return f, inside

    def zeroed(self, B_rest_uT: object) -> "Calibration":
        """The calibration with its tare set to the mean untared (Fz, Fr) over readings taken at rest."""
        raw = self.model(B_rest_uT)
        if not np.isfinite(raw).all():
            raise CalibrationError("the rest readings must be finite to zero the calibration")
        return replace(self, tare_N=(float(raw[:, 0].mean()), float(raw[:, 1].mean())))

    def to_json(self) -> dict[str, object]:
        """calibration.json as a dict of plain Python values (floats at full precision; dump with
        ``sort_keys=True`` for a deterministic file, see :meth:`dumps`)."""
        s = self.scaling
        doc: dict[str, object] = {
            "format": FORMAT,
            "method": self.method,
            "order": self.order,
            "monomials": [[i, j] for i, j in monomials(self.order)],
            "scaling": {"Bz_uT": {"center": s.bz_center, "scale": s.bz_scale},
                        "Br_uT": {"center": s.br_center, "scale": s.br_scale}},
            "coefficients": {name: [float(c) for c in self.coefficients[:, k]] for k, name in enumerate(FORCES)},
            "shear_sign": int(self.shear_sign),
            "direction_min_uT": float(self.direction_min_uT),
            "tare_N": {"Fz_N": float(self.tare_N[0]), "Fr_N": float(self.tare_N[1])},
            "valid_region": {"Bz_uT": list(self.region.bz_uT), "Br_uT": list(self.region.br_uT),
                             "hull": [list(p) for p in self.region.hull]},
            "errors": _plain(self.errors),
            "scan": _plain(self.scan),
            "chip": _plain(self.chip),
        }
        if self.mls is not None:
            m = self.mls
            doc["mls"] = {
                "order": m.order, "bandwidth": m.bandwidth, "units": "bandwidth in the scaled (u, v) of 'scaling'",
                "weight": "gaussian exp(-d^2 / (2 bandwidth^2)), d the distance in (u, v)",
                "points": {"Bz_uT": m.bz_uT.tolist(), "Br_uT": m.br_uT.tolist(), "Fz_N": m.fz_N.tolist(),
                           "Fr_N": m.fr_N.tolist()},
            }
        return doc

    def dumps(self) -> str:
        """calibration.json text: sorted keys, one-space indent, trailing newline (byte-stable)."""
        return json.dumps(self.to_json(), indent=1, sort_keys=True) + "\n"

    @classmethod
    def from_json(cls, doc: Mapping[str, object]) -> "Calibration":
        """A calibration from a calibration.json dict; :class:`CalibrationError` naming the first bad key."""
        return _from_json(doc)


def _readings(B_uT: object) -> np.ndarray:
    b = np.asarray(B_uT, dtype=float)
    if b.ndim == 1 and b.shape[0] == 3:
        b = b[None, :]
    if b.ndim != 2 or b.shape[1] != 3:
        raise CalibrationError(f"B_uT must be an array of shape (N, 3) in uT; instead received shape {b.shape}")
    return b


def _plain(x: object) -> object:
    """JSON-ready copy: numpy scalars to Python numbers, mappings to dicts, sequences to lists."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_plain(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x)
    return x


# ---- calibration.json validation -----------------------------------------------------------------


def _get(doc: Mapping[str, object], path: str) -> object:
    node: object = doc
    parts = path.split(".")
    for k, part in enumerate(parts):
        if not isinstance(node, Mapping) or part not in node:
            where = ".".join(parts[:k + 1])
            need = f" (needed for {path})" if where != path else ""
            raise CalibrationError(f"calibration.json: key {where!r} is missing{need}")
        node = node[part]
    return node


def _real(doc: Mapping[str, object], path: str, positive: bool = False) -> float:
    x = _get(doc, path)
    ok = isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and (x > 0 or not positive)
    if not ok:
        what = "a positive finite number" if positive else "a finite number"
        raise CalibrationError(f"calibration.json: {path} must be {what}; instead received {x!r}")
    return float(x)


def _reals(doc: Mapping[str, object], path: str, length: int | None = None) -> np.ndarray:
    x = _get(doc, path)
    ok = isinstance(x, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                     for v in x) and (length is None or len(x) == length)
    if not ok:
        n = f"{length} " if length is not None else ""
        raise CalibrationError(f"calibration.json: {path} must be a list of {n}finite numbers; instead received "
                               f"{_short(x)}")
    return np.asarray(x, dtype=float)


def _short(x: object) -> str:
    s = repr(x)
    return s if len(s) <= 60 else s[:57] + "..."


def _from_json(doc: Mapping[str, object]) -> Calibration:
    if not isinstance(doc, Mapping):
        raise CalibrationError(f"calibration.json must hold a JSON object; instead received {type(doc).__name__}")
    fmt = doc.get("format")
    if fmt != FORMAT:
        raise CalibrationError(f"calibration.json: format must be {FORMAT!r}; instead received {fmt!r}")
    method = _get(doc, "method")
    if method not in ("poly", "mls"):
        raise CalibrationError(f"calibration.json: method must be 'poly' or 'mls'; instead received {method!r}")
    order = _get(doc, "order")
    if not isinstance(order, int) or isinstance(order, bool) or not 0 <= order <= 12:
        raise CalibrationError(f"calibration.json: order must be an integer 0..12; instead received {order!r}")
    mono = _get(doc, "monomials")
    if mono != [[i, j] for i, j in monomials(order)]:
        raise CalibrationError(f"calibration.json: monomials must be {monomials(order)!r} for order {order} "
                               f"(for k = 0..n, for i = k down to 0: [i, k - i]); instead received {_short(mono)}")
    terms = len(monomials(order))
    coef = np.column_stack([_reals(doc, f"coefficients.{f}", terms) for f in FORCES])
    scaling = Scaling(_real(doc, "scaling.Bz_uT.center"), _real(doc, "scaling.Bz_uT.scale", True),
                      _real(doc, "scaling.Br_uT.center"), _real(doc, "scaling.Br_uT.scale", True))
    sign = _get(doc, "shear_sign")
    if sign not in (1, -1) or isinstance(sign, bool):
        raise CalibrationError(f"calibration.json: shear_sign must be 1 or -1; instead received {sign!r}")
    dmin = _real(doc, "direction_min_uT")
    if dmin < 0:
        raise CalibrationError(f"calibration.json: direction_min_uT must be >= 0; instead received {dmin!r}")
    tare = (_real(doc, "tare_N.Fz_N"), _real(doc, "tare_N.Fr_N"))
    return Calibration(method, order, scaling, coef, int(sign), dmin, _region_json(doc),
                       dict(_mapping(doc, "errors")), dict(_mapping(doc, "scan")), dict(_mapping(doc, "chip")),
                       tare, _mls_json(doc) if method == "mls" else None)


def _mapping(doc: Mapping[str, object], path: str) -> Mapping[str, object]:
    x = _get(doc, path)
    if not isinstance(x, Mapping):
        raise CalibrationError(f"calibration.json: {path} must be an object; instead received {_short(x)}")
    return x


def _region_json(doc: Mapping[str, object]) -> ValidRegion:
    bz = _reals(doc, "valid_region.Bz_uT", 2)
    br = _reals(doc, "valid_region.Br_uT", 2)
    hull = _get(doc, "valid_region.hull")
    ok = isinstance(hull, list) and len(hull) >= 3 and all(
        isinstance(p, list) and len(p) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                    and math.isfinite(x) for x in p) for p in hull)
    if not ok:
        raise CalibrationError("calibration.json: valid_region.hull must be a list of at least 3 [Bz, Br] pairs "
                               f"of finite numbers; instead received {_short(hull)}")
    h = np.asarray(hull, dtype=float)
    turns = _cross(h, np.roll(h, -1, axis=0), np.roll(h, -2, axis=0))
    if (turns <= 0).any() or bz[0] > bz[1] or br[0] > br[1]:
        raise CalibrationError("calibration.json: valid_region.hull must be convex and counter-clockwise and "
                               "its Bz_uT, Br_uT ranges [lo, hi] with lo <= hi")
    return ValidRegion((float(bz[0]), float(bz[1])), (float(br[0]), float(br[1])),
                       tuple((float(a), float(b)) for a, b in h))


def _mls_json(doc: Mapping[str, object]) -> MLSModel:
    order = _get(doc, "mls.order")
    if not isinstance(order, int) or isinstance(order, bool) or not 0 <= order <= 4:
        raise CalibrationError(f"calibration.json: mls.order must be an integer 0..4; instead received {order!r}")
    h = _real(doc, "mls.bandwidth", positive=True)
    cols = [_reals(doc, f"mls.points.{c}") for c in ("Bz_uT", "Br_uT", "Fz_N", "Fr_N")]
    if len({len(c) for c in cols}) != 1 or len(cols[0]) < len(monomials(order)):
        raise CalibrationError("calibration.json: mls.points columns Bz_uT, Br_uT, Fz_N, Fr_N must have the same "
                               f"length, at least {len(monomials(order))}; instead received lengths "
                               f"{[len(c) for c in cols]}")
    return MLSModel(order, h, *cols)


# ---------------------------------------------------------------------------------------------------
# Fitting, cross-validation and the choice


@dataclass(frozen=True)
class Candidate:
    """One fit tried: held-out and fit errors per force in N (keys Fz_N, Fr_N), evaluation cost in
    operations (:func:`poly_ops`, :func:`mls_ops`), the condition number of the design matrix in scaled
    (u, v) and in raw uT (poly only; NaN for MLS), the MLS bandwidth in (u, v) units (None for poly), and the
    fitted model: ``coefficients`` (terms, 2) for poly, ``mls`` for MLS."""

    label: str
    method: str
    order: int
    rms_holdout_N: Mapping[str, float]
    max_holdout_N: Mapping[str, float]
    rms_fit_N: Mapping[str, float]
    cost_ops: int
    condition: float = math.nan
    condition_raw: float = math.nan
    bandwidth: float | None = None
    coefficients: np.ndarray | None = field(default=None, repr=False, compare=False)
    mls: MLSModel | None = field(default=None, repr=False, compare=False)

    @property
    def worst_rms_N(self) -> float:
        return max(self.rms_holdout_N.values())

    def errors(self, folds: int) -> dict[str, object]:
        """The ``errors`` object of calibration.json."""
        out: dict[str, object] = {f: {"rms_holdout": self.rms_holdout_N[f], "max_holdout": self.max_holdout_N[f],
                                      "rms_fit": self.rms_fit_N[f]} for f in FORCES}
        out["folds"] = folds
        return out

    def as_dict(self) -> dict[str, object]:
        return _plain({"label": self.label, "method": self.method, "order": self.order,
                       "rms_holdout_N": self.rms_holdout_N, "max_holdout_N": self.max_holdout_N,
                       "rms_fit_N": self.rms_fit_N, "cost_ops": self.cost_ops,
                       "condition": None if math.isnan(self.condition) else self.condition,
                       "condition_raw": None if math.isnan(self.condition_raw) else self.condition_raw,
                       "bandwidth": self.bandwidth})  # type: ignore[return-value]


@dataclass(frozen=True)
class FitResult:
    """A fit: the calibration, every candidate tried (poly orders, then MLS) and which one was chosen.
    ``meets_tolerance`` False means no candidate reached ``tolerance_mN`` and ``message`` says so.
    ``guard_ops``: operations of the region guard per reading (the same for every candidate).
    ``firmware_order``: the polynomial an MLS calibration carries for the firmware (the best held-out
    order up to ``calibration.order``)."""

    calibration: Calibration
    candidates: tuple[Candidate, ...]
    chosen: str
    tolerance_mN: float
    meets_tolerance: bool
    message: str = ""
    guard_ops: int = 0
    firmware_order: int = 0

    def candidate(self, label: str) -> Candidate:
        return next(c for c in self.candidates if c.label == label)

    def table(self) -> list[dict[str, object]]:
        return [c.as_dict() for c in self.candidates]

    def calibration_for(self, label: str) -> Calibration:
        """The calibration had candidate ``label`` been chosen (same scan, scaling, region and sign)."""
        return _calibration_for(self.calibration, self.candidates, label, self.firmware_order)


def _calibration_for(base: Calibration, candidates: Sequence[Candidate], label: str,
                     firmware_order: int) -> Calibration:
    by = {c.label: c for c in candidates}
    if label not in by:
        raise CalibrationError(f"no candidate {label!r}; the fit tried {', '.join(by)}")
    c = by[label]
    poly = c if c.method == "poly" else by[f"poly {firmware_order}"]
    assert poly.coefficients is not None
    return replace(base, method=c.method, order=poly.order, coefficients=poly.coefficients,
                   errors=c.errors(int(base.errors["folds"])), mls=c.mls)  # type: ignore[call-overload]


def _error_stats(pred: np.ndarray, y: np.ndarray) -> tuple[dict[str, float], dict[str, float]]:
    e = pred - y
    rms = {f: float(np.sqrt(np.mean(e[:, k] ** 2))) for k, f in enumerate(FORCES)}
    mx = {f: float(np.max(np.abs(e[:, k]))) for k, f in enumerate(FORCES)}
    return rms, mx


def _folds(n: int, k: int, seed: int) -> np.ndarray:
    """Fold index (n,) of each row: a seeded random deal into k folds of near-equal size."""
    return np.random.default_rng(seed).permutation(n) % k


def _poly_candidate(bz: np.ndarray, br: np.ndarray, u: np.ndarray, v: np.ndarray, y: np.ndarray, order: int,
                    fold: np.ndarray, k: int) -> Candidate:
    held = np.empty_like(y)
    for f in range(k):
        test = fold == f
        held[test] = _basis(u[test], v[test], order) @ _solve_poly(u[~test], v[~test], y[~test], order)
    a = _basis(u, v, order)
    coef = np.linalg.lstsq(a, y, rcond=None)[0]
    rms, mx = _error_stats(held, y)
    rms_fit, _ = _error_stats(a @ coef, y)
    return Candidate(f"poly {order}", "poly", order, rms, mx, rms_fit, poly_ops(order),
                     float(np.linalg.cond(a)), float(np.linalg.cond(_basis(bz, br, order))), coefficients=coef)


def _mls_candidate(bz: np.ndarray, br: np.ndarray, u: np.ndarray, v: np.ndarray, y: np.ndarray,
                   fold: np.ndarray, k: int, order: int = MLS_ORDER) -> Candidate:
    from scipy.spatial import cKDTree

    uv = np.column_stack([u, v])
    spacing = float(np.median(cKDTree(uv).query(uv, k=2)[0][:, 1]))
    spacing = spacing if spacing > 0 else 1e-3
    best = None
    for mult in MLS_BANDWIDTHS:
        h = mult * spacing
        held = np.empty_like(y)
        for f in range(k):
            test = fold == f
            held[test] = _mls(u[~test], v[~test], y[~test], u[test], v[test], order, h)
        rms, mx = _error_stats(held, y)
        score = math.hypot(*rms.values())
        if best is None or score < best[0]:
            best = (score, h, rms, mx)
    assert best is not None
    _, h, rms, mx = best
    rms_fit, _ = _error_stats(_mls(u, v, y, u, v, order, h), y)
    model = MLSModel(order, h, bz.copy(), br.copy(), y[:, 0].copy(), y[:, 1].copy())
    return Candidate("mls", "mls", order, rms, mx, rms_fit, mls_ops(len(u), order), bandwidth=h, mls=model)


def choose(candidates: Sequence[Candidate], method: str, order: int, tolerance_mN: float) -> tuple[str, bool]:
    """(label, meets tolerance) of the candidate to use (module doc). ``method`` "poly": the order-``order``
    polynomial; "mls": MLS; "auto": the first of poly 1..``order`` then MLS whose held-out RMS for Fz and Fr
    is within ``tolerance_mN``, else the one with the smallest worse-axis held-out RMS."""
    tol = tolerance_mN / 1000.0
    by = {c.label: c for c in candidates}
    if method in ("poly", "mls"):
        label = f"poly {order}" if method == "poly" else "mls"
        if label not in by:
            raise CalibrationError(f"calibration.method = {method!r}: no candidate {label!r} was fitted")
        return label, by[label].worst_rms_N <= tol
    if method != "auto":
        raise CalibrationError(f"calibration.method must be 'auto', 'poly' or 'mls'; instead received {method!r}")
    allowed = [c for c in candidates if (c.method == "poly" and c.order <= order) or c.method == "mls"]
    allowed.sort(key=lambda c: (c.method == "mls", c.order))
    for c in allowed:
        if c.worst_rms_N <= tol:
            return c.label, True
    return min(allowed, key=lambda c: c.worst_rms_N).label, False


def _shear_sign(scan: Scan) -> int:
    """+1 when the force's lateral direction follows the field's (eq. 14), -1 when opposite: the sign of
    sum(Fx Bx + Fy By) over the scan (+1 for a scan without lateral load)."""
    assert scan.F_N is not None
    s = float(np.sum(scan.F_N[:, 0] * scan.B_uT[:, 0] + scan.F_N[:, 1] * scan.B_uT[:, 1]))
    return -1 if s < 0 else 1


def _chip_json(design: "Design") -> tuple[dict[str, object], float]:
    """The ``chip`` object and the RMS xy field noise (uT) predicted for the spec's chip settings."""
    from .predict import chip_setting, noise

    chip = chip_setting(design)
    doc = {"gain_sel": chip.gain_sel, "resolution": chip.resolution, "osr": chip.osr, "dig_filt": chip.dig_filt,
           "lsb_xy_uT": chip.lsb_xy_uT, "lsb_z_uT": chip.lsb_z_uT}
    return doc, noise(design, chip)["total_xy_G"] * UT_PER_G


def fit(scan: Scan, design: "Design", *, mls: bool = True) -> FitResult:
    """Fit every candidate (poly of each order in :data:`ORDERS` and up to ``calibration.order``, and MLS
    unless ``mls`` is False) to ``scan``, cross-validate them and build the calibration the spec's
    ``calibration.method`` chooses (module doc). The chip settings recorded are the spec's."""
    cal = design.spec.calibration
    if scan.F_N is None:
        raise CalibrationError(f"scan {scan.source}: no force columns ({', '.join(FORCE_COLUMNS)}); a calibration "
                               "needs the reference force")
    if scan.rows < MIN_ROWS:
        raise CalibrationError(f"scan {scan.source}: {scan.rows} rows; a calibration needs at least {MIN_ROWS}")
    bz, br = scan.B_uT[:, 2], scan.Br_uT
    y = np.column_stack([scan.F_N[:, 2], scan.Fr_N])
    scaling = Scaling.of(bz, br)
    u, v = scaling(bz, br)
    region = ValidRegion.of(bz, br)
    fold = _folds(scan.rows, cal.folds, cal.seed)
    orders = sorted(set(ORDERS) | {cal.order})
    max_order = max(o for o in orders if len(monomials(o)) * cal.folds <= scan.rows * (cal.folds - 1))
    cands = [_poly_candidate(bz, br, u, v, y, order, fold, cal.folds) for order in orders if order <= max_order]
    if mls or cal.method.value == "mls":
        cands.append(_mls_candidate(bz, br, u, v, y, fold, cal.folds))
    label, meets = choose(cands, cal.method.value, min(cal.order, max_order), cal.tolerance_mN)
    chosen = next(c for c in cands if c.label == label)
    firmware = min((c for c in cands if c.method == "poly" and c.order <= cal.order), key=lambda c: c.worst_rms_N)
    chip, noise_xy_uT = _chip_json(design)
    base = Calibration("poly", 0, scaling, np.zeros((1, 2)), _shear_sign(scan), DIRECTION_MIN_SIGMAS * noise_xy_uT,
                       region, {"folds": cal.folds}, {"sha256": scan.sha256, "rows": scan.rows, "source": scan.source},
                       chip)
    calibration = _calibration_for(base, cands, label, firmware.order)
    message = "" if meets else (
        f"no calibration reaches the held-out RMS tolerance of {cal.tolerance_mN:g} mN; using {label} "
        f"(Fz {1000 * chosen.rms_holdout_N['Fz_N']:.3g} mN, Fr {1000 * chosen.rms_holdout_N['Fr_N']:.3g} mN)")
    return FitResult(calibration, tuple(cands), label, cal.tolerance_mN, meets, message,
                     guard_ops(len(region.hull)), firmware.order)


def evaluation_time_s(calibration: Calibration, B_uT: np.ndarray, method: str | None = None,
                      repeat: int = 5) -> float:
    """Measured time per 1000 evaluations, s (median of ``repeat`` runs over the readings B_uT (N, 3) uT).
    For benchmarks only: nothing deterministic (the chart, calibration.json) uses it."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        calibration.evaluate(B_uT, method)
        times.append(time.perf_counter() - t)
    return float(np.median(times)) * 1000.0 / len(B_uT)


# ---------------------------------------------------------------------------------------------------
# The chart


def chart(result: FitResult) -> dict[str, bytes]:
    """{"calibration_fit.svg": bytes, "calibration_fit.png": bytes}: held-out RMS error (mN) against
    evaluation cost (operations per evaluation), one point per polynomial order and one for MLS, per force;
    the chosen fit ringed. Byte-identical for the same fit (operation counts, not timings)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..export.figures import _render

    with matplotlib.rc_context({"svg.hashsalt": "magfab", "svg.fonttype": "path", "path.simplify": True}):
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for f, marker, colour in (("Fz_N", "o", "#1f77b4"), ("Fr_N", "s", "#ff7f0e")):
            for method, style in (("poly", "-"), ("mls", "none")):
                cs = [c for c in result.candidates if c.method == method]
                if not cs:
                    continue
                x = [c.cost_ops for c in cs]
                e = [1000.0 * c.rms_holdout_N[f] for c in cs]
                label = f"{f[:2]}, {'polynomial' if method == 'poly' else 'moving least squares'}"
                ax.plot(x, e, marker=marker if method == "poly" else "*", ms=6 if method == "poly" else 11,
                        ls=style, color=colour, lw=0.8, label=label)
                for c, xc, ec in zip(cs, x, e):
                    if f == "Fz_N":
                        ax.annotate(str(c.order) if method == "poly" else "MLS", (xc, ec), textcoords="offset points",
                                    xytext=(0, 6), ha="center", fontsize=7)
                    if c.label == result.chosen:
                        ax.plot([xc], [ec], marker="o", ms=14, mfc="none", mec="k", ls="none")
        cost = np.array([c.cost_ops for c in result.candidates], dtype=float)
        ax.axhline(result.tolerance_mN, color="r", lw=0.8, ls="--")
        ax.text(cost.min(), result.tolerance_mN, " tolerance", color="r", fontsize=7, va="bottom")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("evaluation cost, flops per reading (numbers: polynomial order)")
        ax.set_ylabel(f"held-out RMS error ({result.calibration.errors.get('folds')}-fold), mN")
        scan = result.calibration.scan
        ax.set_title(f"Calibration fits on {scan.get('source')} ({scan.get('rows')} rows); ringed: {result.chosen}",
                     fontsize=9)
        ax.legend(fontsize=8)
        fig.tight_layout()
        svg, png = _render(fig)
        plt.close(fig)
    return {"calibration_fit.svg": svg, "calibration_fit.png": png}
