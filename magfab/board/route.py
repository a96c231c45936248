"""Copper geometry, clearance measurement and a small deterministic two-layer grid router.

Everything is in millimetres in the board's KiCad frame (y down). Copper items are :class:`Copper`:
an axis-aligned rectangle (pads, conservatively: a roundrect lies inside its rectangle), a segment
with a half-width (tracks), or a point with a radius (vias, round pads, holes). Distances are edge to
edge; two items touch when the distance is <= 0.

The router is a Lee/A* maze router on a square grid over both copper layers: eight directions per
layer, a via between layers, a penalty per bend so tracks come out straight. Obstacles are the copper of
other nets, holes and the board edge, each grown by the clearance plus the track's (or via's) half
width plus a small margin that covers the corner a grid step can cut. The result is re-measured
exactly by :func:`clearance_violations`, which is what the build trusts.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import MagfabError

__all__ = ["HOLE_TO_HOLE_MM", "LAYERS", "Copper", "distance", "near", "touching", "is_via", "via_clearance",
           "clearance_violations", "connected", "Router", "RouteError"]

LAYERS = ("F.Cu", "B.Cu")
HOLE_TO_HOLE_MM = 0.25  # drill wall to drill wall (KiCad 6 default min_hole_to_hole)
GRID_MARGIN_MM = 0.02  # > the sagitta a 0.125 mm grid step can cut from a 0.25 mm-radius obstacle
SOFT_COST = 2.0  # per grid step through another connection's track, in a rip-up search
MAX_EXPANSIONS = 80_000  # a search that needs more is treated as blocked (fails in well under 1 s)
HEURISTIC_WEIGHT = 1.5  # weighted A*: paths within 1.5x of the cheapest, an order of magnitude fewer nodes

Point = tuple[float, float]  # (x, y) mm


@dataclass(frozen=True)
class Copper:
    """One piece of copper (or a hole when ``net`` is None and ``hole`` is set)."""

    kind: str  # "rect" | "seg" | "point"
    a: tuple[float, float]
    b: tuple[float, float]  # rect: opposite corner; seg: end; point: same as a
    r: float  # half-width / radius (0 for rect)
    layers: frozenset[str]
    net: str | None
    owner: str = ""  # "U1.15", "track", "via", "H1"
    hole: bool = False

    @staticmethod
    def rect(x0: float, y0: float, x1: float, y1: float, layers: Iterable[str], net: str | None,
             owner: str = "") -> Copper:
        return Copper("rect", (min(x0, x1), min(y0, y1)), (max(x0, x1), max(y0, y1)), 0.0, frozenset(layers), net,
                      owner)

    @staticmethod
    def seg(x0: float, y0: float, x1: float, y1: float, width: float, layer: str, net: str | None,
            owner: str = "track") -> Copper:
        return Copper("seg", (x0, y0), (x1, y1), width / 2, frozenset({layer}), net, owner)

    @staticmethod
    def point(x: float, y: float, radius: float, layers: Iterable[str], net: str | None, owner: str = "",
              hole: bool = False) -> Copper:
        return Copper("point", (x, y), (x, y), radius, frozenset(layers), net, owner, hole)

    def bbox(self) -> tuple[float, float, float, float]:
        return (min(self.a[0], self.b[0]) - self.r, min(self.a[1], self.b[1]) - self.r,
                max(self.a[0], self.b[0]) + self.r, max(self.a[1], self.b[1]) + self.r)


# ---------------------------------------------------------------------------------------------------
# Exact distances between cores (segments and rectangles; a point is a zero-length segment)


def _pt_seg(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    t = 0.0 if L2 == 0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / L2))
    return math.hypot(px - ax - t * dx, py - ay - t * dy)


def _cross(ox, oy, ax, ay, bx, by) -> float:
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


def _segs_cross(a, b, c, d) -> bool:
    d1, d2 = _cross(*c, *d, *a), _cross(*c, *d, *b)
    d3, d4 = _cross(*a, *b, *c), _cross(*a, *b, *d)
    return d1 * d2 < 0 and d3 * d4 < 0


def _seg_seg(a, b, c, d) -> float:
    if _segs_cross(a, b, c, d):
        return 0.0
    return min(_pt_seg(*a, *c, *d), _pt_seg(*b, *c, *d), _pt_seg(*c, *a, *b), _pt_seg(*d, *a, *b))


def _pt_rect(px: float, py: float, lo, hi) -> float:
    dx = max(lo[0] - px, 0.0, px - hi[0])
    dy = max(lo[1] - py, 0.0, py - hi[1])
    return math.hypot(dx, dy)


def _seg_rect(a: Point, b: Point, lo: Point, hi: Point) -> float:
    if _pt_rect(*a, lo, hi) == 0.0 or _pt_rect(*b, lo, hi) == 0.0:
        return 0.0
    corners = [lo, (hi[0], lo[1]), hi, (lo[0], hi[1])]
    edges = list(zip(corners, corners[1:] + corners[:1]))
    return min(_seg_seg(a, b, c, d) for c, d in edges)


def _rect_rect(lo1, hi1, lo2, hi2) -> float:
    dx = max(lo2[0] - hi1[0], 0.0, lo1[0] - hi2[0])
    dy = max(lo2[1] - hi1[1], 0.0, lo1[1] - hi2[1])
    return math.hypot(dx, dy)


def distance(p: Copper, q: Copper) -> float:
    """Edge-to-edge distance in the plane, mm (<= 0: touching or overlapping)."""
    if p.kind == "rect" and q.kind == "rect":
        core = _rect_rect(p.a, p.b, q.a, q.b)
    elif p.kind == "rect":
        core = _seg_rect(q.a, q.b, p.a, p.b)
    elif q.kind == "rect":
        core = _seg_rect(p.a, p.b, q.a, q.b)
    else:
        core = _seg_seg(p.a, p.b, q.a, q.b)
    return core - p.r - q.r


def near(p: Copper, q: Copper, gap: float) -> bool:
    """Whether the bounding boxes come within ``gap`` (mm): the cheap test before :func:`distance`."""
    a, b = p.bbox(), q.bbox()
    return not (a[2] + gap < b[0] or b[2] + gap < a[0] or a[3] + gap < b[1] or b[3] + gap < a[1])


def touching(a: Copper, b: Copper) -> bool:
    """Whether two pieces of copper share a layer and meet (edge distance <= 0)."""
    return bool(a.layers & b.layers) and distance(a, b) <= 0.0


def is_via(c: Copper) -> bool:
    return c.kind == "point" and not c.hole and len(c.layers) == 2


def via_clearance(clearance: float, hole_clearance: float, via_radius: float, via_drill: float) -> float:
    """Copper clearance a via's pad needs: its drill must also keep ``hole_clearance`` from other nets'
    copper (KiCad checks both), which binds when the annular ring is narrow."""
    return max(clearance, hole_clearance - (via_radius - via_drill / 2))


def clearance_violations(items: Sequence[Copper], clearance: float, hole_clearance: float,
                         via_drill: float | None = None):
    """Pairs of copper of different nets (or copper and a hole) on a shared layer closer than allowed.
    With ``via_drill``, a via's drill is held to ``hole_clearance`` as well (see :func:`via_clearance`).

    Returns ``[(item, item, distance, required)]``, smallest margin first.
    """
    out = []
    for i, p in enumerate(items):
        for q in items[i + 1:]:
            if p.hole and q.hole:
                continue
            if not p.hole and not q.hole and (p.net == q.net or not (p.layers & q.layers)):
                continue
            need = hole_clearance if (p.hole or q.hole) else clearance
            if via_drill is not None and not (p.hole or q.hole):
                for v in (p, q):
                    if is_via(v):
                        need = max(need, via_clearance(clearance, hole_clearance, v.r, via_drill))
            if not near(p, q, need):
                continue
            d = distance(p, q)
            if d < need - 1e-6:
                out.append((p, q, d, need))
    out.sort(key=lambda t: t[2] - t[3])
    return out


def connected(items: Sequence[Copper]) -> dict[str, int]:
    """Number of separate copper islands per net (1 means the net is fully connected)."""
    parent = list(range(len(items)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, p in enumerate(items):
        for j in range(i + 1, len(items)):
            q = items[j]
            if p.net is None or p.net != q.net or not (p.layers & q.layers) or not near(p, q, 0.0):
                continue
            if distance(p, q) <= 1e-9:
                parent[find(i)] = find(j)
    roots: dict[str, set[int]] = {}
    for i, p in enumerate(items):
        if p.net is not None:
            roots.setdefault(p.net, set()).add(find(i))
    return {net: len(r) for net, r in sorted(roots.items())}


# ---------------------------------------------------------------------------------------------------
# Router


class RouteError(MagfabError):
    """No path for one connection. The board's rip-up loop catches it and reports what stays unrouted as
    a finding; should one escape, a feasible spec was routed wrong: our bug (exit 1), not the input's."""

    def __init__(self, message: str, enclosed: bool = False) -> None:
        super().__init__(message)
        self.enclosed = enclosed  # the window cut the search off nowhere: a larger one makes the same steps


_DIRS = ((1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1))


@dataclass
class Router:
    """Grid router over the rectangle ``bounds`` = (x0, y0, x1, y1) with grid ``step`` (mm)."""

    bounds: tuple[float, float, float, float]
    step: float
    width: float
    via_diameter: float
    via_drill: float
    clearance: float
    hole_clearance: float
    edge_clearance: float
    via_cost: float = 8.0
    bend_cost: float = 0.6
    bottom_cost: float = 1.3
    history: np.ndarray | None = None  # congestion cost per grid node, raised by :meth:`congest`

    def __post_init__(self) -> None:
        x0, y0, x1, y1 = self.bounds
        self.nx = round(float((x1 - x0) / self.step)) + 1
        self.ny = round(float((y1 - y0) / self.step)) + 1
        self.xs = x0 + self.step * np.arange(self.nx)
        self.ys = y0 + self.step * np.arange(self.ny)
        self._masks: dict = {}  # (item, distance) -> :meth:`_near_mask`
        self._ids: dict = {}  # (item, layer) -> :meth:`_inside_ids`

    def node_xy(self, ix: int, iy: int) -> tuple[float, float]:
        return (round(float(self.xs[ix]), 6), round(float(self.ys[iy]), 6))

    # -- rasterising obstacles --------------------------------------------------------------------

    def _blocked(self, items: Sequence[Copper], net: str, grow: float, via: bool = False) -> np.ndarray:
        """Boolean [layer, y, x]: nodes where copper of half-width ``grow`` (a via's pad if ``via``)
        would violate a rule."""
        via_need = via_clearance(self.clearance, self.hole_clearance, self.via_diameter / 2, self.via_drill)
        out = np.zeros((2, self.ny, self.nx), dtype=bool)
        x0, y0, x1, y1 = self.bounds
        edge = self.edge_clearance + grow + GRID_MARGIN_MM
        ex = (self.xs < x0 + edge) | (self.xs > x1 - edge)
        ey = (self.ys < y0 + edge) | (self.ys > y1 - edge)
        out[:, ey, :] = True
        out[:, :, ex] = True
        for it in items:
            if it.net == net and not it.hole:
                continue
            need = self.hole_clearance if it.hole else (via_need if (via or is_via(it)) else self.clearance)
            hit = self._near_mask(it, need + grow + GRID_MARGIN_MM)
            if hit is not None:
                j0, j1, i0, i1, mask, layers = hit
                for li in layers:
                    out[li, j0:j1, i0:i1] |= mask
        return out

    def _near_mask(self, it: Copper, need: float):
        """(rows j0:j1, columns i0:i1, mask, layer indices) of the nodes closer than ``need`` to an item's
        copper, or None when none is: each item's is computed once per router (the pads, holes and stubs stay
        while connection after connection is routed around them)."""
        key = (it, need)
        if key in self._masks:
            return self._masks[key]
        x0, y0 = self.bounds[0], self.bounds[1]
        bx0, by0, bx1, by1 = it.bbox()
        i0 = max(0, math.floor((bx0 - need - x0) / self.step))
        i1 = min(self.nx, math.ceil((bx1 + need - x0) / self.step) + 1)
        j0 = max(0, math.floor((by0 - need - y0) / self.step))
        j1 = min(self.ny, math.ceil((by1 + need - y0) / self.step) + 1)
        hit = None
        if i0 < i1 and j0 < j1:
            X, Y = np.meshgrid(self.xs[i0:i1], self.ys[j0:j1])
            layers = tuple(li for li, layer in enumerate(LAYERS)
                           if it.hole or layer in it.layers or "*.Cu" in it.layers)
            hit = (j0, j1, i0, i1, _field(it, X, Y) < need, layers)
        self._masks[key] = hit
        return hit

    def _inside(self, item: Copper, layer_index: int) -> list[int]:
        """Grid nodes (flat ids) inside an item's copper on one layer."""
        return self._inside_ids(item, layer_index).tolist()

    def _inside_ids(self, item: Copper, layer_index: int) -> np.ndarray:
        """:meth:`_inside` as an array of flat ids, computed once per item and layer."""
        key = (item, layer_index)
        if key in self._ids:
            return self._ids[key]
        bx0, by0, bx1, by1 = item.bbox()
        x0, y0 = self.bounds[0], self.bounds[1]
        i0 = max(0, math.ceil((bx0 - x0) / self.step - 1e-9))
        i1 = min(self.nx, math.floor((bx1 - x0) / self.step + 1e-9) + 1)
        j0 = max(0, math.ceil((by0 - y0) / self.step - 1e-9))
        j1 = min(self.ny, math.floor((by1 - y0) / self.step + 1e-9) + 1)
        ids = np.zeros(0, dtype=np.int64)
        if i0 < i1 and j0 < j1:
            X, Y = np.meshgrid(self.xs[i0:i1], self.ys[j0:j1])
            jj, ii = np.nonzero(_field(item, X, Y) <= 1e-9)
            ids = (layer_index * self.ny + jj + j0) * self.nx + ii + i0
        self._ids[key] = ids
        return ids

    # -- search -----------------------------------------------------------------------------------

    def route(self, items: list[Copper], net: str, source: Copper, target: Copper,
              soft: Sequence[Copper] = ()) -> list[Copper]:
        """Tracks and vias joining ``source`` to ``target`` (pads of ``net``) around ``items``.

        ``soft`` copper (other connections' tracks, in a rip-up search) may be crossed at a cost of
        SOFT_COST per grid step, plus the congestion history of the nodes (see :meth:`congest`). The
        search first stays within a window around the two pads (fast), then tries the whole board.
        """
        try:
            return self._route(items, net, source, target, 4.0, soft)
        except RouteError as exc:
            if exc.enclosed:  # the window cut nothing off: the whole board fails the same way
                raise
            return self._route(items, net, source, target, None, soft)

    def congest(self, path: Sequence[Copper], amount: float = 1.0) -> None:
        """Raise the cost of the grid nodes under ``path`` (negotiated congestion, as in PathFinder):
        where two connections keep wanting the same place, each rip-up makes it dearer for both."""
        if self.history is None:
            self.history = np.zeros(2 * self.nx * self.ny)
        for c in path:
            for li, layer in enumerate(LAYERS):
                if layer in c.layers:
                    self.history[self._inside_ids(c, li)] += amount

    def _route(self, items: list[Copper], net: str, source: Copper, target: Copper, window_mm: float | None,
               soft: Sequence[Copper] = ()) -> list[Copper]:
        track, extra, via_ok = self._costs(items, net, soft)
        starts = [n for li, layer in enumerate(LAYERS) if layer in source.layers for n in self._inside(source, li)]
        goals = {n for li, layer in enumerate(LAYERS) if layer in target.layers for n in self._inside(target, li)}
        starts = [n for n in starts if not track[n]] or starts
        if not starts or not goals:
            raise RouteError(f"net {net}: pad {source.owner} or {target.owner} has no grid node inside it")
        window = self._window(source, target, window_mm)
        budget = MAX_EXPANSIONS * (4 if soft else 1)  # crossing soft copper widens the search
        end, came, enclosed = self._search(starts, goals, target.bbox(), window, track, extra, via_ok, budget)
        if end < 0:
            raise RouteError(f"net {net}: no path from {source.owner} to {target.owner} with these rules",
                             enclosed=enclosed)
        path = [end // 9]
        s = end
        while s in came:
            s = came[s]
            path.append(s // 9)
        path.reverse()
        return self._to_copper(path, net)

    def _costs(self, items: list[Copper], net: str, soft: Sequence[Copper]):
        """Per grid node (both layers, flattened): blocked for a track; extra cost (soft copper and
        congestion history, or None); and per (row, column) where a via may stand."""
        track = self._blocked(items, net, self.width / 2).ravel()
        extra = None
        if soft:
            extra = np.where(self._blocked(soft, net, self.width / 2).ravel(), SOFT_COST, 0.0)
        if self.history is not None:
            extra = self.history if extra is None else extra + self.history
        via = self._blocked(items, net, self.via_diameter / 2, via=True)
        # No vias inside any pad (solder would wick into them).
        flat = via.reshape(-1)
        grow = self.via_diameter / 2 + self.clearance
        for it in items:
            if it.kind == "rect":
                padded = Copper.rect(it.a[0] - grow, it.a[1] - grow, it.b[0] + grow, it.b[1] + grow, LAYERS, None)
                for li in range(2):
                    flat[self._inside_ids(padded, li)] = True
        # Drilled holes keep HOLE_TO_HOLE_MM apart, whatever their nets (vias of the same net too).
        for it in items:
            if it.kind == "point" and not it.hole and len(it.layers) == 2:
                keep = Copper.point(it.a[0], it.a[1], self.via_drill / 2 + self.via_drill / 2 + HOLE_TO_HOLE_MM,
                                    LAYERS, None)
                flat[self._inside_ids(keep, 0)] = True
        return track, extra, ~(via[0] | via[1])

    def _window(self, source: Copper, target: Copper, window_mm: float | None) -> tuple[int, int, int, int]:
        """The grid columns and rows (i0, j0, i1, j1) a search may use: the whole grid, or the box round
        both ends grown by ``window_mm``."""
        if window_mm is None:
            return 0, 0, self.nx - 1, self.ny - 1
        sx0, sy0, sx1, sy1 = source.bbox()
        tx0, ty0, tx1, ty1 = target.bbox()
        m = window_mm
        wi0 = max(0, int((min(sx0, tx0) - m - self.bounds[0]) / self.step))
        wi1 = min(self.nx - 1, int((max(sx1, tx1) + m - self.bounds[0]) / self.step) + 1)
        wj0 = max(0, int((min(sy0, ty0) - m - self.bounds[1]) / self.step))
        wj1 = min(self.ny - 1, int((max(sy1, ty1) + m - self.bounds[1]) / self.step) + 1)
        return wi0, wj0, wi1, wj1

    def _search(self, starts: list[int], goals: set[int], target_box, window, track, extra, via_ok,
                budget: int) -> tuple[int, dict[int, int], bool]:
        """Weighted A* over (node, direction) states: (goal state or -1 when none within ``budget``
        expansions, predecessor of each state, whether a failed search never had a state cut off by the window:
        then the whole board's search would make the very same steps, within the same budget, and fail the same
        way)."""
        plane = self.nx * self.ny
        nx = self.nx
        tx0, ty0, tx1, ty1 = target_box
        gx0 = (tx0 - self.bounds[0]) / self.step
        gx1 = (tx1 - self.bounds[0]) / self.step
        gy0 = (ty0 - self.bounds[1]) / self.step
        gy1 = (ty1 - self.bounds[1]) / self.step
        wi0, wj0, wi1, wj1 = window
        # The heuristic's distances to the target box per column and per row (the octile distance of the two).
        hx = [max(gx0 - i, 0.0, i - gx1) for i in range(self.nx)]
        hy = [max(gy0 - j, 0.0, j - gy1) for j in range(self.ny)]
        diag = math.sqrt(2) - 1
        weight = HEURISTIC_WEIGHT
        track = track.tolist()
        extra = extra.tolist() if extra is not None else None
        via_ok = via_ok.ravel().tolist()
        steps = [(k, di, dj, dj * nx + di, math.sqrt(2) if di and dj else 1.0) for k, (di, dj) in enumerate(_DIRS)]
        bend, via_cost, bottom = self.bend_cost, self.via_cost, self.bottom_cost
        heappush, heappop = heapq.heappush, heapq.heappop
        inf = math.inf

        def h(i: int, j: int) -> float:
            dx, dy = hx[i], hy[j]
            return dx + diag * dy if dx >= dy else dy + diag * dx

        # State = node * 9 + direction (8: none yet / just changed layer).
        best: dict[int, float] = {}
        came: dict[int, int] = {}
        heap: list[tuple[float, float, int]] = []
        for n in sorted(starts):
            s = n * 9 + 8
            best[s] = 0.0
            r = n % plane
            heappush(heap, (h(r % nx, r // nx), 0.0, s))
        clipped = False
        while heap and budget:
            budget -= 1
            _f, g, s = heappop(heap)
            if g > best.get(s, inf):
                continue
            n, d = divmod(s, 9)
            if n in goals:
                return s, came, False
            layer, r = divmod(n, plane)
            j, i = divmod(r, nx)
            layer_cost = bottom if layer == 1 else 1.0
            for k, di, dj, dm, length in steps:
                ii, jj = i + di, j + dj
                if not (wi0 <= ii <= wi1 and wj0 <= jj <= wj1):
                    clipped = clipped or (0 <= ii < nx and 0 <= jj < self.ny and not track[n + dm])
                    continue
                m = n + dm
                if track[m]:
                    continue
                cost = length * layer_cost
                if extra is not None:
                    cost += extra[m]
                if d != 8 and d != k:
                    cost += bend
                ng = g + cost
                ns = m * 9 + k
                if ng < best.get(ns, inf):
                    best[ns] = ng
                    came[ns] = s
                    heappush(heap, (ng + weight * h(ii, jj), ng, ns))
            if via_ok[r]:
                m = (1 - layer) * plane + r
                ns = m * 9 + 8
                ng = g + via_cost + (extra[m] if extra is not None else 0.0)
                if not track[m] and ng < best.get(ns, inf):
                    best[ns] = ng
                    came[ns] = s
                    heappush(heap, (ng + weight * h(i, j), ng, ns))
        return -1, came, not clipped

    def _to_copper(self, path: list[int], net: str) -> list[Copper]:
        plane = self.nx * self.ny
        out: list[Copper] = []
        run: list[tuple[int, int]] = []
        layer = path[0] // plane

        def flush() -> None:
            if len(run) < 2:
                return
            # Merge collinear steps into single segments.
            pts = [run[0]]
            for k in range(1, len(run) - 1):
                a, b, c = pts[-1], run[k], run[k + 1]
                if (b[0] - a[0]) * (c[1] - b[1]) != (b[1] - a[1]) * (c[0] - b[0]):
                    pts.append(b)
            pts.append(run[-1])
            for (i0, j0), (i1, j1) in itertools.pairwise(pts):
                (xa, ya), (xb, yb) = self.node_xy(i0, j0), self.node_xy(i1, j1)
                out.append(Copper.seg(xa, ya, xb, yb, self.width, LAYERS[layer], net))

        for n in path:
            nl, r = divmod(n, plane)
            ij = (r % self.nx, r // self.nx)
            if nl != layer:
                flush()
                x, y = self.node_xy(*ij)
                out.append(Copper.point(x, y, self.via_diameter / 2, LAYERS, net, "via"))
                run = []
                layer = nl
            run.append(ij)
        flush()
        return out


def _field(it: Copper, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Distance from grid points to an item's edge (negative inside), vectorised."""
    if it.kind == "rect":
        dx = np.maximum(np.maximum(it.a[0] - X, 0.0), X - it.b[0])
        dy = np.maximum(np.maximum(it.a[1] - Y, 0.0), Y - it.b[1])
        inside = (it.a[0] <= X) & (it.b[0] >= X) & (it.a[1] <= Y) & (it.b[1] >= Y)
        return np.where(inside, -1e-3, np.hypot(dx, dy))
    ax, ay = it.a
    bx, by = it.b
    vx, vy = bx - ax, by - ay
    L2 = vx * vx + vy * vy
    t = np.zeros_like(X, dtype=float) if L2 == 0 else np.clip(((X - ax) * vx + (Y - ay) * vy) / L2, 0.0, 1.0)
    return np.hypot(X - ax - t * vx, Y - ay - t * vy) - it.r
