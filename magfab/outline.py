"""Outlines in the plane for an array's parts: the convex hull of the taxel centres grown by a radius.

A pad under an array, the lip round a continuous skin and the skin itself are each the set of points within a
radius of the taxels' convex hull (the Minkowski sum of the hull and a disc): straight edges parallel to the hull's,
joined by arcs about its corners. One taxel gives a circle, a row a stadium. The same outline feeds the CAD solids
(:func:`segments`: lines and three-point arcs, exact), the mesh checks (:func:`polygon`: sampled) and the design's
closed-form figures (:func:`area`, :func:`distance`).
"""

from __future__ import annotations

import math

__all__ = ["hull", "segments", "polygon", "area", "distance"]

Point = tuple[float, float]


def hull(points: list[Point]) -> list[Point]:
    """Convex hull, counter-clockwise from the lowest-leftmost point (Andrew's monotone chain); collinear points
    give the two ends, one point itself."""
    pts = sorted(set(points))
    if len(pts) <= 2:
        return pts

    def half(seq):
        out: list[Point] = []
        for p in seq:
            while len(out) >= 2 and (out[-1][0] - out[-2][0]) * (p[1] - out[-2][1]) \
                    - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0]) <= 1e-12:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(reversed(pts))
    return lower[:-1] + upper[:-1]


def _normals(h: list[Point]) -> list[float]:
    """The outward normal's angle of each edge h[i] -> h[i+1] (the right-hand side of a counter-clockwise walk)."""
    out = []
    for i, (x0, y0) in enumerate(h):
        x1, y1 = h[(i + 1) % len(h)]
        out.append(math.atan2(-(x1 - x0), y1 - y0))
    return out


def segments(h: list[Point], r: float) -> list[tuple[Point, ...]]:
    """The grown outline as a closed chain, counter-clockwise: ``(start, end)`` lines and ``(start, mid, end)`` arcs
    (each arc about a hull corner, ``mid`` halfway round it). Empty for a single point (a circle: say so yourself)."""
    if len(h) < 2:
        return []
    normals = _normals(h)
    out: list[tuple[Point, ...]] = []
    for i, a0 in enumerate(normals):
        (x0, y0), (x1, y1) = h[i], h[(i + 1) % len(h)]
        c, s = r * math.cos(a0), r * math.sin(a0)
        out.append(((x0 + c, y0 + s), (x1 + c, y1 + s)))
        a1 = normals[(i + 1) % len(h)]
        turn = (a1 - a0) % (2.0 * math.pi) or 2.0 * math.pi  # counter-clockwise, in (0, pi] for a convex hull
        mid = a0 + turn / 2.0
        out.append(((x1 + c, y1 + s), (x1 + r * math.cos(mid), y1 + r * math.sin(mid)),
                    (x1 + r * math.cos(a1), y1 + r * math.sin(a1))))
    return out


def polygon(h: list[Point], r: float, facets: int = 128) -> list[Point]:
    """The grown outline sampled counter-clockwise, its arcs at ``facets`` per full turn (vertices on the outline,
    so the polygon lies inside it by at most r (1 - cos(pi / facets)))."""
    if len(h) == 1:
        (x, y), = h
        return [(x + r * math.cos(2 * math.pi * k / facets), y + r * math.sin(2 * math.pi * k / facets))
                for k in range(facets)]
    normals = _normals(h)
    pts: list[Point] = []
    for i, a0 in enumerate(normals):
        x1, y1 = h[(i + 1) % len(h)]
        a1 = normals[(i + 1) % len(h)]
        turn = (a1 - a0) % (2.0 * math.pi) or 2.0 * math.pi
        steps = max(1, math.ceil(turn / (2.0 * math.pi) * facets))
        pts += [(x1 + r * math.cos(a0 + turn * k / steps), y1 + r * math.sin(a0 + turn * k / steps))
                for k in range(steps + 1)]
    return pts


def area(h: list[Point], r: float) -> float:
    """Area of the grown outline (Steiner: the hull's area, its perimeter times r, and one disc)."""
    n = len(h)
    a = 0.5 * abs(sum(h[i][0] * h[(i + 1) % n][1] - h[(i + 1) % n][0] * h[i][1] for i in range(n))) if n > 2 else 0.0
    perimeter = sum(math.dist(h[i], h[(i + 1) % n]) for i in range(n)) if n > 1 else 0.0
    return a + perimeter * r + math.pi * r * r


def distance(p: Point, h: list[Point]) -> float:
    """Distance from ``p`` to the hull (zero inside it); ``r - distance`` is how far inside the grown outline."""
    n = len(h)
    if n == 1:
        return math.dist(p, h[0])
    best = math.inf
    inside = n > 2
    for i in range(n):
        (x0, y0), (x1, y1) = h[i], h[(i + 1) % n]
        dx, dy = x1 - x0, y1 - y0
        t = min(1.0, max(0.0, ((p[0] - x0) * dx + (p[1] - y0) * dy) / (dx * dx + dy * dy)))
        best = min(best, math.dist(p, (x0 + t * dx, y0 + t * dy)))
        inside = inside and dx * (p[1] - y0) - dy * (p[0] - x0) >= 0.0
    return 0.0 if inside else best
