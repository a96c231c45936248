"""The MLX90393 footprint and the breakout board, as KiCad 6 files.

The board is laid out in KiCad's frame (mm, y down) with the chip's centre at :data:`ORIGIN`; the
design frame (y up, chip centre at 0) maps to it by ``X = ORIGIN_x + x``, ``Y = ORIGIN_y - y``. The
rigid pad (:mod:`magfab.pad`) sits on the top face centred on the chip, so nothing but the chip may
stand on the top side inside the pad's disc: the decoupling capacitors and the pull-ups go on the
bottom, right under the chip and behind the connector; the Qwiic connector sits on the bottom edge,
outside the disc; the two alignment holes match the pad's; two screw holes sit in the far corners.

:func:`board` places, wires and routes everything; :func:`findings` measures the result (clearances,
pad overlaps, outline, courtyards, the pad's keep-out, connectivity); :func:`files` renders the
footprint library, the board, its project file (design rules) and a library table.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Mapping

from . import __version__
from .design import Design
from .errors import Finding, Severity, SpecError
from .board.footprint import Footprint, Pad, chip_footprint, connector_footprint, hole_footprint, qfn_footprint
from .recipes import catalogue
from .board.route import (HOLE_TO_HOLE_MM, LAYERS, Copper, Router, RouteError, clearance_violations, connected, distance,
                    is_via, via_clearance)
from .formats.sexpr import Sym, at, render, xy

__all__ = ["Board", "Placed", "board", "findings", "files", "ORIGIN", "LIBRARY"]

ORIGIN = (100.0, 100.0)  # chip centre on the KiCad sheet, mm
LIBRARY = "magfab"
ROUTE_GRID_MM = 0.125  # divides the 0.5 mm pitch and the 0.25 mm pad offsets of the QFN
PAD_KEEPOUT_MARGIN_MM = 0.25  # beyond the pad's radius, no top-side part may stand
SILK_STROKE_MM = 0.15  # the usual fab minimum silk line width
SILK_MIN_TEXT_MM = 0.8  # smallest silk text we write (with a 0.15 mm stroke it stays legible)
SILK_ADVANCE = 0.9  # assumed glyph advance per mm of text size; KiCad's stroke font measures ~0.77
HOLE_CLEARANCE_MM = 0.25  # copper to a drilled hole (KiCad 6 default min_hole_clearance)
BOARD_VERSION = 20211014
NETS_ROUTED = ("SCL", "SDA", "+3V3", "GND")  # routing order: the fine-pitch signals first
SUPPLY, GROUND = "+3V3", "GND"


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

    def box(self, box: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        (ax, ay), (bx, by) = self.to_board(box[0], box[1]), self.to_board(box[2], box[3])
        return (min(ax, bx), min(ay, by), max(ax, bx), max(ay, by))

    @property
    def side(self) -> str:
        return "B" if self.bottom else "F"

    def copper(self) -> list[Copper]:
        out = []
        for p in self.footprint.pads:
            layers = [_side_layer(layer, self.bottom) for layer in p.layers]
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


def _side_layer(layer: str, bottom: bool) -> str:
    if bottom and layer.startswith("F."):
        return "B." + layer[2:]
    return layer


@dataclass(frozen=True)
class Board:
    """A placed, wired and routed board, ready to render and check."""

    name: str
    outline: tuple[float, float, float, float]  # x0, y0, x1, y1 in the KiCad frame
    parts: tuple[Placed, ...]
    tracks: tuple[Copper, ...]
    pad_circle: tuple[float, float, float]  # the rigid pad's disc: x, y, r
    label: tuple[SilkText, ...]
    rules: Mapping[str, float]
    thickness_mm: float
    address: int
    unrouted: tuple[str, ...] = ()

    def nets(self) -> list[str]:
        names = {n for p in self.parts for n in p.nets.values()}
        return sorted(names, key=lambda n: (n.startswith("unconnected"), n))

    def copper(self) -> list[Copper]:
        items = [c for p in self.parts for c in p.copper()]
        return items + list(self.tracks)

    def footprints(self) -> dict[str, Footprint]:
        return {p.footprint.name: p.footprint for p in self.parts}


# ---------------------------------------------------------------------------------------------------
# Placement and netlist


def _chip_nets(design: Design, fp: Footprint) -> dict[str, str]:
    chip = design.chip
    a1, a0 = design.address_straps
    by_name = {"VSS": GROUND, "EP": GROUND, "VDD": SUPPLY, "VDDIO": SUPPLY, "CS": SUPPLY, "SCL": "SCL", "SDA": "SDA",
               "A1": SUPPLY if a1 else GROUND, "A0": SUPPLY if a0 else GROUND}
    nets = {}
    ep_number = str(max(int(p.number) for p in fp.copper_pads()))
    for p in fp.copper_pads():
        pin = chip.texts["pin_EP" if p.number == ep_number else f"pin_{p.number}"]
        nets[p.number] = by_name.get(pin, f"unconnected-(U1-{pin}-Pad{p.number})")
    return nets


def _land_gap(part: "Placed") -> float:
    """The smallest copper gap between two of a part's pads on different nets (mm)."""
    pads = part.copper()
    gap = min(distance(a, b) for i, a in enumerate(pads) for b in pads[i + 1:] if a.net != b.net)
    return math.floor(gap * 1000 + 1e-6) / 1000


def _disc_clear(box, cx: float, cy: float, r: float) -> bool:
    """Whether an axis-aligned box lies wholly outside the disc."""
    dx = max(box[0] - cx, 0.0, cx - box[2])
    dy = max(box[1] - cy, 0.0, cy - box[3])
    return math.hypot(dx, dy) >= r


def _overlap(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _place(design: Design) -> tuple[list[Placed], tuple[float, float, float, float], tuple[float, float, float]]:
    spec = design.spec
    pcb = spec.pcb
    ox, oy = ORIGIN
    hw, hh = pcb.width_mm / 2, pcb.height_mm / 2
    outline = (ox - hw, oy - hh, ox + hw, oy + hh)
    for key, half in (("pcb.width_mm", hw), ("pcb.height_mm", hh)):
        if half < design.pad_radius_mm + PAD_KEEPOUT_MARGIN_MM:
            raise SpecError(key, 2 * half, f"must be at least {2 * (design.pad_radius_mm + PAD_KEEPOUT_MARGIN_MM):g} mm "
                            f"so the {2 * design.pad_radius_mm:g} mm mounting pad fits on the board")
    keep_r = design.pad_radius_mm + PAD_KEEPOUT_MARGIN_MM
    parts = catalogue("parts")
    qfn = qfn_footprint(design.chip, pcb.density, clearance=pcb.clearance_mm)
    cap = chip_footprint(parts["chip-0603"], pcb.density, prefix="C")
    res = chip_footprint(parts["chip-0603"], pcb.density, prefix="R")
    jst = connector_footprint(parts["jst-sh-4"])
    placed = [Placed("U1", f"MLX90393SLW-ABA-{spec.sensor.option_code}", qfn, ox, oy, nets=_chip_nets(design, qfn))]
    gap = _land_gap(placed[0])
    if pcb.clearance_mm > gap + 1e-9:
        raise SpecError("pcb.clearance_mm", pcb.clearance_mm,
                        f"must be at most {gap:g} mm: the MLX90393's lands at density {pcb.density.value} are "
                        f"{gap:g} mm apart, so no board could meet a larger clearance")

    # The pad's alignment holes (dowel pins), at the pad's own positions.
    for k, (x, y, d) in enumerate(design.alignment_holes):
        fp = hole_footprint(d, f"AlignmentHole_{d:g}mm", keepout=HOLE_CLEARANCE_MM)
        placed.append(Placed(f"H{k + 1}", f"dowel {d:g} mm", fp, round(ox + x, 6), round(oy - y, 6)))
    holes: list[Placed] = []
    if pcb.mounting_hole_diameter_mm > 0:
        head = parts["npth"]["m2_head_diameter_mm"].nominal
        d = pcb.mounting_hole_diameter_mm
        fp = hole_footprint(d, f"MountingHole_{d:g}mm", keepout=max(head / 2 - d / 2, 0.0) + 0.25)
        inset = pcb.mounting_hole_inset_mm
        for k, sx in enumerate((-1, 1)):
            holes.append(Placed(f"H{k + 3}", f"M2 screw", fp, round(ox + sx * (hw - inset), 6), round(oy - hh + inset, 6)))
    placed.extend(holes)

    # Qwiic connector on the bottom edge, mating face flush with it, as near the centre line as the
    # pad's keep-out and the holes allow.
    reach = max(jst.body[3], max(p.y + p.h / 2 for p in jst.pads) + pcb.edge_clearance_mm)
    jy = round(oy + hh - reach, 6)
    j1 = None
    for k in range(int(hw / 0.25) * 2 + 1):
        dx = (k + 1) // 2 * 0.25 * (1 if k % 2 else -1)
        cand = Placed("J1", "Qwiic JST-SH 4", jst, round(ox + dx, 6), jy,
                      nets={"1": GROUND, "2": SUPPLY, "3": "SDA", "4": "SCL", "MP": GROUND})
        cy = cand.box(jst.courtyard)
        body = cand.box(jst.body)
        if body[0] < outline[0] or body[2] > outline[2]:
            continue
        e = pcb.edge_clearance_mm
        if any(c.bbox()[0] < outline[0] + e or c.bbox()[2] > outline[2] - e for c in cand.copper()):
            continue
        if not _disc_clear(cy, ox, oy, keep_r):
            continue
        if any(_overlap(cy, h.box(h.footprint.courtyard)) for h in placed[1:]):
            continue
        j1 = cand
        break
    if j1 is None:
        raise SpecError("pcb.width_mm", pcb.width_mm,
                        f"leaves no room for the Qwiic connector on the bottom edge outside the mounting pad's "
                        f"{2 * keep_r:g} mm keep-out and clear of the screw holes",
                        "make the board larger (usually pcb.height_mm: 30 x 28 fits the default pad, 28 x 28 does not)")
    placed.append(j1)

    # Decoupling right under the chip (bottom side): C1 by VDD (top row), C2 by VDDIO (bottom row).
    off = round(qfn.body[3] + cap.courtyard[3] + 0.1, 2)
    # On the bottom side KiCad mirrors a footprint top to bottom, so the angles below put each
    # reference text on the side away from its neighbour.
    placed.append(Placed("C1", "100nF", cap, ox, round(oy - off, 6), 180.0, True, {"1": SUPPLY, "2": GROUND}))
    placed.append(Placed("C2", "100nF", cap, ox, round(oy + off, 6), 0.0, True, {"1": SUPPLY, "2": GROUND}))
    if pcb.pullups:
        ohm = parts["jst-sh-4"]["pullup_ohm"].nominal
        value = f"{ohm / 1000:g}k"
        ry = round(jy + jst.courtyard[1] - res.courtyard[3] - 0.4, 2)
        placed.append(Placed("R1", value, res, j1.x, ry, 0.0, True, {"1": SUPPLY, "2": "SDA"}))
        # R2 above R1, far enough that R2's silk reference clears R1's pads.
        pitch = (res.courtyard[3] - res.courtyard[1]) + 1.3
        placed.append(Placed("R2", value, res, j1.x, round(ry - pitch, 2), 180.0,
                             True, {"1": SUPPLY, "2": "SCL"}))
    return placed, outline, (ox, oy, design.pad_radius_mm)


@dataclass(frozen=True)
class SilkText:
    """A line of board silk: centred at (x, y), ``size`` the glyph height (mm)."""

    text: str
    x: float
    y: float
    size: float
    thickness: float = SILK_STROKE_MM

    def box(self) -> tuple[float, float, float, float]:
        """Conservative extent: KiCad's stroke font advances about 0.77 x size per glyph (measured on
        the plotted F.SilkS of the default board); we allow SILK_ADVANCE."""
        hw = SILK_ADVANCE * self.size * len(self.text) / 2 + self.thickness / 2
        hh = 0.7 * self.size + self.thickness / 2  # KiCad's box also holds the descenders
        return (self.x - hw, self.y - hh, self.x + hw, self.y + hh)


def _wrap(name: str, chars: int) -> list[str]:
    """The name on as few lines as fit ``chars`` glyphs, broken after '.', '_' or '-' where possible."""
    lines: list[str] = []
    rest = name
    while len(rest) > chars:
        cut = max((i + 1 for i, ch in enumerate(rest[:chars]) if ch in "._-" and i + 1 >= chars // 2), default=chars)
        lines.append(rest[:cut])
        rest = rest[cut:]
    return lines + [rest]


def _label(design: Design, outline: tuple[float, float, float, float], parts: list[Placed],
           circle: tuple[float, float, float]) -> tuple[SilkText, ...]:
    """The design name and I2C address in silk along the top edge, between the screw holes and above
    the pad's disc: the largest text from 1.0 down to SILK_MIN_TEXT_MM mm that fits, the name wrapped
    onto at most two lines (cut short with '..' only if even that does not fit)."""
    x0, y0, x1, _ = outline
    edge = design.spec.pcb.edge_clearance_mm
    left, right = x0 + edge, x1 - edge
    for p in parts:
        if p.ref in ("H3", "H4"):
            cy = p.box(p.footprint.courtyard)
            if cy[2] < (x0 + x1) / 2:
                left = max(left, cy[2])
            else:
                right = min(right, cy[0])
    width = right - left - 0.2
    address = f"MLX90393 I2C 0x{design.i2c_address:02X}"
    name = design.spec.name
    room = circle[1] - circle[2] - (y0 + edge + 0.5)  # fabs clip silk within ~0.5 mm of the edge

    def height(n: int, size: float) -> float:
        return (n - 1) * 1.6 * size + 2 * (0.7 * size + SILK_STROKE_MM / 2)

    for size in (1.0, 0.9, 0.8):
        chars = int(width / (SILK_ADVANCE * size))
        lines = _wrap(name, chars)
        if len(lines) <= 2 and len(address) <= chars and height(len(lines) + 1, size) <= room:
            break
    else:
        lines = lines[:2]
        lines[-1] = lines[-1][: max(chars - 2, 1)] + ".." if len(_wrap(name, chars)) > 2 else lines[-1]
    top = y0 + edge + 0.5 + 0.7 * size + SILK_STROKE_MM / 2
    return tuple(SilkText(t, round((x0 + x1) / 2, 6), round(top + k * 1.6 * size, 6), size)
                 for k, t in enumerate([*lines, address]))


# ---------------------------------------------------------------------------------------------------
# Routing


def _mst(pads: list[Copper]) -> list[tuple[Copper, Copper]]:
    """Prim's tree over pad centres: (new pad, pad already in the tree), deterministic."""
    def centre(c: Copper) -> tuple[float, float]:
        return ((c.a[0] + c.b[0]) / 2, (c.a[1] + c.b[1]) / 2)

    tree = [pads[0]]
    rest = pads[1:]
    edges = []
    while rest:
        best = min(((math.dist(centre(p), centre(t)), i, j) for i, p in enumerate(rest) for j, t in enumerate(tree)))
        _, i, j = best
        edges.append((rest[i], tree[j]))
        tree.append(rest.pop(i))
    return edges


RIP_UP_LIMIT = 8  # times one connection may be ripped up to make way for another
FANOUT_MM = 0.5  # straight escape beyond a QFN land's outer end, so no route can box a pin in


def _fanout(u1: Placed, width: float, clearance: float, via_diameter: float) -> tuple[list[Copper], list[Copper]]:
    """Escape stubs for the chip, so no route can box a pin in: every routed pin gets a straight stub
    outwards; ground pins also run from their inner end diagonally onto the exposed pad. Where such an
    inner stub would come too close to a neighbouring pin of another net (a corner pin next to a
    supply-strapped address pin, or a wide clearance rule), the pin fans out like the others and the
    exposed pad is tied to ground by a via at its centre instead. Returns (stubs and vias, terminals)."""
    pads = {c.owner.split(".")[1]: c for c in u1.copper()}
    ep = max(pads, key=lambda n: int(n))
    epc = pads[ep]
    others = [c for c in pads.values() if c.net != GROUND]
    stubs, terminals = [], []
    ep_tied = False
    h = width / 2
    for number, c in sorted(pads.items(), key=lambda kv: int(kv[0])):
        if number == ep or c.net not in NETS_ROUTED:
            continue
        cx, cy = (c.a[0] + c.b[0]) / 2, (c.a[1] + c.b[1]) / 2
        horizontal = (c.b[0] - c.a[0]) > (c.b[1] - c.a[1])
        # Necked down to the land's width: a wider track would break the rule between neighbours.
        w = min(width, c.b[1] - c.a[1] if horizontal else c.b[0] - c.a[0])
        h = w / 2
        if horizontal:
            sgn = 1 if cx > u1.x else -1
            outer = (round((c.b[0] if sgn > 0 else c.a[0]) + sgn * FANOUT_MM, 6), cy)
            start = (round(c.a[0] + h if sgn > 0 else c.b[0] - h, 6), cy)
            inner = (round(start[0] - sgn * (start[0] - (epc.b[0] if sgn > 0 else epc.a[0]) + 0.3), 6),
                     round(u1.y + (cy - u1.y) * 0.6, 6))
        else:
            sgn = 1 if cy > u1.y else -1
            outer = (cx, round((c.b[1] if sgn > 0 else c.a[1]) + sgn * FANOUT_MM, 6))
            start = (cx, round(c.a[1] + h if sgn > 0 else c.b[1] - h, 6))
            inner = (round(u1.x + (cx - u1.x) * 0.6, 6),
                     round(start[1] - sgn * (start[1] - (epc.b[1] if sgn > 0 else epc.a[1]) + 0.3), 6))
        fan_out = c.net != GROUND or number == _vss(u1)
        if c.net == GROUND:
            stub = Copper.seg(*start, *inner, w, "F.Cu", c.net, f"U1.{number} stub")
            if all(distance(stub, o) >= clearance for o in others):
                stubs.append(stub)
                # Only the fanned-out VSS pin gives the pad's group a way out; a strap pin tied to the
                # pad alone would leave pad and strap as an island.
                ep_tied = ep_tied or number == _vss(u1)
            else:
                fan_out = True
        if fan_out:
            stubs.append(Copper.seg(cx, cy, *outer, w, "F.Cu", c.net, f"U1.{number} stub"))
            terminals.append(Copper.rect(outer[0] - h, outer[1] - h, outer[0] + h, outer[1] + h, ["F.Cu"], c.net,
                                         f"U1.{number}"))
    if not ep_tied:
        h = width / 2
        ex, ey = (epc.a[0] + epc.b[0]) / 2, (epc.a[1] + epc.b[1]) / 2
        stubs.append(Copper.point(ex, ey, via_diameter / 2, LAYERS, GROUND, "U1.EP via"))
        # Escape on the bottom towards -x, between the decoupling capacitors above and below the chip.
        tx = round(ex - (u1.footprint.courtyard[2] - u1.footprint.courtyard[0]) / 2 - FANOUT_MM, 6)
        stubs.append(Copper.seg(ex, ey, tx, ey, width, "B.Cu", GROUND, "U1.EP stub"))
        terminals.append(Copper.rect(tx - h, ey - h, tx + h, ey + h, ["B.Cu"], GROUND, "U1.EP"))
    return stubs, terminals


def _vss(u1: Placed) -> str:
    return next(n for n, net in sorted(u1.nets.items(), key=lambda kv: int(kv[0])) if net == GROUND)


def _clash(a: Copper, b: Copper, clearance: float, via_drill: float) -> bool:
    """Would two pieces of routed copper of different nets break a rule (clearance, hole spacing)?"""
    if a.kind == "point" and b.kind == "point" and len(a.layers) == 2 == len(b.layers):
        if math.dist(a.a, b.a) - via_drill < HOLE_TO_HOLE_MM - 1e-6:
            return True
    return bool(a.layers & b.layers) and distance(a, b) < clearance - 1e-6


def _route_all(router: Router, parts: list[Placed], order: tuple[str, ...]):
    """Route every connection, with targeted rip-up and re-route.

    Connections go in order (fine-pitch signals first). When one finds no path, it is routed again
    with the other nets' tracks ignored (pads, holes and stubs still count); the connections whose
    tracks that path would clash with are ripped up and queued again. Each connection may be ripped
    up at most ``RIP_UP_LIMIT`` times, so the loop ends; the order of events depends only on the board,
    so the result is deterministic. Returns (tracks, messages for connections left unrouted)."""
    items = [c for p in parts for c in p.copper()]
    stubs, terminals = _fanout(parts[0], router.width, router.clearance, router.via_diameter)
    connections = []
    for net in order:
        ends = [c for c in items if c.net == net and c.kind == "rect" and not c.owner.startswith("U1.")]
        ends += [t for t in terminals if t.net == net]
        ends.sort(key=lambda c: (not c.owner.startswith("U1"), c.owner))
        connections += [(net, new, old) for new, old in _mst(ends) if not _touching(new, old)]
    routes: dict[int, list[Copper]] = {}
    ripped = [0] * len(connections)
    queue = list(range(len(connections)))
    failed: dict[int, str] = {}
    fixed = items + stubs
    while queue:
        k = queue.pop(0)
        net, new, old = connections[k]
        placed = [c for path in routes.values() for c in path]
        try:
            routes[k] = router.route(fixed + placed, net, new, old)
            continue
        except RouteError as exc:
            reason = str(exc)
        own = [c for j, path in routes.items() if connections[j][0] == net for c in path]
        others = [c for j, path in routes.items() if connections[j][0] != net for c in path]
        try:
            path = router.route(fixed + own, net, new, old, soft=others)
        except RouteError:
            failed[k] = reason  # blocked by pads, holes or the edge: no rip-up can help
            continue
        victims = sorted(j for j, other in routes.items() if connections[j][0] != net
                         and any(_clash(a, b, router.clearance, router.via_drill) for a in path for b in other))
        if any(ripped[j] >= RIP_UP_LIMIT for j in victims):
            failed[k] = reason
            continue
        router.congest(path)
        for j in victims:
            ripped[j] += 1
            del routes[j]
            queue.append(j)
        routes[k] = path
    tracks = list(stubs) + [c for k in sorted(routes) for c in routes[k]]
    return tracks, [failed[k] for k in sorted(failed)]


def board(design: Design) -> Board:
    """Place, wire and route the breakout board for a design.

    Connections are routed fine-pitch signals first; see :func:`_route_all` for the rip-up rounds.
    """
    pcb = design.spec.pcb
    parts, outline, circle = _place(design)
    router = Router(outline, ROUTE_GRID_MM, pcb.track_width_mm, pcb.via_diameter_mm, pcb.via_drill_mm,
                    pcb.clearance_mm, HOLE_CLEARANCE_MM, pcb.edge_clearance_mm)
    tracks, unrouted = _route_all(router, parts, NETS_ROUTED)
    rules = {"clearance": pcb.clearance_mm, "track_width": pcb.track_width_mm, "via_diameter": pcb.via_diameter_mm,
             "via_drill": pcb.via_drill_mm, "edge_clearance": pcb.edge_clearance_mm, "hole_clearance": HOLE_CLEARANCE_MM}
    return Board(design.spec.name, outline, tuple(parts), tuple(tracks), circle, _label(design, outline, parts, circle), rules,
                 pcb.thickness_mm, design.i2c_address, tuple(unrouted))


def _touching(a: Copper, b: Copper) -> bool:
    return bool(a.layers & b.layers) and distance(a, b) <= 0.0


# ---------------------------------------------------------------------------------------------------
# Checks


def findings(b: Board) -> list[Finding]:
    """Measure the board: every rule the build promises, as findings (errors stop the build)."""
    out: list[Finding] = []
    err = lambda code, msg: out.append(Finding(Severity.ERROR, code, msg, "pcb"))  # noqa: E731
    for msg in b.unrouted:
        err("pcb-unrouted", msg)
    items = b.copper()
    bad = clearance_violations(items, b.rules["clearance"], b.rules["hole_clearance"], b.rules["via_drill"])
    for p, q, d, need in bad[:5]:
        err("pcb-clearance", f"{p.owner} ({p.net}) and {q.owner} ({q.net}) are {d:.3f} mm apart; need {need:g} mm")
    if len(bad) > 5:
        err("pcb-clearance", f"... and {len(bad) - 5} more clearance violations")
    drills = [(c.a, c.r if c.hole else b.rules["via_drill"] / 2, c.owner) for c in items
              if c.kind == "point" and (c.hole or len(c.layers) == 2)]
    for i, (pa, ra, oa) in enumerate(drills):
        for pb, rb, ob in drills[i + 1:]:
            gap = math.dist(pa, pb) - ra - rb
            if gap < HOLE_TO_HOLE_MM - 1e-6:
                err("pcb-hole-spacing", f"drilled holes of {oa} at {pa} and {ob} at {pb} are {gap:.3f} mm apart; "
                                        f"need {HOLE_TO_HOLE_MM:g} mm")
    pads = [c for c in items if c.kind == "rect"]
    for i, p in enumerate(pads):
        for q in pads[i + 1:]:
            if p.owner.split(".")[0] != q.owner.split(".")[0] and p.layers & q.layers and _touching(p, q):
                err("pcb-pad-overlap", f"pads {p.owner} and {q.owner} overlap")
    x0, y0, x1, y1 = b.outline
    e = b.rules["edge_clearance"]
    for c in items:
        if c.hole:
            continue
        bx = c.bbox()
        if bx[0] < x0 + e - 1e-6 or bx[1] < y0 + e - 1e-6 or bx[2] > x1 - e + 1e-6 or bx[3] > y1 - e + 1e-6:
            err("pcb-edge", f"copper of {c.owner} ({c.net}) is closer than {e:g} mm to the board edge")
    for p in b.parts:
        body = p.box(p.footprint.body)
        if body[0] < x0 - 1e-6 or body[1] < y0 - 1e-6 or body[2] > x1 + 1e-6 or body[3] > y1 + 1e-6:
            err("pcb-outline", f"{p.ref} ({p.footprint.name}) sticks out of the board outline")
    for i, p in enumerate(b.parts):
        for q in b.parts[i + 1:]:
            holes = p.ref.startswith("H") or q.ref.startswith("H")
            if (p.bottom == q.bottom or holes) and _overlap(p.box(p.footprint.courtyard), q.box(q.footprint.courtyard)):
                err("pcb-courtyard", f"courtyards of {p.ref} and {q.ref} overlap")
    cx, cy, r = b.pad_circle
    for p in b.parts:
        if p.bottom or p.ref == "U1" or p.ref in {"H1", "H2"}:
            continue
        if not _disc_clear(p.box(p.footprint.courtyard), cx, cy, r + PAD_KEEPOUT_MARGIN_MM):
            err("pcb-pad-keepout", f"{p.ref} stands inside the mounting pad's disc (radius {r:g} mm): the pad would "
                                   "not sit flat")
    for t in b.label:
        box = t.box()
        inside = box[0] >= x0 + e and box[1] >= y0 + e and box[2] <= x1 - e and box[3] <= y1 - e
        clear = _disc_clear(box, cx, cy, r) and not any(
            _overlap(box, p.box(p.footprint.courtyard)) for p in b.parts if p.ref.startswith("H"))
        clear = clear and not any(_overlap(box, o.box()) for o in b.label if o is not t)
        if not inside or not clear:
            err("pcb-silk", f"the silk label {t.text!r} ({box[2] - box[0]:.1f} mm wide) does not fit between the "
                            "screw holes, inside the edge, clear of the pad's disc and the other lines: make pcb.width_mm larger or "
                            "the name shorter")
    islands = connected(items)
    for net, n in islands.items():
        if n > 1 and not net.startswith("unconnected"):
            err("pcb-unconnected", f"net {net} is in {n} separate pieces")
    if not out:
        n_tracks = sum(1 for c in b.tracks if c.kind == "seg")
        n_vias = sum(1 for c in b.tracks if c.kind == "point")
        margin = max(min(distance_margin(items, b.rules), default=0.0), 0.0)  # no "-0.000"
        out.append(Finding(Severity.INFO, "pcb-ok",
                           f"board routed: {n_tracks} track segments, {n_vias} vias, every net connected, "
                           f"smallest clearance margin {margin:.3f} mm above the rules ({b.rules['clearance']:g} mm "
                           f"between copper, {b.rules['hole_clearance']:g} mm from a drill)", "pcb"))
    return out


def distance_margin(items: list[Copper], rules: Mapping[str, float]) -> list[float]:
    """Smallest clearance margin (distance - rule) per copper pair that is within 1 mm, for the report."""
    from .board.route import _near

    out = []
    for i, p in enumerate(items):
        for q in items[i + 1:]:
            if p.hole or q.hole or p.net == q.net or not (p.layers & q.layers) or not _near(p, q, 1.0):
                continue
            need = rules["clearance"]
            for v in (p, q):
                if is_via(v):
                    need = max(need, via_clearance(rules["clearance"], rules["hole_clearance"], v.r, rules["via_drill"]))
            out.append(distance(p, q) - need)
    return out


# ---------------------------------------------------------------------------------------------------
# Rendering


_LAYER_TABLE = (
    (0, "F.Cu", "signal"), (31, "B.Cu", "signal"), (32, "B.Adhes", "user", "B.Adhesive"),
    (33, "F.Adhes", "user", "F.Adhesive"), (34, "B.Paste", "user"), (35, "F.Paste", "user"),
    (36, "B.SilkS", "user", "B.Silkscreen"), (37, "F.SilkS", "user", "F.Silkscreen"), (38, "B.Mask", "user"),
    (39, "F.Mask", "user"), (40, "Dwgs.User", "user", "User.Drawings"), (41, "Cmts.User", "user", "User.Comments"),
    (44, "Edge.Cuts", "user"), (45, "Margin", "user"), (46, "B.CrtYd", "user", "B.Courtyard"),
    (47, "F.CrtYd", "user", "F.Courtyard"), (48, "B.Fab", "user"), (49, "F.Fab", "user"),
)


def _board_text(b: Board) -> str:
    nets = b.nets()
    code = {n: i + 1 for i, n in enumerate(nets)}
    layers = tuple((row[0], row[1], Sym(row[2]), *row[3:]) for row in _LAYER_TABLE)
    x0, y0, x1, y1 = b.outline
    cx, cy, r = b.pad_circle
    node: list = [
        "kicad_pcb", ("version", BOARD_VERSION), ("generator", Sym("magfab")),
        ("general", ("thickness", b.thickness_mm)), ("paper", "A4"),
        ("title_block", ("title", f"{b.name}: MLX90393 breakout"), ("rev", __version__),
         ("comment", 1, f"I2C address 0x{b.address:02X}; generated by magfab {__version__}")),
        ("layers", *layers),
        ("setup", ("pad_to_mask_clearance", 0)),
        ("net", 0, ""), *(("net", code[n], n) for n in nets),
    ]
    for p in b.parts:
        fp = p.footprint
        pad_nets = {num: (code[n], n) for num, n in p.nets.items()}
        node.append(("footprint", f"{LIBRARY}:{fp.name}", ("layer", "B.Cu" if p.bottom else "F.Cu"),
                     at(p.x, p.y, p.angle), ("descr", fp.descr), ("tags", fp.tags), ("attr", Sym(fp.attr)),
                     *_with_value(fp.nodes(reference=p.ref, angle=p.angle, nets=pad_nets, bottom=p.bottom), p.value)))
    node.append(("gr_rect", ("start", x0, y0), ("end", x1, y1), ("layer", "Edge.Cuts"), ("width", 0.1), ("fill", Sym("none"))))
    node.append(("gr_circle", ("center", cx, cy), ("end", cx + r, cy), ("layer", "Dwgs.User"), ("width", 0.1),
                 ("fill", Sym("none"))))
    node.append(("gr_text", "rigid pad outline", at(cx, cy - r - 0.8), ("layer", "Dwgs.User"),
                 ("effects", ("font", ("size", 0.8, 0.8), ("thickness", 0.12)))))
    node.extend(_label_nodes(b))
    for t in b.tracks:
        net = (("net", code[t.net]),) if t.net else ()
        if t.kind == "seg":
            node.append(("segment", ("start", *t.a), ("end", *t.b), ("width", 2 * t.r), ("layer", next(iter(t.layers))), *net))
        else:
            node.append(("via", at(*t.a), ("size", 2 * t.r), ("drill", b.rules["via_drill"]), ("layers", "F.Cu", "B.Cu"), *net))
    pts = ("pts", xy(x0, y0), xy(x1, y0), xy(x1, y1), xy(x0, y1))
    for layer in LAYERS:
        node.append(("zone", ("net", code[GROUND]), ("net_name", GROUND), ("layer", layer), ("hatch", Sym("edge"), 0.508),
                     ("connect_pads", ("clearance", b.rules["clearance"])), ("min_thickness", 0.2),
                     ("filled_areas_thickness", Sym("no")),
                     ("fill", ("thermal_gap", 0.3), ("thermal_bridge_width", 0.3)), ("polygon", pts)))
    return render(tuple(node), wrap=("kicad_pcb", "footprint", "layers")) + "\n"


def _with_value(nodes: list[tuple], value: str) -> list[tuple]:
    out = []
    for n in nodes:
        if n[0] == "fp_text" and n[1] == "value":
            n = (n[0], n[1], value, *n[3:])
        out.append(n)
    return out


def _label_nodes(b: Board) -> list[tuple]:
    """The label lines (see :func:`_label`) as board silk."""
    return [("gr_text", t.text, at(t.x, t.y), ("layer", "F.SilkS"),
             ("effects", ("font", ("size", t.size, t.size), ("thickness", t.thickness)))) for t in b.label]


def _narrowest(b: Board) -> float:
    """The narrowest track on the board (QFN stubs neck down to the land width)."""
    return round(min([b.rules["track_width"]] + [2 * c.r for c in b.tracks if c.kind == "seg"]), 6)


def _project_text(b: Board) -> str:
    """The .kicad_pro: KiCad 6 keeps the design rules here, so DRC checks the rules we routed to."""
    r = b.rules
    project = {
        "board": {"design_settings": {
            "defaults": {"board_outline_line_width": 0.1, "copper_line_width": 0.2},
            "rules": {"min_clearance": r["clearance"], "min_track_width": _narrowest(b),
                      "min_via_diameter": r["via_diameter"], "min_through_hole_diameter": r["via_drill"],
                      "min_hole_clearance": r["hole_clearance"], "min_copper_edge_clearance": r["edge_clearance"],
                      "min_hole_to_hole": HOLE_TO_HOLE_MM, "min_via_annular_width": 0.1, "solder_mask_clearance": 0.0,
                      "min_silk_clearance": 0.0},
            "track_widths": [], "via_dimensions": []}},
        "meta": {"filename": f"{b.name}.kicad_pro", "version": 1},
        "net_settings": {"classes": [{
            "name": "Default", "clearance": r["clearance"], "track_width": r["track_width"],
            "via_diameter": r["via_diameter"], "via_drill": r["via_drill"], "microvia_diameter": 0.3,
            "microvia_drill": 0.1, "diff_pair_gap": 0.25, "diff_pair_via_gap": 0.25, "diff_pair_width": 0.2,
            "line_style": 0, "wire_width": 6, "bus_width": 12}], "meta": {"version": 2}},
    }
    return json.dumps(project, indent=2, sort_keys=True) + "\n"


def files(b: Board) -> dict[str, bytes]:
    """Relative path -> bytes: the footprint library, the board, its project file and a library table."""
    out = {f"{LIBRARY}.pretty/{name}.kicad_mod": fp.library_text().encode()
           for name, fp in sorted(b.footprints().items())}
    out[f"{b.name}.kicad_pcb"] = _board_text(b).encode()
    out[f"{b.name}.kicad_pro"] = _project_text(b).encode()
    out["fp-lib-table"] = (f'(fp_lib_table\n  (lib (name "{LIBRARY}")(type "KiCad")(uri "${{KIPRJMOD}}/{LIBRARY}.pretty")'
                           f'(options "")(descr "footprints generated by magfab"))\n)\n').encode()
    return out
