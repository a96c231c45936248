"""The breakout board as values: a footprint standing on the board (:class:`Placed`), a line of silk
(:class:`SilkText`) and the placed, routed whole (:class:`Board`), with the frame and house margins
that placement, routing, the checks and the KiCad writer share.

KiCad's frame: millimetres, y down, the chip's centre at :data:`ORIGIN`. The design frame (y up, chip
centre at 0) maps to it by ``X = ORIGIN_x + x``, ``Y = ORIGIN_y - y``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from .. import outline
from .footprint import Footprint, flip_layer
from .route import LAYERS, Copper

__all__ = ["ORIGIN", "SUPPLY", "GROUND", "PAD_KEEPOUT_MARGIN_MM", "HOLE_CLEARANCE_MM", "SILK_STROKE_MM",
           "SILK_MIN_TEXT_MM", "SILK_ADVANCE", "Placed", "SilkText", "Board", "disc_clear", "outline_clear", "overlap"]

ORIGIN = (100.0, 100.0)  # chip centre on the KiCad sheet, mm
SUPPLY, GROUND = "+3V3", "GND"
PAD_KEEPOUT_MARGIN_MM = 0.25  # beyond the pad's radius, no top-side part may stand
HOLE_CLEARANCE_MM = 0.25  # copper to a drilled hole (KiCad 6 default min_hole_clearance)
SILK_STROKE_MM = 0.15  # the usual fab minimum silk line width
SILK_MIN_TEXT_MM = 0.8  # smallest silk text we write (with a 0.15 mm stroke it stays legible)
SILK_ADVANCE = 0.9  # assumed glyph advance per mm of text size; KiCad's stroke font measures ~0.77

Box = tuple[float, float, float, float]  # x0, y0, x1, y1 in mm


@dataclass(frozen=True)
class Placed:
    """A footprint on the board: absolute position (KiCad frame), angle (0 or 180), side, pad nets."""

    ref: str
    value: str
    footprint: Footprint
    x: float
    y: float
    angle: float = 0.0
    bottom: bool = False
    nets: Mapping[str, str] = field(default_factory=dict)

    def to_board(self, px: float, py: float) -> tuple[float, float]:
        """A footprint-local point in the board frame (flip for the bottom side, then rotate)."""
        if self.bottom:
            py = -py
        c, s = round(math.cos(math.radians(self.angle)), 12), round(math.sin(math.radians(self.angle)), 12)
        return (round(self.x + px * c + py * s, 6), round(self.y - px * s + py * c, 6))

    def box(self, box: Box) -> Box:
        """A footprint-local box (e.g. the courtyard) as an axis-aligned box in the board frame."""
        (ax, ay), (bx, by) = self.to_board(box[0], box[1]), self.to_board(box[2], box[3])
        return (min(ax, bx), min(ay, by), max(ax, bx), max(ay, by))

    @property
    def side(self) -> str:
        return "B" if self.bottom else "F"

    def copper(self) -> list[Copper]:
        """The part's pads as copper in the board frame; non-plated holes as holes on both layers."""
        out = []
        for p in self.footprint.pads:
            layers = [flip_layer(layer) if self.bottom else layer for layer in p.layers]
            if p.kind == "np_thru_hole":
                x, y = self.to_board(p.x, p.y)
                out.append(Copper.point(x, y, p.drill / 2, LAYERS, None, self.ref, hole=True))
                continue
            cu = [layer for layer in layers if layer in LAYERS]
            if not cu:
                continue
            x0, y0, x1, y1 = self.box(p.box())
            out.append(Copper.rect(x0, y0, x1, y1, cu, self.nets.get(p.number), f"{self.ref}.{p.number}"))
        return out


@dataclass(frozen=True)
class SilkText:
    """A line of board silk: centred at (x, y), ``size`` the glyph height (mm)."""

    text: str
    x: float
    y: float
    size: float
    thickness: float = SILK_STROKE_MM

    def box(self) -> Box:
        """Conservative extent: KiCad's stroke font advances about 0.77 x size per glyph (measured on
        the plotted F.SilkS of the default board); we allow SILK_ADVANCE."""
        hw = SILK_ADVANCE * self.size * len(self.text) / 2 + self.thickness / 2
        hh = 0.7 * self.size + self.thickness / 2  # KiCad's box also holds the descenders
        return (self.x - hw, self.y - hh, self.x + hw, self.y + hh)


@dataclass(frozen=True)
class Board:
    """A placed, wired and routed board, ready to render and check."""

    name: str
    outline: Box  # in the KiCad frame
    parts: tuple[Placed, ...]
    tracks: tuple[Copper, ...]
    pad_circle: tuple[float, float, float]  # the rigid pad's disc: x, y, r (mm)
    label: tuple[SilkText, ...]
    rules: Mapping[str, float]  # clearance, track_width, via_diameter, via_drill, edge_clearance, hole_clearance (mm)
    thickness_mm: float
    address: int
    unrouted: tuple[str, ...] = ()
    pad_hull: tuple[tuple[float, float], ...] = ()  # an array's pad: the taxels' hull (KiCad frame), grown by r
    marks: tuple[SilkText, ...] = ()  # an array's taxel marks ("T0 0x0C") beside each chip, top silk
    address_table: tuple[str, ...] = ()  # an array's address plan, one line per chip, drawn beside the board

    def pad_clear(self, box: Box, margin: float = 0.0) -> bool:
        """Whether an axis-aligned box lies wholly outside the rigid pad (grown by ``margin``)."""
        cx, cy, r = self.pad_circle
        return outline_clear(box, self.pad_hull or ((cx, cy),), r + margin)

    def nets(self) -> list[str]:
        """Every net name, the unconnected pins' nets last."""
        names = {n for p in self.parts for n in p.nets.values()}
        return sorted(names, key=lambda n: (n.startswith("unconnected"), n))

    def copper(self) -> list[Copper]:
        """The pads (and holes) of every part, then the tracks and vias."""
        items = [c for p in self.parts for c in p.copper()]
        return items + list(self.tracks)

    def footprints(self) -> dict[str, Footprint]:
        return {p.footprint.name: p.footprint for p in self.parts}


def outline_clear(box: Box, hull, r: float) -> bool:
    """Whether an axis-aligned box lies wholly outside a convex hull (KiCad frame) grown by ``r``: the box's
    distance from the hull (zero where they meet) is at least r."""
    if len(hull) == 1:
        return disc_clear(box, hull[0][0], hull[0][1], r)
    corners = [(box[0], box[1]), (box[2], box[1]), (box[2], box[3]), (box[0], box[3])]
    if any(box[0] <= x <= box[2] and box[1] <= y <= box[3] for x, y in hull):
        return False
    if any(outline.distance(c, list(hull)) == 0.0 for c in corners):
        return False
    edges = list(zip(corners, corners[1:] + corners[:1]))
    return all(_segments_apart(a, b, p, q, r) for a, b in edges for p, q in zip(hull, hull[1:] + hull[:1]))


def _segments_apart(a, b, p, q, r: float) -> bool:
    """Whether two segments are at least r apart (zero if they cross; else the least end-to-segment distance)."""
    def side(o, u, v) -> float:
        return (u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0])

    if side(a, b, p) * side(a, b, q) < 0 and side(p, q, a) * side(p, q, b) < 0:
        return False
    return min(outline.distance(a, [p, q]), outline.distance(b, [p, q]), outline.distance(p, [a, b]),
               outline.distance(q, [a, b])) >= r


def disc_clear(box: Box, cx: float, cy: float, r: float) -> bool:
    """Whether an axis-aligned box lies wholly outside the disc."""
    dx = max(box[0] - cx, 0.0, cx - box[2])
    dy = max(box[1] - cy, 0.0, cy - box[3])
    return math.hypot(dx, dy) >= r


def overlap(a: Box, b: Box) -> bool:
    """Whether two axis-aligned boxes overlap (touching edges do not)."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]
