"""The rule checks behind :func:`magfab.pcb.findings`: every rule the build promises of the routed board
(clearances, hole spacing, pad overlaps, edge and outline, courtyards, the pad's keep-out, the silk
label, connectivity), measured on the board itself, each broken rule an error-level finding."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from ..errors import Finding, Severity
from .layout import PAD_KEEPOUT_MARGIN_MM, Board, overlap
from .route import (
    HOLE_TO_HOLE_MM,
    Copper,
    clearance_violations,
    connected,
    distance,
    is_via,
    near,
    touching,
    via_clearance,
)

__all__ = ["findings", "placement_findings", "distance_margin"]

Report = Callable[[str, str], None]  # (code, message) -> records an error-level finding


def findings(b: Board) -> list[Finding]:
    """Measure the board: every rule the build promises, as findings (errors stop the build); a clean
    board gets one ``pcb-ok`` note with its track count and smallest clearance margin."""
    out: list[Finding] = []
    err = _reporter(out)
    for msg in b.unrouted:
        err("pcb-unrouted", msg)
    items = b.copper()
    _copper_rules(b, items, err)
    _edge_rules(b, items, err)
    _part_rules(b, err)
    _silk_rules(b, err)
    for net, n in connected(items).items():
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


def placement_findings(b: Board) -> list[Finding]:
    """The rules placement alone decides, on a board before routing (no tracks): the parts' copper and bodies
    against the edge and the outline, courtyards and the pad's keep-out, the silk label. The routed board has the same
    parts and label, so :func:`findings` reports each of these errors there too."""
    out: list[Finding] = []
    err = _reporter(out)
    _edge_rules(b, [c for p in b.parts for c in p.copper()], err)
    _part_rules(b, err)
    _silk_rules(b, err)
    return out


def _reporter(out: list[Finding]) -> Report:
    """A Report that records each broken rule in ``out`` as an error-level finding on the board."""
    return lambda code, msg: out.append(Finding(Severity.ERROR, code, msg, "pcb"))


def _copper_rules(b: Board, items: list[Copper], err: Report) -> None:
    """Clearance between nets (the first five, then a count), drill-to-drill spacing, pads of two parts
    overlapping."""
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
            if p.owner.split(".")[0] != q.owner.split(".")[0] and p.layers & q.layers and touching(p, q):
                err("pcb-pad-overlap", f"pads {p.owner} and {q.owner} overlap")


def _edge_rules(b: Board, items: list[Copper], err: Report) -> None:
    """Copper keeps the edge clearance; every part's body stays inside the outline."""
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


def _part_rules(b: Board, err: Report) -> None:
    """Courtyards on one side (holes go through both) do not overlap; nothing but the chip and the
    alignment holes stands on top inside the mounting pad's disc."""
    for i, p in enumerate(b.parts):
        for q in b.parts[i + 1:]:
            holes = p.ref.startswith("H") or q.ref.startswith("H")
            if (p.bottom == q.bottom or holes) and overlap(p.box(p.footprint.courtyard), q.box(q.footprint.courtyard)):
                err("pcb-courtyard", f"courtyards of {p.ref} and {q.ref} overlap")
    r = b.pad_circle[2]
    for p in b.parts:
        if p.bottom or p.ref.startswith("U") or p.ref in {"H1", "H2"}:
            continue
        if not b.pad_clear(p.box(p.footprint.courtyard), PAD_KEEPOUT_MARGIN_MM):
            err("pcb-pad-keepout", f"{p.ref} stands inside the mounting pad's disc (radius {r:g} mm): the pad would "
                                   "not sit flat")


def _silk_rules(b: Board, err: Report) -> None:
    """Each label line lies inside the edge clearance, off the pad's disc, the holes and the other lines."""
    x0, y0, x1, y1 = b.outline
    e = b.rules["edge_clearance"]
    for t in b.label:
        box = t.box()
        inside = box[0] >= x0 + e and box[1] >= y0 + e and box[2] <= x1 - e and box[3] <= y1 - e
        clear = b.pad_clear(box) and not any(
            overlap(box, p.box(p.footprint.courtyard)) for p in b.parts if p.ref.startswith("H"))
        clear = clear and not any(overlap(box, o.box()) for o in b.label if o is not t)
        if not inside or not clear:
            err("pcb-silk", f"the silk label {t.text!r} ({box[2] - box[0]:.1f} mm wide) does not fit between the "
                            "screw holes, inside the edge, clear of the pad's disc and the other lines: make "
                            "pcb.width_mm larger or the name shorter")


def distance_margin(items: list[Copper], rules: Mapping[str, float]) -> list[float]:
    """Clearance margin (distance - rule, mm) per pair of copper of different nets on a shared layer
    within 1 mm of each other, for the ``pcb-ok`` note."""
    out = []
    for i, p in enumerate(items):
        for q in items[i + 1:]:
            if p.hole or q.hole or p.net == q.net or not (p.layers & q.layers) or not near(p, q, 1.0):
                continue
            need = rules["clearance"]
            for v in (p, q):
                if is_via(v):
                    need = max(need,
                               via_clearance(rules["clearance"], rules["hole_clearance"], v.r, rules["via_drill"]))
            out.append(distance(p, q) - need)
    return out
