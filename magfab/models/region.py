"""The calibration's valid region: the scanned part of (Bz, Br) and the guard that flags readings outside it.

The region is the range box of the scan and the convex hull of its points, simplified to the least-area
enclosing polygon of at most ``HULL_MAX_VERTICES`` vertices, since the firmware tests every reading against
it. Field values in microtesla.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np

from ..errors import ScanError

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["HULL_MAX_VERTICES", "Scaling", "ValidRegion", "guard_ops"]


@dataclass(frozen=True)
class Scaling:
    """u = (Bz - bz_center) / bz_scale, v = (Br - br_center) / br_scale; all in uT."""

    bz_center: float
    bz_scale: float
    br_center: float
    br_scale: float

    @classmethod
    def of(cls, bz: np.ndarray, br: np.ndarray) -> Scaling:
        """Mid-range and half-range of the data (1 uT where the data has no spread), so |u|, |v| <= 1."""
        def axis(x: np.ndarray) -> tuple[float, float]:
            lo, hi = float(np.min(x)), float(np.max(x))
            half = (hi - lo) / 2.0
            return (lo + hi) / 2.0, half if half > 1e-9 * max(abs(lo), abs(hi), 1.0) else 1.0
        return cls(*axis(bz), *axis(br))

    def __call__(self, bz: np.ndarray, br: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (bz - self.bz_center) / self.bz_scale, (br - self.br_center) / self.br_scale


def guard_ops(hull_vertices: int) -> int:
    """Operations of the region guard per reading: the range box (4 compares) and, per hull edge, a cross
    product and its sign (2 sub, 2 mul, 1 sub, 1 compare). The same for every candidate, so kept apart."""
    return 4 + 6 * hull_vertices



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


def _widened(poly: np.ndarray, mu: float, mv: float) -> np.ndarray:
    """The convex CCW polygon ``poly`` (n, 2) with each edge moved outward by the support of the box
    [-mu, mu] x [-mv, mv] in its normal's direction: the intersection of the moved half-planes, which holds
    ``poly`` grown by the box (every point within mu in u and mv in v of it); same vertex count."""
    n = len(poly)
    edges = np.roll(poly, -1, axis=0) - poly
    normals = np.column_stack([edges[:, 1], -edges[:, 0]])  # outward for a CCW polygon
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    offsets = np.einsum("ij,ij->i", normals, poly) + mu * np.abs(normals[:, 0]) + mv * np.abs(normals[:, 1])
    out = []
    for i in range(n):  # vertex i + 1 is where edge i meets edge i + 1
        j = (i + 1) % n
        out.append(np.linalg.solve(np.vstack([normals[i], normals[j]]), [offsets[i], offsets[j]]))
    return np.roll(np.array(out), 1, axis=0)


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
    def of(cls, bz: np.ndarray, br: np.ndarray, max_vertices: int = HULL_MAX_VERTICES,
           margin_uT: float = 0.0) -> ValidRegion:
        """The region of the scan points, widened by ``margin_uT`` on every side (Br not below 0): a reading
        that differs from a scan point by the chip's noise is still inside. The scan's rest point is a corner
        of the region (least indentation, no lateral load), so without the margin a sensor at rest reads
        outside about half the time."""
        from scipy.spatial import ConvexHull

        sc = Scaling.of(bz, br)
        scaled = np.column_stack(sc(bz, br))  # the hull in (u, v): both axes of order 1
        try:
            idx = ConvexHull(scaled).vertices  # counter-clockwise in 2-D
        except (RuntimeError, ValueError) as exc:  # QhullError (a RuntimeError): no area, e.g. all on a line
            raise ScanError(f"the scan's (Bz, Br) points span no area ({str(exc).splitlines()[0]}); "
                                   "a calibration needs a 2-D scan (normal and lateral load)") from None
        poly = _enclosing(scaled[idx], max_vertices)
        if margin_uT > 0:
            # two neighbouring edges parallel: keep the polygon as it is (the box still widens)
            with contextlib.suppress(np.linalg.LinAlgError):
                poly = _widened(poly, margin_uT / sc.bz_scale, margin_uT / sc.br_scale)
        hull = tuple((sc.bz_center + sc.bz_scale * float(u), sc.br_center + sc.br_scale * float(v)) for u, v in poly)
        m = max(margin_uT, 0.0)
        return cls((float(bz.min()) - m, float(bz.max()) + m), (max(float(br.min()) - m, 0.0), float(br.max()) + m),
                   hull)

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
