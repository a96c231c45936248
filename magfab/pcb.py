"""The breakout board as a whole: the MLX90393 on a routed two-layer board, as KiCad 6 files.

:func:`board` places, wires and routes everything; :func:`findings` measures the result (clearances,
pad overlaps, outline, courtyards, the pad's keep-out, connectivity); :func:`files` renders the
footprint library, the board, its project file (design rules) and a library table.

Built from :mod:`magfab.board`: ``layout`` (the values: Placed, Board, the frame), ``placement`` (where
each part stands, the silk label), ``fit`` (the board before routing, :func:`placed`, and its size, held to it before
any work), ``connect`` (escape stubs, spanning trees, rip-up and re-route over the grid router in ``route``),
``rules`` (the checks) and ``kicad_files`` (the text).
"""

from __future__ import annotations

from dataclasses import replace

from .board.connect import NETS_ROUTED, ROUTE_GRID_MM, route_all
from .board.fit import placed
from .board.kicad_files import LIBRARY, files
from .board.layout import HOLE_CLEARANCE_MM, ORIGIN, SILK_MIN_TEXT_MM, Board, Placed, SilkText
from .board.placement import taxel_marks
from .board.plan import address_plan
from .board.route import Router
from .board.rules import distance_margin, findings
from .design import Design

__all__ = ["Board", "Placed", "SilkText", "board", "placed", "findings", "files", "distance_margin", "address_plan",
           "ORIGIN", "LIBRARY", "SILK_MIN_TEXT_MM"]


def board(design: Design) -> Board:
    """Place, wire and route the breakout board for a design (KiCad frame, mm).

    Connections are routed fine-pitch signals first; see :func:`magfab.board.connect.route_all` for the
    rip-up rounds. Raises :class:`magfab.errors.SpecError` when the board cannot hold its parts; what
    cannot be routed is reported by :func:`findings`, not raised."""
    pcb = design.spec.pcb
    board = placed(design)
    router = Router(board.outline, ROUTE_GRID_MM, pcb.track_width_mm, pcb.via_diameter_mm, pcb.via_drill_mm,
                    pcb.clearance_mm, HOLE_CLEARANCE_MM, pcb.edge_clearance_mm)
    tracks, unrouted = route_all(router, list(board.parts), NETS_ROUTED)
    board = replace(board, tracks=tuple(tracks), unrouted=tuple(unrouted))
    if design.array is None:
        return board
    return replace(board, marks=taxel_marks(design, board))
