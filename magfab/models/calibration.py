"""Force calibration (docs/models.md, M12 to M14): scan data in, calibration.json out.

The pipeline::

    scan = read_scan_csv("scan.csv")          # magfab.formats.scan_csv; or magfab.models.scan.simulate_scan
                                               # (design): the provisional calibration
    result = fit(scan, design)                 # every candidate, k-fold held-out errors, the choice
    result.calibration.evaluate(B_uT)          # -> forces (N, 3) in N, in-region flags (N,)
    json.dumps(result.calibration.to_json())   # calibration.json, docs/bundle.md section 2
    Calibration.from_json(doc)                 # back, through magfab.formats.calibration_json.validate

**The model.** Fz and Fr = sqrt(Fx^2 + Fy^2) are each a full bivariate polynomial of order n in the scaled
field u = (Bz - c_z) / s_z, v = (Br - c_r) / s_r, Br = sqrt(Bx^2 + By^2), with the centre c and half-width s
of the scan's own range, so |u|, |v| <= 1 over the scan. Unscaled, the order-6 design matrix holds
Bz^6 ~ 10^30 uT^6 next to 1 and is numerically singular; scaled its condition number stays below ~10^4
(the candidates' table carries both). The shear is split by the field's lateral direction (M14) with a
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

**Temperature.** The field is first corrected to the calibration's temperature, B_k / (1 + a_k (T - T0)),
with coefficients fitted from a scan spanning temperatures or the recipe's (:mod:`.calibration_thermal`);
calibration.json's ``thermal`` says which, and the firmware applies the same correction.

**The guard.** Readings outside the scanned region of (Bz, Br) -- the range box and the convex hull of the
scan points (simplified to the least-area enclosing polygon of at most ``HULL_MAX_VERTICES`` vertices, since
the firmware tests every reading against it) -- are flagged ``in_region = False``; the model's value is still
returned, never silently trusted.

Units: field in microtesla (uT; 1 G = 100 uT), force in newton, lengths in mm, time in s.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError, ScanError
from ..formats import calibration_json
from ..formats.scan_csv import FORCE_COLUMNS, MIN_ROWS, SCAN_COLUMNS, Scan, check_calibration_scan
from ..units import UT_PER_GAUSS
from .calibration_thermal import ThermalFit, correct, fit_thermal, thermal_from_json
from .chip import chip_setting, noise
from .mls import mls as _mls
from .mls import monomials
from .region import HULL_MAX_VERTICES, Scaling, ValidRegion, guard_ops

if TYPE_CHECKING:
    from ..design import Design

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = [
    "FORMAT", "MIN_ROWS", "ORDERS", "MLS_ORDER", "SCAN_COLUMNS", "FORCE_COLUMNS", "HULL_MAX_VERTICES",
    "CalibrationError", "ScanError", "Scan",
    "monomials", "Scaling", "ValidRegion", "MLSModel", "Calibration", "Candidate", "FitResult",
    "fit", "fits_mls", "choose", "poly_ops", "mls_ops", "guard_ops", "evaluation_time_s",
]

FORMAT = calibration_json.FORMAT
#: Polynomial orders every fit tries (the table and the chart show them all).
ORDERS = (1, 2, 3, 4, 5, 6)
#: Order of the local polynomial of moving least squares.
MLS_ORDER = 2
#: MLS bandwidths tried, as multiples of the scan's median nearest-neighbour spacing in (u, v).
MLS_BANDWIDTHS = tuple(float(x) for x in np.geomspace(1.5, 48.0, 11))
#: The shear direction is undefined below this many RMS xy field noise (the chip's and the environment's).
DIRECTION_MIN_SIGMAS = 3.0
#: The valid region reaches this many RMS xy field noise beyond the scan's points (region.ValidRegion.of).
REGION_MARGIN_SIGMAS = 3.0
FORCES = calibration_json.FORCES


class CalibrationError(InputError):
    """A calibration asked for what it cannot give (a candidate not fitted, a method it does not carry, readings
    of the wrong shape): one line naming the value and what is allowed. A scan that cannot be calibrated on
    raises :class:`~magfab.errors.ScanError`, a malformed calibration.json
    :class:`magfab.formats.calibration_json.CalibrationError` (a :class:`~magfab.errors.CalibrationFormatError`)."""


# ---------------------------------------------------------------------------------------------------
# The model: scaling, monomials, polynomial, moving least squares


def _basis(u: np.ndarray, v: np.ndarray, order: int) -> np.ndarray:
    """Design matrix (N, terms) of :func:`monomials` at (u, v)."""
    pu = [np.ones_like(u)]
    pv = [np.ones_like(v)]
    for _ in range(order):
        pu.append(pu[-1] * u)
        pv.append(pv[-1] * v)
    return np.column_stack([pu[i] * pv[j] for i, j in monomials(order)])


def _solve_poly(u: np.ndarray, v: np.ndarray, y: np.ndarray, order: int) -> np.ndarray:
    """Least-squares coefficients (terms, k) of the order-``order`` polynomial through y (N, k)."""
    return np.linalg.lstsq(_basis(u, v, order), y, rcond=None)[0]


# ---------------------------------------------------------------------------------------------------
# Evaluation cost, in floating-point operations (add, multiply, divide, sqrt, exp: one each)


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
    thermal: ThermalFit | None = None

    def corrected(self, B_uT: ArrayLike, temperature_C: ArrayLike | None = None) -> np.ndarray:
        """Readings B_uT (N, 3) uT as at the calibration's temperature (``thermal``: B_k / (1 + a_k (T - T0)))
        given the chip temperatures (N,) degC; unchanged without temperatures or without ``thermal``."""
        b = _readings(B_uT)
        if temperature_C is None or self.thermal is None:
            return b
        t = np.broadcast_to(np.asarray(temperature_C, dtype=float), (len(b),))
        return correct(b, t, self.thermal.reference_C, self.thermal.coefficient_per_C)

    def model(self, B_uT: ArrayLike, method: str | None = None) -> np.ndarray:
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

    def evaluate(self, B_uT: ArrayLike, method: str | None = None,
                 temperature_C: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Force (Fx, Fy, Fz) in N, (N, 3), and in_region (N,) bool, from field readings B_uT (N, 3) uT
        (a single (3,) reading gives (3,) and a bool array of shape ()); with the chip's ``temperature_C``
        (N,) degC the readings are first corrected (:meth:`corrected`).

        docs/bundle.md section 2: Fz and Fr from the model, the tare subtracted from each, then the shear
        split Fx = shear_sign Fr Bx / Br, Fy = shear_sign Fr By / Br (0 where Br < direction_min_uT).
        Readings outside the valid region (or not finite) get the model's value and in_region False.
        """
        b = self.corrected(B_uT, temperature_C)
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

    def zeroed(self, B_rest_uT: ArrayLike) -> Calibration:
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
        if self.thermal is not None:
            doc["thermal"] = self.thermal.as_json()
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
    def from_json(cls, doc: Mapping[str, object]) -> Calibration:
        """A calibration from a parsed calibration.json; :class:`~magfab.formats.calibration_json.CalibrationError`
        naming the key path of the first value the format does not allow."""
        c = calibration_json.validate(dict(doc) if isinstance(doc, Mapping) else doc)
        mls = None
        if c.method == "mls" and c.mls is not None:
            m = c.mls
            mls = MLSModel(m.order, m.bandwidth,
                           *(np.asarray(x, dtype=float) for x in (m.bz_uT, m.br_uT, m.fz_N, m.fr_N)))
        return cls(c.method, c.order, Scaling(c.center[0], c.scale[0], c.center[1], c.scale[1]),
                   np.column_stack([c.coefficients[f] for f in FORCES]), c.shear_sign, c.direction_min_uT,
                   ValidRegion(c.box[0], c.box[1], c.hull), c.errors, c.scan, c.chip, c.tare_N, mls,
                   thermal_from_json(doc, c.thermal))


def _readings(B_uT: ArrayLike) -> np.ndarray:
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

    @property
    def thermal_note(self) -> str:
        """One line: the temperature correction the calibration carries, fitted or the recipe's, and why."""
        t = self.calibration.thermal
        return "" if t is None else f"temperature correction: {t.note}"

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
    """+1 when the force's lateral direction follows the field's (docs/models.md, M14), -1 when opposite: the sign of
    sum(Fx Bx + Fy By) over the scan (+1 for a scan without lateral load)."""
    assert scan.F_N is not None
    s = float(np.sum(scan.F_N[:, 0] * scan.B_uT[:, 0] + scan.F_N[:, 1] * scan.B_uT[:, 1]))
    return -1 if s < 0 else 1


def _chip_json(design: Design) -> tuple[dict[str, object], float]:
    """The ``chip`` object and the RMS xy field noise (uT) predicted for the spec's chip settings."""
    chip = chip_setting(design)
    doc: dict[str, object] = {"gain_sel": chip.gain_sel, "resolution": chip.resolution, "osr": chip.osr,
                              "dig_filt": chip.dig_filt, "lsb_xy_uT": chip.lsb_xy_uT, "lsb_z_uT": chip.lsb_z_uT}
    return doc, noise(design, chip)["total_xy_G"] * UT_PER_GAUSS


def fits_mls(design: Design) -> bool:
    """Whether a calibration of ``design`` fits moving least squares too: only when its ``calibration.method`` may
    choose it (MLS costs seconds)."""
    return design.spec.calibration.method.value != "poly"


def fit(scan: Scan, design: Design, *, mls: bool = True) -> FitResult:
    """Fit every candidate (poly of each order in :data:`ORDERS` and up to ``calibration.order``, and MLS
    unless ``mls`` is False) to ``scan``, cross-validate them and build the calibration the spec's
    ``calibration.method`` chooses (module doc). The chip settings recorded are the spec's."""
    cal = design.spec.calibration
    if scan.rows < MIN_ROWS:
        raise ScanError(f"scan {scan.source}: {scan.rows} rows; a calibration needs at least {MIN_ROWS}")
    check_calibration_scan(scan)  # force columns, plausible values, (Bz, Br) spanning an area: before any work
    F_N = scan.F_N  # the scan's forces: the temperature correction below replaces only its field
    assert F_N is not None
    thermal = fit_thermal(scan.B_uT, F_N, scan.temperature_C, design, cal.order)
    if scan.temperature_C is not None:  # every fit below sees the field as at the calibration's temperature
        scan = replace(scan, B_uT=correct(scan.B_uT, scan.temperature_C, thermal.reference_C,
                                          thermal.coefficient_per_C))
    bz, br = scan.B_uT[:, 2], scan.Br_uT
    y = np.column_stack([F_N[:, 2], scan.Fr_N])
    scaling = Scaling.of(bz, br)
    u, v = scaling(bz, br)
    chip, noise_xy_uT = _chip_json(design)
    region = ValidRegion.of(bz, br, margin_uT=REGION_MARGIN_SIGMAS * noise_xy_uT)
    fold = _folds(scan.rows, cal.folds, cal.seed)
    orders = sorted(set(ORDERS) | {cal.order})
    max_order = max(o for o in orders if len(monomials(o)) * cal.folds <= scan.rows * (cal.folds - 1))
    cands = [_poly_candidate(bz, br, u, v, y, order, fold, cal.folds) for order in orders if order <= max_order]
    if mls or cal.method.value == "mls":
        cands.append(_mls_candidate(bz, br, u, v, y, fold, cal.folds))
    label, meets = choose(cands, cal.method.value, min(cal.order, max_order), cal.tolerance_mN)
    chosen = next(c for c in cands if c.label == label)
    firmware = min((c for c in cands if c.method == "poly" and c.order <= cal.order), key=lambda c: c.worst_rms_N)
    base = Calibration("poly", 0, scaling, np.zeros((1, 2)), _shear_sign(scan), DIRECTION_MIN_SIGMAS * noise_xy_uT,
                       region, {"folds": cal.folds}, {"sha256": scan.sha256, "rows": scan.rows, "source": scan.source,
                                                   **({} if scan.model is None else {"model": dict(scan.model)})},
                       chip, thermal=thermal)
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
