"""Where each part stands on the breakout board, and the silk label.

The rigid pad (:mod:`magfab.pad`) sits on the top face centred on the chip, so nothing but the chip may
stand on the top side inside the pad's disc: the decoupling capacitors and the pull-ups go on the
bottom, right under the chip and behind the connector; the Qwiic connector sits on the bottom edge,
outside the disc; the two alignment holes match the pad's; two screw holes sit in the far corners.
Everything is in KiCad's frame (:mod:`magfab.board.layout`).
"""

from __future__ import annotations

import math
from dataclasses import replace

from ..design import Design
from ..errors import SpecError
from ..recipes import catalogue
from ..reference_chip import reference_chip
from .footprint import Footprint, chip_footprint, connector_footprint, hole_footprint, qfn_footprint
from .layout import (
    GROUND,
    HOLE_CLEARANCE_MM,
    ORIGIN,
    PAD_KEEPOUT_MARGIN_MM,
    SILK_ADVANCE,
    SILK_MIN_TEXT_MM,
    SILK_STROKE_MM,
    SUPPLY,
    Box,
    Placed,
    SilkText,
    outline_clear,
    overlap,
)
from .plan import BUS_NETS, ORDER_CODE, taxel_bus, two_buses
from .route import distance

__all__ = ["place", "label", "wrap", "pad_hull", "pad_room_mm", "resized", "board_size_mm", "SIZE_STEP_MM",
           "SIZE_REACH_MM"]

#: A board size that magfab searches for (the least that holds the parts) goes up in these steps, mm ...
SIZE_STEP_MM = 0.5
#: ... up to this much beyond where the search starts, mm.
SIZE_REACH_MM = 40.0


def _chip_nets(design: Design, fp: Footprint, straps: tuple[int, int] | None = None, ref: str = "U1",
               bus: int = 0) -> dict[str, str]:
    """Pad number -> net for the MLX90393, from the chip recipe's pin names, the address straps and its I2C bus
    (:data:`~magfab.board.plan.BUS_NETS`)."""
    chip = design.chip
    a1, a0 = straps or design.address_straps
    sda, scl, _ = BUS_NETS[bus]
    by_name = {"VSS": GROUND, "EP": GROUND, "VDD": SUPPLY, "VDDIO": SUPPLY, "CS": SUPPLY, "SCL": scl, "SDA": sda,
               "A1": SUPPLY if a1 else GROUND, "A0": SUPPLY if a0 else GROUND}
    nets = {}
    ep_number = str(max(int(p.number) for p in fp.copper_pads()))
    for p in fp.copper_pads():
        pin = chip.texts["pin_EP" if p.number == ep_number else f"pin_{p.number}"]
        nets[p.number] = by_name.get(pin, f"unconnected-({ref}-{pin}-Pad{p.number})")
    return nets


def _land_gap(part: Placed) -> float:
    """The smallest copper gap between two of a part's pads on different nets (mm)."""
    pads = part.copper()
    gap = min(distance(a, b) for i, a in enumerate(pads) for b in pads[i + 1:] if a.net != b.net)
    return math.floor(gap * 1000 + 1e-6) / 1000


def place(design: Design, hint: bool = True) -> tuple[list[Placed], Box, tuple[float, float, float]]:
    """Every part on the board: (parts with U1 first, board outline, the pad's disc x, y, r), mm.

    Raises :class:`SpecError` when the board cannot hold the pad, the connector or the clearance asked; with ``hint``
    the connector's names the size that would hold it (a search: :mod:`magfab.board.fit` asks only whether it fits)."""
    pcb = design.spec.pcb
    ox, oy = ORIGIN
    hw, hh = pcb.width_mm / 2, pcb.height_mm / 2
    outline = (ox - hw, oy - hh - _reference_room(design), ox + hw, oy + hh)
    _pad_fits(design, hw, hh)
    qfn = qfn_footprint(design.chip, pcb.density, clearance=pcb.clearance_mm)
    placed = _chips(design, qfn) + _reference(design, qfn)
    gap = _land_gap(placed[0])
    if pcb.clearance_mm > gap + 1e-9:
        raise SpecError("pcb.clearance_mm", pcb.clearance_mm,
                        f"must be at most {gap:g} mm: the MLX90393's lands at density {pcb.density.value} are "
                        f"{gap:g} mm apart, so no board could meet a larger clearance")
    chips = len(placed)
    placed += _holes(design, outline)
    connectors = _connectors(design, outline, placed, chips, hint)
    placed += connectors
    placed += _passives(design, qfn, connectors, placed[:chips])
    return placed, outline, (ox, oy, design.pad_radius_mm)


def pad_hull(design: Design) -> tuple[tuple[float, float], ...]:
    """The rigid pad's core in KiCad's frame: the taxels' hull (the pad is it grown by the pad radius); one point,
    the chip's centre, for a single taxel."""
    ox, oy = ORIGIN
    hull = design.array.hull_mm if design.array is not None else ((0.0, 0.0),)
    return tuple((round(ox + x, 6), round(oy - y, 6)) for x, y in hull)


def pad_room_mm(design: Design) -> tuple[float, float]:
    """The least board width and height (mm) that hold the mounting pad and its keep-out margin, centred on the
    board: the single pad's disc, or an array's pad (the taxels' hull grown by the pad radius, ``pad_extent_mm``)."""
    m = PAD_KEEPOUT_MARGIN_MM
    if design.array is None:
        return 2 * (design.pad_radius_mm + m), 2 * (design.pad_radius_mm + m)
    x0, y0, x1, y1 = design.array.pad_extent_mm
    return 2 * (max(-x0, x1) + m), 2 * (max(-y0, y1) + m)


def _pad_fits(design: Design, hw: float, hh: float) -> None:
    """The pad and its margin fit on a board of half width ``hw`` and half height ``hh`` (:func:`pad_room_mm`), or
    one SpecError naming the least side that holds it."""
    if design.array is None:
        what = f"the {2 * design.pad_radius_mm:g} mm mounting pad fits on the board"
    else:
        x0, y0, x1, y1 = design.array.pad_extent_mm
        what = f"the array's {x1 - x0:g} x {y1 - y0:g} mm mounting pad fits on the board, centred on it"
    for key, half, need in zip(("pcb.width_mm", "pcb.height_mm"), (hw, hh), pad_room_mm(design)):
        if half < need / 2:
            raise SpecError(key, 2 * half, f"must be at least {need:g} mm so {what}")


def _chips(design: Design, qfn: Footprint) -> list[Placed]:
    """U1 under the single magnet, or U1..UN under each taxel's (designator: taxel index + 1), each strapped to
    its address."""
    ox, oy = ORIGIN
    if design.array is None:
        return [Placed("U1", ORDER_CODE.format(design.spec.sensor.option_code), qfn, ox, oy,
                       nets=_chip_nets(design, qfn))]
    return [Placed(f"U{t.index + 1}", ORDER_CODE.format(t.option_code), qfn, round(ox + t.x_mm, 6),
                   round(oy - t.y_mm, 6),
                   nets=_chip_nets(design, qfn, t.address_straps, f"U{t.index + 1}", taxel_bus(design, t.index)))
            for t in design.taxels]


#: Above the reference chip's centre, to the board's top edge: its courtyard and the decoupling capacitor on the
#: bottom (3.4 mm), then the silk label's three lines at 1 mm and the fabs' silk margin (5.6 mm), mm.
REFERENCE_TOP_MM = 9.0


def _reference_room(design: Design) -> float:
    """How far the board's top edge moves up (mm) so the reference chip and the label above it fit: 0 without one."""
    ref = reference_chip(design)
    if ref is None:
        return 0.0
    return max(0.0, ref.y_mm + REFERENCE_TOP_MM - design.spec.pcb.height_mm / 2)


def board_size_mm(design: Design) -> tuple[float, float]:
    """The board's width and height, mm: the spec's, taller by what the reference chip needs."""
    pcb = design.spec.pcb
    return pcb.width_mm, round(pcb.height_mm + _reference_room(design), 3)


def _reference(design: Design, qfn: Footprint) -> list[Placed]:
    """The reference chip (:mod:`magfab.reference_chip`) where the magnets leave the field quiet, or nothing."""
    ref = reference_chip(design)
    if ref is None:
        return []
    ox, oy = ORIGIN
    return [Placed(ref.designator, ORDER_CODE.format(ref.option_code), qfn, round(ox + ref.x_mm, 6),
                   round(oy - ref.y_mm, 6), nets=_chip_nets(design, qfn, ref.address_straps, ref.designator))]


def _holes(design: Design, outline: Box) -> list[Placed]:
    """The pad's alignment holes (dowel pins) at the pad's own positions, then the screw holes in the
    corners of the top edge."""
    pcb = design.spec.pcb
    ox, oy = ORIGIN
    out = []
    for k, (x, y, d) in enumerate(design.alignment_holes):
        fp = hole_footprint(d, f"AlignmentHole_{d:g}mm", keepout=HOLE_CLEARANCE_MM)
        out.append(Placed(f"H{k + 1}", f"dowel {d:g} mm", fp, round(ox + x, 6), round(oy - y, 6)))
    if pcb.mounting_hole_diameter_mm > 0:
        head = catalogue("parts")["npth"]["m2_head_diameter_mm"].nominal
        d = pcb.mounting_hole_diameter_mm
        fp = hole_footprint(d, f"MountingHole_{d:g}mm", keepout=max(head / 2 - d / 2, 0.0) + 0.25)
        inset = pcb.mounting_hole_inset_mm
        hw = pcb.width_mm / 2
        for k, sx in enumerate((-1, 1)):
            out.append(Placed(f"H{k + 3}", "M2 screw", fp, round(ox + sx * (hw - inset), 6),
                              round(outline[1] + inset, 6)))
    return out


def _connectors(design: Design, outline: Box, placed: list[Placed], chips: int = 1, hint: bool = True) -> list[Placed]:
    """Each bus's Qwiic connector (J1, and J2 beside it for a second bus) on the bottom edge, mating face flush with
    it, as near the centre line as the pad's keep-out, the holes and the connector before it allow."""
    found = _find_connectors(design, outline, placed, chips)
    if found is not None:
        return found
    pcb = design.spec.pcb
    keep_r = design.pad_radius_mm + PAD_KEEPOUT_MARGIN_MM
    what = "both Qwiic connectors (one a bus)" if two_buses(design) else "the Qwiic connector"
    raise SpecError("pcb.width_mm", pcb.width_mm,
                    f"leaves no room for {what} on the bottom edge outside the mounting pad's "
                    f"{2 * keep_r:g} mm keep-out and clear of the screw holes", _larger_board(design) if hint else "")


def _larger_board(design: Design) -> str:
    """What to change when the connector finds no room: for an array, the least board height (in SIZE_STEP_MM steps,
    at the spec's width) that holds it; for a single taxel, the default pad's sizes."""
    pcb = design.spec.pcb
    if design.array is None:
        return "make the board larger (usually pcb.height_mm: 30 x 28 fits the default pad, 28 x 28 does not)"
    for k in range(1, round(SIZE_REACH_MM / SIZE_STEP_MM) + 1):
        height = pcb.height_mm + SIZE_STEP_MM * k
        trial = resized(design, {"height_mm": height})
        ox, oy = ORIGIN
        outline = (ox - pcb.width_mm / 2, oy - height / 2 - _reference_room(trial), ox + pcb.width_mm / 2,
                   oy + height / 2)
        placed = _chips(trial, qfn_footprint(design.chip, pcb.density, clearance=pcb.clearance_mm))
        if _find_connectors(trial, outline, placed + _holes(trial, outline), len(placed)) is not None:
            return (f"make the board taller: {pcb.width_mm:g} x {height:g} mm (pcb.height_mm = {height:g}) holds this "
                    "array's pad and the connector below it")
    return f"make the board larger: no height up to {SIZE_REACH_MM:g} mm more holds the connector at this width"


def resized(design: Design, sizes: dict[str, float]) -> Design:
    """``design`` on a board of other ``sizes`` (``{"width_mm": ..., "height_mm": ...}``, either or both), mm."""
    return replace(design, spec=design.spec.model_copy(update={"pcb": design.spec.pcb.model_copy(update=sizes)}))


#: Far more than a placed box's rounding (1e-6 mm) and far less than any clearance: the margin of a sure refusal.
_SURE_MM = 1e-4


def _find_connectors(design: Design, outline: Box, placed: list[Placed], chips: int) -> list[Placed] | None:
    """Every bus's connector where it fits, each placed after the ones before it (:func:`_connectors`), or None."""
    found: list[Placed] = []
    for bus in range(2 if two_buses(design) else 1):
        connector = _find_connector(design, outline, placed + found, chips, bus)
        if connector is None:
            return None
        found.append(connector)
    return found


def _find_connector(design: Design, outline: Box, placed: list[Placed], chips: int, bus: int = 0) -> Placed | None:
    """Bus ``bus``'s connector where it fits (see :func:`_connectors`), or None."""
    pcb = design.spec.pcb
    ox, oy = ORIGIN
    hw, hh = pcb.width_mm / 2, pcb.height_mm / 2
    keep_r = design.pad_radius_mm + PAD_KEEPOUT_MARGIN_MM
    jst = connector_footprint(catalogue("parts")["jst-sh-4"])
    reach = max(jst.body[3], max(p.y + p.h / 2 for p in jst.pads) + pcb.edge_clearance_mm)
    jy = round(oy + hh - reach, 6)
    e = pcb.edge_clearance_mm
    hull = pad_hull(design)
    holes = [h.box(h.footprint.courtyard) for h in placed[chips:]]
    # The courtyard at the middle, moved along for each place and shrunk by far more than the rounding of a placed
    # box: a place whose moved courtyard the pad's keep-out refuses is refused as placed, without placing it (most
    # places are; placing them was 4 % of a design's time in the search).
    x0, y0, x1, y1 = Placed("J1", "", jst, ox, jy).box(jst.courtyard)
    for k in range(int(hw / 0.25) * 2 + 1):
        dx = (k + 1) // 2 * 0.25 * (1 if k % 2 else -1)
        inner = (x0 + dx + _SURE_MM, y0 + _SURE_MM, x1 + dx - _SURE_MM, y1 - _SURE_MM)
        if not outline_clear(inner, hull, keep_r - _SURE_MM):
            continue
        sda, scl, ref = BUS_NETS[bus]
        cand = Placed(ref, "Qwiic JST-SH 4", jst, round(ox + dx, 6), jy,
                      nets={"1": GROUND, "2": SUPPLY, "3": sda, "4": scl, "MP": GROUND})
        cy = cand.box(jst.courtyard)
        body = cand.box(jst.body)
        if body[0] < outline[0] or body[2] > outline[2]:
            continue
        if not outline_clear(cy, hull, keep_r):  # first: it refuses most places, and costs less than the copper
            continue
        if any(c.bbox()[0] < outline[0] + e or c.bbox()[2] > outline[2] - e for c in cand.copper()):
            continue
        if any(overlap(cy, h) for h in holes):
            continue
        return cand
    return None


def _passives(design: Design, qfn: Footprint, connectors: list[Placed], chips: list[Placed]) -> list[Placed]:
    """Decoupling right under each chip (bottom side): C1 by VDD (top row), C2 by VDDIO (bottom row), and so on
    for the next chip; each bus's I2C pull-ups, if asked for, behind its connector (R1, R2 behind J1; R3, R4 behind
    J2)."""
    pcb = design.spec.pcb
    parts = catalogue("parts")
    cap = chip_footprint(parts["chip-0603"], pcb.density, prefix="C")
    off = round(qfn.body[3] + cap.courtyard[3] + 0.1, 2)
    # On the bottom side KiCad mirrors a footprint top to bottom, so the angles below put each
    # reference text on the side away from its neighbour.
    out = []
    for k, u in enumerate(chips):
        out += [Placed(f"C{2 * k + 1}", "100nF", cap, u.x, round(u.y - off, 6), 180.0, True,
                       {"1": SUPPLY, "2": GROUND}),
                Placed(f"C{2 * k + 2}", "100nF", cap, u.x, round(u.y + off, 6), 0.0, True, {"1": SUPPLY, "2": GROUND})]
    if pcb.pullups:
        res = chip_footprint(parts["chip-0603"], pcb.density, prefix="R")
        ohm = parts["jst-sh-4"]["pullup_ohm"].nominal
        value = f"{ohm / 1000:g}k"
        for bus, j in enumerate(connectors):
            sda, scl, _ = BUS_NETS[bus]
            ry = round(j.y + j.footprint.courtyard[1] - res.courtyard[3] - 0.4, 2)
            out.append(Placed(f"R{2 * bus + 1}", value, res, j.x, ry, 0.0, True, {"1": SUPPLY, "2": sda}))
            # the second above the first, far enough that its silk reference clears the first's pads.
            pitch = (res.courtyard[3] - res.courtyard[1]) + 1.3
            out.append(Placed(f"R{2 * bus + 2}", value, res, j.x, round(ry - pitch, 2), 180.0, True,
                              {"1": SUPPLY, "2": scl}))
    return out


# ---------------------------------------------------------------------------------------------------
# The silk label


def wrap(name: str, chars: int) -> list[str]:
    """The name on as few lines as fit ``chars`` glyphs, broken after '.', '_' or '-' where possible."""
    lines: list[str] = []
    rest = name
    while len(rest) > chars:
        cut = max((i + 1 for i, ch in enumerate(rest[:chars]) if ch in "._-" and i + 1 >= chars // 2), default=chars)
        lines.append(rest[:cut])
        rest = rest[cut:]
    return [*lines, rest]


def label(design: Design, outline: Box, parts: list[Placed],
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
    if design.array is not None:
        t = design.taxels
        arr = design.spec.array
        assert arr is not None  # an array layout is derived from the spec's array only
        shape = f"{arr.rows}x{arr.cols}" if arr.positions_mm is None else f"{len(t)}-taxel"
        address = f"{shape} array: MLX90393 0x{t[0].i2c_address:02X}-0x{t[-1].i2c_address:02X}"
    ref = reference_chip(design)
    if ref is not None:  # the address that is not a taxel's, said to be the reference's
        address = address.replace(" I2C", "") + f", ref 0x{ref.i2c_address:02X}"
    name = design.spec.name
    pad_top = min(y for _, y in pad_hull(design)) - circle[2]
    room = pad_top - (y0 + edge + 0.5)  # fabs clip silk within ~0.5 mm of the edge

    def height(n: int, size: float) -> float:
        return (n - 1) * 1.6 * size + 2 * (0.7 * size + SILK_STROKE_MM / 2)

    for size in (1.0, 0.9, 0.8):
        chars = int(width / (SILK_ADVANCE * size))
        lines = wrap(name, chars)
        if len(lines) <= 2 and len(address) <= chars and height(len(lines) + 1, size) <= room:
            break
    else:
        lines = lines[:2]
        lines[-1] = lines[-1][: max(chars - 2, 1)] + ".." if len(wrap(name, chars)) > 2 else lines[-1]
    top = y0 + edge + 0.5 + 0.7 * size + SILK_STROKE_MM / 2
    return tuple(SilkText(t, round((x0 + x1) / 2, 6), round(top + k * 1.6 * size, 6), size)
                 for k, t in enumerate([*lines, address]))


def taxel_marks(design: Design, board) -> tuple[SilkText, ...]:
    """Beside each chip, on the top silk (under the pad once it is glued, there to solder and check by): its taxel,
    address and order-code suffix, "T0 0x0C -011" (or without the suffix where only that fits). Each goes to the
    first side of its chip (right, left, above, below; each side nearest first) where it clears every top pad, via,
    courtyard, other mark and the edge (tracks lie under the solder mask); a chip with no such side goes without
    (the address table on the drawing layer and the checklist carry the plan)."""
    x0, y0, x1, y1 = board.outline
    e = design.spec.pcb.edge_clearance_mm
    # silk may cross tracks (under the solder mask), not pads or vias (bare copper)
    top = [c.bbox() for p in board.parts for c in p.copper() if "F.Cu" in c.layers]
    top += [c.bbox() for c in board.tracks if c.kind == "point"]
    yards = [p.box(p.footprint.courtyard) for p in board.parts if not p.bottom and not _is_chip_ref(p.ref)]
    marks: list[SilkText] = []
    for t, u in zip(design.taxels, (p for p in board.parts if _is_chip_ref(p.ref))):
        short = f"T{t.index} 0x{t.i2c_address:02X}"
        for text in (f"{short} -{t.option_code}", short):
            mark = _mark_beside(u, text, marks, top + yards, (x0 + e, y0 + e, x1 - e, y1 - e))
            if mark is not None:
                marks.append(mark)
                break
    return tuple(marks)


def _mark_beside(u: Placed, text: str, marks: list[SilkText], keep: list[Box], inside: Box) -> SilkText | None:
    """The first place beside chip ``u`` (right, left, above, below; each side nearest first) where ``text`` clears
    the boxes ``keep`` by 0.2 mm and the other marks, within ``inside``; None when there is none."""
    cy = u.box(u.footprint.courtyard)
    half_w = SILK_ADVANCE * SILK_MIN_TEXT_MM * len(text) / 2 + 0.3
    sides = [((cy[2] + half_w + d, u.y), (cy[0] - half_w - d, u.y), (u.x, cy[1] - 0.9 - d), (u.x, cy[3] + 0.9 + d))
             for d in (0.0, 0.8, 1.6)]
    for x, y in (p for three in zip(*sides) for p in three):
        mark = SilkText(text, round(x, 6), round(y, 6), SILK_MIN_TEXT_MM)
        box = mark.box()
        grown = (box[0] - 0.2, box[1] - 0.2, box[2] + 0.2, box[3] + 0.2)
        if box[0] < inside[0] or box[1] < inside[1] or box[2] > inside[2] or box[3] > inside[3]:
            continue
        if any(overlap(grown, c) for c in keep) or any(overlap(box, m.box()) for m in marks):
            continue
        return mark
    return None


def _is_chip_ref(ref: str) -> bool:
    return ref.startswith("U")
