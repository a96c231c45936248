"""array.json (format ``magfab-array/1``, docs/bundle.md section 5): an array's taxels and how the host removes
what each chip reads of the other taxels' magnets. The one validator and the one compensation.

Standard library only: a module of the readout package (shipped verbatim in every build; an array build's package
uses it), which magfab imports as :mod:`magfab.formats.array_json`, so the build's tests and the host compute the
same numbers.

The compensation of one cycle of readings ``B[k]`` (uT, chip axes, one per taxel)::

    B'[k] = B[k] - offset[k] - sum over j != k of  A_kj(z_j) + s_j (D(r_kj - t_j) - D(r_kj - z_j))

``offset[k]`` is the field of every other magnet at chip k at rest and ``A_kj(z)`` the change at chip k when
magnet j travels z towards its chip (both exact, computed by magfab; ``neighbour_uT[k][j]`` over ``travel_mm``);
``D`` the field of the magnet's moment (below), ``r_kj`` chip k from magnet j's centre at rest, ``s_j`` its
polarity. Magnet j's motion ``t_j`` (its axial part ``z_j``) is read from its own chip: the travel by
inverting the own field's Bz along the axis (``travel_mm`` -> ``own_Bz_uT``, for polarity +1), and with the
lateral offset from the own field's (Bx, Bz) over travel and offset (``own_lateral_uT`` over ``travel_mm`` x
``lateral_mm``, the magnet shifted along +x: for each offset the travel that gives the measured Bz, then the offset
whose |Bx| there is the measured lateral field; the direction is the lateral field's). ``D`` is the field of the
magnet's moment spread over its cylinder (``magnet_mm``: radius, height) as 2 x 6 x 2 point dipoles
(Gauss-Legendre in radius and height, even in angle), so the lateral part converges on the exact field much
faster than one dipole with distance. So the axial part, most of it, is exact and only the lateral part rests on
the dipoles. The motions are estimated from the cleaned fields again, SWEEPS times (Jacobi). With ``dynamic``
false only the offsets are removed. Each taxel's calibration (its
own file) then takes ``B'[k]`` as a single taxel's calibration takes B.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Sequence
from typing import Tuple

from .json_checks import FormatError, finite, is_finite, lookup

__all__ = ["FORMAT", "ArrayError", "Compensator", "validate"]

FORMAT = "magfab-array/1"
MAX_TAXELS = 16
#: Jacobi sweeps of the motion estimate: each taxel's own field is cleaned of its neighbours' motion, then read again
#: (a 1x5 strip at 14 mm, one magnet slid 2.5 mm: 55 mN left after 2 sweeps with a linear lateral rate, 0.54 after 3
#: with the tables, 0.22 after 4, 0.04 after 5; each costs the same again).
SWEEPS = 4

Vector = Tuple[float, float, float]  # evaluated at import: the readout's Python 3.8 has no tuple[...]


class ArrayError(FormatError):
    """An array.json that does not hold what format magfab-array/1 requires."""

    file = "array.json"


def _vectors(data: dict, key: str, n: int, name: str = "") -> list[Vector]:
    """The ``n`` [x, y, z] triples at ``key``; ``name`` is the key path the error names (``key`` by default)."""
    rows = lookup(data, key, ArrayError)
    if not isinstance(rows, list) or len(rows) != n or not all(
            isinstance(r, list) and len(r) == 3 and all(is_finite(x) for x in r) for r in rows):
        raise ArrayError(name or key, rows, f"must be {n} [x, y, z] triples of finite numbers, one per "
                         + ("point of travel_mm" if name else "taxel"))
    return [(float(r[0]), float(r[1]), float(r[2])) for r in rows]


def _table(data: dict, key: str, length: int = 0) -> list[float]:
    values = lookup(data, key, ArrayError)
    if not isinstance(values, list) or len(values) < 2 or (length and len(values) != length) or not all(
            is_finite(x) for x in values):
        raise ArrayError(key, values, "must be a list of finite numbers" + (f", {length} long" if length else
                                                                           ", at least 2"))
    return [float(x) for x in values]


def validate(data: object) -> Compensator:
    """The compensation array.json describes, or :class:`ArrayError` naming the key, the value and what is allowed."""
    if not isinstance(data, dict):
        raise ArrayError("", type(data).__name__, "must be a JSON object")
    if data.get("format") != FORMAT:
        raise ArrayError("format", data.get("format"), f"must be {FORMAT!r}")
    taxels = lookup(data, "taxels", ArrayError)
    if not isinstance(taxels, list) or not 2 <= len(taxels) <= MAX_TAXELS:
        raise ArrayError("taxels", taxels, f"must be a list of 2 to {MAX_TAXELS} taxels")
    for i, t in enumerate(taxels):
        # JSON's true and false are Python's bools, which equal 1 and 0 and are ints: none is an index, a polarity
        # or an address.
        if not isinstance(t, dict) or any(isinstance(t.get(k), bool) for k in ("index", "polarity", "i2c_address")) \
                or t.get("index") != i or t.get("polarity") not in (1, -1) \
                or not isinstance(t.get("calibration"), str) or not isinstance(t.get("i2c_address"), int):
            raise ArrayError(f"taxels[{i}]", t, f"must hold index {i}, polarity 1 or -1, an integer i2c_address and "
                             "a calibration file name")
    n = len(taxels)
    travel = _table(data, "travel_mm")
    if any(b <= a for a, b in zip(travel, travel[1:])):
        raise ArrayError("travel_mm", travel, "must increase")
    own = _table(data, "own_Bz_uT", len(travel))
    if any(b <= a for a, b in zip(own, own[1:])):
        raise ArrayError("own_Bz_uT", own, "must increase with the travel (the magnet nears its chip)")
    lateral = _table(data, "lateral_mm")
    if lateral[0] != 0.0 or any(b <= a for a, b in zip(lateral, lateral[1:])):
        raise ArrayError("lateral_mm", lateral, "must start at 0 and increase")
    table = lookup(data, "own_lateral_uT", ArrayError)
    if not isinstance(table, list) or len(table) != len(travel) or not all(
            isinstance(row, list) and len(row) == len(lateral) and all(
                isinstance(v, list) and len(v) == 2 and all(is_finite(x) for x in v) for v in row)
            for row in table):
        raise ArrayError("own_lateral_uT", table, f"must be {len(travel)} x {len(lateral)} [Bx, Bz] pairs")
    size = _table(data, "magnet_mm", 2)
    if not all(x > 0 for x in size):
        raise ArrayError("magnet_mm", size, "must be the magnet's radius and height, both positive")
    if not isinstance(data.get("dynamic"), bool):
        raise ArrayError("dynamic", data.get("dynamic"), "must be true or false")
    rows = lookup(data, "neighbour_uT", ArrayError)
    if not isinstance(rows, list) or len(rows) != n or not all(isinstance(r, list) and len(r) == n for r in rows):
        raise ArrayError("neighbour_uT", rows, f"must be {n} x {n} tables (chip k, magnet j)")
    neighbour = [[_vectors({"t": rows[k][j]}, "t", len(travel), f"neighbour_uT[{k}][{j}]") for j in range(n)]
                 for k in range(n)]
    if data.get("rest_uT") is not None:  # optional (the host then takes the own field at rest from own_Bz_uT)
        _vectors(data, "rest_uT", n)
    return Compensator([t["polarity"] for t in taxels], _vectors(data, "chips_mm", n), _vectors(data, "centres_mm", n),
                       _vectors(data, "offset_uT", n), travel, own, (lateral, table, size), neighbour,
                       finite(data, "moment_uT_mm3", ArrayError, positive=True), data["dynamic"])


def _locate(x: float, xs: Sequence[float]) -> tuple[int, float]:
    """(i, f) with x = xs[i] + f (xs[i + 1] - xs[i]) in increasing ``xs``, held at the ends (f 0 or 1)."""
    if x <= xs[0]:
        return 0, 0.0
    if x >= xs[-1]:
        return len(xs) - 2, 1.0
    hi = bisect_left(xs, x)
    return hi - 1, (x - xs[hi - 1]) / (xs[hi] - xs[hi - 1])


def _interp(x: float, xs: Sequence[float], ys: Sequence[float]) -> float:
    """Linear interpolation in increasing ``xs``, held at the ends."""
    i, f = _locate(x, xs)
    return ys[i] + f * (ys[i + 1] - ys[i])


def _cylinder_points(radius: float, height: float) -> list[tuple[float, float, float, float]]:
    """(x, y, z, weight) of 2 x 6 x 2 point dipoles filling a cylinder of unit total weight: Gauss-Legendre nodes in
    r^2 (equal areas) and in z, six angles."""
    g = 1.0 / math.sqrt(3.0)
    out = []
    for u in ((1 - g) / 2, (1 + g) / 2):  # r^2 / R^2 at the two Gauss nodes on [0, 1]
        rho = radius * math.sqrt(u)
        for m in range(6):
            phi = math.pi * (2 * m + (u > 0.5)) / 6
            for h in (-g * height / 2, g * height / 2):
                out.append((rho * math.cos(phi), rho * math.sin(phi), h, 1.0 / 24))
    return out


def dipole_uT(moment_uT_mm3: float, r: Vector) -> Vector:
    """Field (uT) of a +z point dipole at displacement ``r`` (mm) from it: m (3 (z.r) r / |r|^5 - z / |r|^3)."""
    d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    d = math.sqrt(d2)
    k = moment_uT_mm3 / (d2 * d)
    c = 3.0 * r[2] / d2
    return (k * c * r[0], k * c * r[1], k * (c * r[2] - 1.0))


class Compensator:
    """Removes from each taxel's reading what the other magnets put there (module doc)."""

    def __init__(self, polarity, chips, centres, offset, travel, own, lateral, neighbour, moment, dynamic) -> None:
        self.polarity, self.chips, self.centres, self.offset = polarity, chips, centres, offset
        self.travel, self.own, self.neighbour = travel, own, neighbour
        self.lateral, self.table, (radius, height) = lateral
        self.moment, self.dynamic = moment, dynamic
        self.points = [(x, y, z, moment * w) for x, y, z, w in _cylinder_points(radius, height)]
        # The tables by column, read once: each lateral offset's Bz over travel (None where not monotonic) and |Bx|;
        # each chip's and magnet's axial change per axis.
        self._columns = []
        for k in range(len(self.lateral)):
            bz = [row[k][1] for row in self.table]
            self._columns.append((bz if all(b > a for a, b in zip(bz, bz[1:])) else None,
                                  [row[k][0] for row in self.table]))
        self._axial = [[tuple([v[a] for v in self.neighbour[k][j]] for a in range(3)) for j in range(len(chips))]
                       for k in range(len(chips))]

    @property
    def taxels(self) -> int:
        return len(self.chips)

    def _motion(self, j: int, b: Vector) -> Vector:
        """Magnet j's displacement (mm, board frame) from its own field ``b`` (neighbours removed)."""
        s = self.polarity[j]
        bz, br = s * b[2], math.hypot(b[0], b[1])
        dz = _interp(bz, self.own, self.travel)
        if br == 0.0:
            return (0.0, 0.0, -dz)
        prev = None
        for off, (column_bz, column_bx) in zip(self.lateral, self._columns):  # the first offset whose |Bx| reaches br
            z = _interp(bz, column_bz, self.travel) if column_bz is not None else dz
            r = abs(_interp(z, self.travel, column_bx))
            if r >= br and prev is not None:
                f = (br - prev[2]) / (r - prev[2]) if r != prev[2] else 1.0
                off, z = prev[0] + f * (off - prev[0]), prev[1] + f * (z - prev[1])
                break
            prev = (off, z, r)
        # the chip's lateral field is s * sign(table) * |Bx| along the magnet's shift: the shift is along it or against
        sign = -1.0 if self.table[0][1][0] * s < 0 else 1.0
        return (sign * off * b[0] / br, sign * off * b[1] / br, -z)

    def _from(self, j: int, k: int, t: Vector, at: tuple[int, float] | None = None) -> Vector:
        """What magnet j moved by ``t`` changes at chip k (uT): the exact axial table (``at``: where -t_z lies in
        the travel, found when None), the lateral part by the spread moment."""
        c, p = self.centres[j], self.chips[k]
        i, f = at if at is not None else _locate(-t[2], self.travel)
        axial = [v[i] + f * (v[i + 1] - v[i]) for v in self._axial[k][j]]
        lowered = (p[0] - c[0], p[1] - c[1], p[2] - c[2] - t[2])
        if t[0] == 0.0 and t[1] == 0.0:  # no lateral motion: the two spread fields are the same
            return (axial[0], axial[1], axial[2])
        a = self._spread((lowered[0] - t[0], lowered[1] - t[1], lowered[2]))
        b = self._spread(lowered)
        s = self.polarity[j]
        return (axial[0] + s * (a[0] - b[0]), axial[1] + s * (a[1] - b[1]), axial[2] + s * (a[2] - b[2]))

    def _spread(self, r: Vector) -> Vector:
        """The moment spread over the magnet's cylinder (module doc), at displacement ``r`` from its centre (the
        sum of :func:`dipole_uT` over the points, inlined)."""
        x = y = z = 0.0
        rx, ry, rz = r
        for px, py, pz, m in self.points:
            dx, dy, dz = rx - px, ry - py, rz - pz
            d2 = dx * dx + dy * dy + dz * dz
            k = m / (d2 * math.sqrt(d2))
            c = 3.0 * dz / d2
            x += k * c * dx
            y += k * c * dy
            z += k * (c * dz - 1.0)
        return (x, y, z)

    def apply(self, readings: Sequence[Sequence[float]]) -> list[Vector]:
        """One cycle's readings (one [Bx, By, Bz] uT per taxel, in taxel order) -> each taxel's own field."""
        n = self.taxels
        if len(readings) != n:
            raise ValueError(f"{len(readings)} readings for {n} taxels")
        base = [tuple(float(r[a]) - self.offset[k][a] for a in range(3)) for k, r in enumerate(readings)]
        if not self.dynamic:
            return base
        own = list(base)
        for _ in range(SWEEPS):
            motion = [self._motion(j, own[j]) for j in range(n)]
            at = [_locate(-t[2], self.travel) for t in motion]
            own = []
            for k in range(n):
                extra = [self._from(j, k, motion[j], at[j]) for j in range(n) if j != k]
                own.append(tuple(base[k][a] - sum(e[a] for e in extra) for a in range(3)))
        return own
