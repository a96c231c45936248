"""The force calibration (``calibration.json``, format ``magfab-calibration/1``) evaluated in Python.

The evaluation follows the bundle format (docs/bundle.md of magfab) step by step, in float64::

    Br = sqrt(Bx^2 + By^2)
    u  = (Bz - scaling.Bz_uT.center) / scaling.Bz_uT.scale
    v  = (Br - scaling.Br_uT.center) / scaling.Br_uT.scale
    F  = sum_m coefficients[F][m] * u^i_m * v^j_m - tare_N[F]        for F in Fz_N, Fr_N
    Fx = shear_sign * Fr * Bx / Br,  Fy = shear_sign * Fr * By / Br  (both 0 when Br < direction_min_uT)

With a ``thermal`` object and the chip's temperature T, each field axis is first divided by
(1 + coefficient_per_C[axis] (T - reference_C)), as the firmware does (docs/bundle.md section 2).

The tare belongs to Fz and Fr (the model's outputs), so it is taken off before Fr is split into Fx and Fy.

``method`` says what the host uses. "poly" is the global polynomial above, which the firmware always
evaluates (``method="poly"`` recomputes the firmware's forces from the raw field to cross-check them).
"mls" is moving least squares over the scan points the file carries under ``mls``: at each query (uq, vq)
a polynomial of order ``mls.order`` in ((u - uq)/h, (v - vq)/h), h = ``mls.bandwidth``, is fitted to the
points with weights exp(-d^2 / 2h^2) (taken relative to the nearest point's; a ridge of 1e-12 times the
trace keeps the normal equations solvable), and its constant term is the (Fz, Fr) there. It is exact to
rounding but slow in pure Python (milliseconds per sample), so it is for recomputing, not for streaming.

The file is checked by ``calibration_json`` (standard library only), the very validator magfab runs before it
renders a readout package: the build and the host refuse exactly the same files.
"""

from __future__ import annotations

import json
import math
import pkgutil

from . import bounded
from .calibration_json import (
    FORCES,
    FORMAT,
    THERMAL_MIN_DENOMINATOR,
    CalibrationError,
    calibration_sha256,
    canonical_json,
    cross,
    monomials,
    validate,
)

__all__ = ["FORMAT", "Calibration", "CalibrationError", "canonical_json", "calibration_sha256", "monomials"]


MLS_CUTOFF = 40.0  # points whose weight is below exp(-40) of the nearest one's add nothing in float64


def _mls_model(checked) -> tuple:
    """(order, bandwidth, monomials, u, v, Fz, Fr) of the validated ``mls`` object, the points scaled to (u, v)."""
    m = checked.mls
    (cz, cr), (sz, sr) = checked.center, checked.scale
    u = [(z - cz) / sz for z in m.bz_uT]
    v = [(r - cr) / sr for r in m.br_uT]
    return m.order, m.bandwidth, tuple((i, j) for i, j in monomials(m.order)), u, v, list(m.fz_N), list(m.fr_N)


def _solve(a: list, b: list) -> list:
    """x of a x = b (a: m x m, b: m x k lists), Gaussian elimination with partial pivoting."""
    m = len(a)
    rows = [list(a[r]) + list(b[r]) for r in range(m)]
    for col in range(m):
        pivot = max(range(col, m), key=lambda r: abs(rows[r][col]))
        rows[col], rows[pivot] = rows[pivot], rows[col]
        p = rows[col][col]
        if p == 0.0:
            raise ZeroDivisionError("singular moving-least-squares system")
        for r in range(col + 1, m):
            f = rows[r][col] / p
            if f:
                rows[r] = [x - f * y for x, y in zip(rows[r], rows[col])]
    k = len(b[0])
    x = [[0.0] * k for _ in range(m)]
    for r in range(m - 1, -1, -1):
        for c in range(k):
            x[r][c] = (rows[r][m + c] - sum(rows[r][j] * x[j][c] for j in range(r + 1, m))) / rows[r][r]
    return x


class Calibration:
    """A validated calibration: evaluates forces from the field and flags readings outside the scanned region.

    Build it from the parsed calibration.json (a dict); :meth:`embedded` gives the one this package was built
    with. Fields in microtesla, forces in newton, sensor frame (+z presses the tip towards the chip).
    """

    def __init__(self, data: dict) -> None:
        checked = validate(data)
        self._center = checked.center
        self._scale = checked.scale
        self._coefficients = checked.coefficients
        self._sign = float(checked.shear_sign)
        self._direction_min = checked.direction_min_uT
        self._tare = checked.tare_N
        self._box = checked.box
        self._hull = checked.hull
        self._hull_tolerance = 1e-9 * checked.span
        self._mls = _mls_model(checked) if checked.mls is not None else None
        self._method = checked.method
        self._order = checked.order
        self._monomials = checked.monomials
        self._thermal = checked.thermal
        self._json = checked.canonical
        self.sha256 = checked.sha256

    # --- construction -------------------------------------------------------------------------------------

    @classmethod
    def from_json(cls, text: str) -> Calibration:
        """Parse calibration.json text (its nesting and keys bounded, :mod:`.bounded`)."""
        try:
            data = bounded.loads_json(text, "calibration.json")
        except bounded.InputFileError:
            raise
        except ValueError as exc:
            raise CalibrationError("", text[:40], f"is not valid JSON ({exc})") from None
        return cls(data)

    @classmethod
    def load(cls, path: str) -> Calibration:
        """Read a calibration.json file: a regular file within its limit (:mod:`.bounded`)."""
        return cls.from_json(bounded.read_text(path, "calibration.json"))

    @classmethod
    def embedded(cls) -> Calibration:
        """The calibration this package was built with (the package's calibration.json)."""
        raw = pkgutil.get_data("magfab_readout", "calibration.json")
        if raw is None:
            raise CalibrationError("", None, "the package's calibration.json cannot be read")
        return cls.from_json(raw.decode("utf-8"))

    def to_dict(self) -> dict:
        """A fresh copy of the calibration as a JSON-ready dict."""
        return json.loads(self._json)

    def with_tare(self, Fz_N: float, Fr_N: float) -> Calibration:
        """The same calibration with ``tare_N`` replaced (the model's Fz and Fr at rest, before any tare)."""
        data = self.to_dict()
        data["tare_N"] = {"Fz_N": float(Fz_N), "Fr_N": float(Fr_N)}
        return Calibration(data)

    # --- facts ----------------------------------------------------------------------------------------------

    @property
    def order(self) -> int:
        """Polynomial order n."""
        return self._order

    @property
    def method(self) -> str:
        """'poly' or 'mls': what the host uses by default (the firmware always evaluates 'poly')."""
        return self._method

    @property
    def short_hash(self) -> str:
        """First 16 hex digits of :attr:`sha256`, as in the firmware's info line."""
        return self.sha256[:16]

    @property
    def hull(self) -> tuple:
        """The valid region's convex hull, ((Bz_uT, Br_uT), ...), counter-clockwise."""
        return self._hull

    @property
    def box(self) -> tuple:
        """((Bz_lo, Bz_hi), (Br_lo, Br_hi)) of the valid region, microtesla."""
        return self._box

    # --- evaluation -----------------------------------------------------------------------------------------

    def _method_of(self, method) -> str:
        method = self._method if method is None else method
        if method not in ("poly", "mls"):
            raise ValueError(f"method must be 'poly', 'mls' or None; instead received {method!r}")
        if method == "mls" and self._mls is None:
            raise ValueError("method 'mls' asked of a calibration without an 'mls' model")
        return method

    def model(self, Bz_uT: float, Br_uT: float, tare: bool = True, method=None) -> tuple:
        """(Fz_N, Fr_N) at (Bz, Br) in microtesla, minus the tare unless ``tare`` is False. ``method``: 'poly'
        (the firmware's), 'mls', or None for the calibration's own."""
        u = (float(Bz_uT) - self._center[0]) / self._scale[0]
        v = (float(Br_uT) - self._center[1]) / self._scale[1]
        if self._method_of(method) == "mls":
            fz, fr = self._moving_least_squares(u, v)
            return (fz - self._tare[0], fr - self._tare[1]) if tare else (fz, fr)
        up = [1.0]
        vp = [1.0]
        for _ in range(self._order):
            up.append(up[-1] * u)
            vp.append(vp[-1] * v)
        out = []
        for f, force in enumerate(FORCES):
            total = math.fsum(c * up[i] * vp[j] for c, (i, j) in zip(self._coefficients[force], self._monomials))
            out.append(total - self._tare[f] if tare else total)
        return out[0], out[1]

    def _moving_least_squares(self, uq: float, vq: float) -> tuple:
        assert self._mls is not None, "called only for the 'mls' method, which _method_of refuses without the model"
        order, h, terms, u, v, fz, fr = self._mls
        d2 = [((a - uq) / h) ** 2 + ((b - vq) / h) ** 2 for a, b in zip(u, v)]
        nearest = min(d2)
        m = len(terms)
        normal = [[0.0] * m for _ in range(m)]
        rhs = [[0.0, 0.0] for _ in range(m)]
        for k, dk in enumerate(d2):
            exponent = 0.5 * (dk - nearest)
            if exponent > MLS_CUTOFF:
                continue
            w = math.exp(-exponent)
            du, dv = (u[k] - uq) / h, (v[k] - vq) / h
            pu, pv = [1.0], [1.0]
            for _ in range(order):
                pu.append(pu[-1] * du)
                pv.append(pv[-1] * dv)
            p = [pu[i] * pv[j] for i, j in terms]
            for r in range(m):
                wp = w * p[r]
                row = normal[r]
                for c in range(r, m):
                    row[c] += wp * p[c]
                rhs[r][0] += wp * fz[k]
                rhs[r][1] += wp * fr[k]
        for r in range(m):
            for c in range(r):
                normal[r][c] = normal[c][r]
        ridge = 1e-12 * sum(normal[r][r] for r in range(m))
        for r in range(m):
            normal[r][r] += ridge
        solution = _solve(normal, rhs)
        return solution[0][0], solution[0][1]

    @property
    def thermal(self):
        """The temperature correction (``reference_C``, ``coefficient_per_C`` (x, y, z), ``source``), or None."""
        return self._thermal

    def corrected(self, Bx_uT: float, By_uT: float, Bz_uT: float, temperature_C=None) -> tuple:
        """The field as at the calibration's temperature: each axis / (1 + a (T - T0)); unchanged without a
        temperature (None or NaN), without ``thermal``, or where a denominator falls below
        ``THERMAL_MIN_DENOMINATOR`` (a temperature outside the chip's range: the validator holds it there inside;
        the firmware leaves it uncorrected too, and flags the sample)."""
        B = (float(Bx_uT), float(By_uT), float(Bz_uT))
        t = self._thermal
        if t is None or temperature_C is None or temperature_C != temperature_C:
            return B
        dt = float(temperature_C) - t.reference_C
        d = [1.0 + a * dt for a in t.coefficient_per_C]
        if not min(d) >= THERMAL_MIN_DENOMINATOR:
            return B
        return tuple(b / dk for b, dk in zip(B, d))

    def evaluate(self, Bx_uT: float, By_uT: float, Bz_uT: float, method=None, temperature_C=None) -> tuple:
        """(Fx_N, Fy_N, Fz_N) for a field in microtesla (chip axes) read at the chip's ``temperature_C`` (degC;
        None: no correction); ``method`` as in :meth:`model`."""
        Bx, By, Bz_uT = self.corrected(Bx_uT, By_uT, Bz_uT, temperature_C)
        Br = math.sqrt(Bx * Bx + By * By)
        Fz, Fr = self.model(Bz_uT, Br, method=method)
        if Br < self._direction_min or Br == 0.0:
            return 0.0, 0.0, Fz
        return self._sign * Fr * Bx / Br, self._sign * Fr * By / Br, Fz

    def in_region(self, Bz_uT: float, Br_uT: float) -> bool:
        """True when (Bz, Br) lies in the scanned region (box and convex hull, boundary included)."""
        Bz, Br = float(Bz_uT), float(Br_uT)
        (zlo, zhi), (rlo, rhi) = self._box
        if not (zlo <= Bz <= zhi and rlo <= Br <= rhi):
            return False
        hull = self._hull
        for k in range(len(hull)):
            a, b = hull[k - 1], hull[k]
            edge = math.hypot(b[0] - a[0], b[1] - a[1])
            if cross(a, b, (Bz, Br)) < -self._hull_tolerance * edge:
                return False
        return True

    def in_region_B(self, Bx_uT: float, By_uT: float, Bz_uT: float) -> bool:
        """:meth:`in_region` for a field vector."""
        return self.in_region(Bz_uT, math.hypot(float(Bx_uT), float(By_uT)))

    def __repr__(self) -> str:
        return f"Calibration(order={self._order}, method={self.method!r}, sha256={self.short_hash}...)"
