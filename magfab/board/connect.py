"""Wiring the placed board: the chip's escape stubs, a spanning tree per net, and the grid router run
connection by connection with targeted rip-up and re-route (:func:`route_all`).

All in KiCad's frame, mm (:mod:`magfab.board.layout`); the router itself is :mod:`magfab.board.route`.
"""

from __future__ import annotations

import math

from .layout import GROUND, Placed
from .route import HOLE_TO_HOLE_MM, LAYERS, Copper, Point, RouteError, Router, distance, is_via, touching, via_clearance

__all__ = ["NETS_ROUTED", "ROUTE_GRID_MM", "RIP_UP_LIMIT", "FANOUT_MM", "route_all"]

# routing order: the fine-pitch signals first (the second bus's only on a board that has one: plan.BUS_NETS)
NETS_ROUTED = ("SCL", "SDA", "SCL_B", "SDA_B", "+3V3", "GND")
ROUTE_GRID_MM = 0.125  # divides the 0.5 mm pitch and the 0.25 mm pad offsets of the QFN
RIP_UP_LIMIT = 8  # times one connection may be ripped up to make way for another
FANOUT_MM = 0.5  # straight escape beyond a QFN land's outer end, so no route can box a pin in


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


def _stub_ends(u1: Placed, c: Copper, epc: Copper, h: float) -> tuple[Point, Point, Point]:
    """For a land ``c`` of the chip: (outer end of its escape stub, start of a stub on the land, inner end
    of a diagonal stub onto the exposed pad ``epc``), (x, y) mm each, for a stub of half-width ``h``."""
    cx, cy = (c.a[0] + c.b[0]) / 2, (c.a[1] + c.b[1]) / 2
    if (c.b[0] - c.a[0]) > (c.b[1] - c.a[1]):
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
    return outer, start, inner


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
    for number, c in sorted(pads.items(), key=lambda kv: int(kv[0])):
        if number == ep or c.net not in NETS_ROUTED:
            continue
        horizontal = (c.b[0] - c.a[0]) > (c.b[1] - c.a[1])
        # Necked down to the land's width: a wider track would break the rule between neighbours.
        w = min(width, c.b[1] - c.a[1] if horizontal else c.b[0] - c.a[0])
        h = w / 2
        outer, start, inner = _stub_ends(u1, c, epc, h)
        fan_out = c.net != GROUND or number == _vss(u1)
        if c.net == GROUND:
            stub = Copper.seg(*start, *inner, w, "F.Cu", c.net, f"{u1.ref}.{number} stub")
            if all(distance(stub, o) >= clearance for o in others):
                stubs.append(stub)
                # Only the fanned-out VSS pin gives the pad's group a way out; a strap pin tied to the
                # pad alone would leave pad and strap as an island.
                ep_tied = ep_tied or number == _vss(u1)
            else:
                fan_out = True
        if fan_out:
            cx, cy = (c.a[0] + c.b[0]) / 2, (c.a[1] + c.b[1]) / 2
            stubs.append(Copper.seg(cx, cy, *outer, w, "F.Cu", c.net, f"{u1.ref}.{number} stub"))
            terminals.append(Copper.rect(outer[0] - h, outer[1] - h, outer[0] + h, outer[1] + h, ["F.Cu"], c.net,
                                         f"{u1.ref}.{number}"))
    if not ep_tied:
        h = width / 2
        ex, ey = (epc.a[0] + epc.b[0]) / 2, (epc.a[1] + epc.b[1]) / 2
        stubs.append(Copper.point(ex, ey, via_diameter / 2, LAYERS, GROUND, f"{u1.ref}.EP via"))
        # Escape on the bottom towards -x, between the decoupling capacitors above and below the chip.
        tx = round(ex - (u1.footprint.courtyard[2] - u1.footprint.courtyard[0]) / 2 - FANOUT_MM, 6)
        stubs.append(Copper.seg(ex, ey, tx, ey, width, "B.Cu", GROUND, f"{u1.ref}.EP stub"))
        terminals.append(Copper.rect(tx - h, ey - h, tx + h, ey + h, ["B.Cu"], GROUND, f"{u1.ref}.EP"))
    return stubs, terminals


def _vss(u1: Placed) -> str:
    """The chip's first ground pin: the one that fans out for the exposed pad's group."""
    return next(n for n, net in sorted(u1.nets.items(), key=lambda kv: int(kv[0])) if net == GROUND)


def _is_chip(p: Placed) -> bool:
    return p.ref.startswith("U")


def _chip_order(owner: str) -> tuple:
    """Sort key: a chip's terminals by chip number (U2 before U10), then the owner's name."""
    ref = owner.split(".")[0]
    return (int(ref[1:]) if ref[:1] == "U" and ref[1:].isdigit() else 0, owner)


def _clash(a: Copper, b: Copper, router: Router) -> bool:
    """Would two pieces of routed copper of different nets break a rule (clearance, hole spacing)? A via is held to
    the clearance its drill needs (:func:`via_clearance`), as the board's check holds it."""
    if (a.kind == "point" and b.kind == "point" and len(a.layers) == 2 == len(b.layers)
            and math.dist(a.a, b.a) - router.via_drill < HOLE_TO_HOLE_MM - 1e-6):
        return True
    need = router.clearance
    for v in (a, b):
        if is_via(v):
            need = max(need, via_clearance(router.clearance, router.hole_clearance, v.r, router.via_drill))
    return bool(a.layers & b.layers) and distance(a, b) < need - 1e-6


def _connections(parts: list[Placed], terminals: list[Copper], order: tuple[str, ...]):
    """(net, new end, end already connected) per connection still to route: each net's pads and the
    chip's stub terminals joined by a spanning tree, nets in ``order``."""
    items = [c for p in parts for c in p.copper()]
    chips = {p.ref for p in parts if _is_chip(p)}
    connections = []
    for net in order:
        ends = [c for c in items if c.net == net and c.kind == "rect" and c.owner.split(".")[0] not in chips]
        ends += [t for t in terminals if t.net == net]
        ends.sort(key=lambda c: (c.owner.split(".")[0] not in chips, _chip_order(c.owner)))
        if ends:  # a net the board does not have (a second bus) has no connection
            connections += [(net, new, old) for new, old in _mst(ends) if not touching(new, old)]
    return connections


def route_all(router: Router, parts: list[Placed], order: tuple[str, ...] = NETS_ROUTED):
    """Route every connection, with targeted rip-up and re-route.

    Connections go in order (fine-pitch signals first). When one finds no path, it is routed again
    with the other nets' tracks ignored (pads, holes and stubs still count); the connections whose
    tracks that path would clash with are ripped up and queued again. Each connection may be ripped
    up at most ``RIP_UP_LIMIT`` times, so the loop ends; the order of events depends only on the board,
    so the result is deterministic. Returns (tracks, messages for connections left unrouted)."""
    stubs, terminals = [], []
    for chip in (p for p in parts if _is_chip(p)):
        s, t = _fanout(chip, router.width, router.clearance, router.via_diameter)
        stubs += s
        terminals += t
    connections = _connections(parts, terminals, order)
    routes: dict[int, list[Copper]] = {}
    ripped = [0] * len(connections)
    queue = list(range(len(connections)))
    failed: dict[int, str] = {}
    fixed = [c for p in parts for c in p.copper()] + stubs
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
                         and any(_clash(a, b, router) for a in path for b in other))
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
