"""The board before routing, and its size.

:func:`placed` is the board as placement leaves it: every part, the silk label and the pad's outline, no tracks yet.
The routed board (:func:`magfab.pcb.board`) is this board with its tracks, so what the board's size decides is decided
here: whether the pad and its keep-out, the connector and the screw holes fit (placement's refusals), and the rules of
the routed board's check that placement alone decides (:func:`magfab.board.rules.placement_findings`).

:func:`fit` holds a design's board to them before any work; ``magfab check``, the build's plan and the design search
call it through :func:`magfab.check.preflight`. A board size the spec states must hold the parts, or the spec is
refused with placement's one line (which names the least size where placement knows it) or the rule the placed board
breaks. A side the spec leaves unstated (``pcb.width_mm``, ``pcb.height_mm``) is the default 30 mm where that holds
the parts; where it does not, the board is sized to fit. Each unstated side starts from the larger of the default and
the pad's side with its keep-out (:func:`magfab.board.placement.pad_room_mm`), rounded up to SIZE_STEP_MM, and may
grow SIZE_REACH_MM beyond that (not past the spec's bound, 200 mm); the width is the least in SIZE_STEP_MM steps that
holds the parts at the largest height, then the height the least that holds them at that width. Each least is found by
bisection: a board larger by a step keeps every part where it was relative to the pad or moves it away from it.
"""

from __future__ import annotations

import math
from dataclasses import replace

from ..design import Design
from ..errors import BuildError, InputError, SpecError
from ..spec import Pcb
from .layout import HOLE_CLEARANCE_MM, Board
from .placement import SIZE_REACH_MM, SIZE_STEP_MM, label, pad_hull, pad_room_mm, place, resized
from .plan import table_lines
from .rules import placement_findings

__all__ = ["placed", "refusal", "fit", "SIDES"]

#: The board's sides, as the keys of ``[pcb]``.
SIDES = ("width_mm", "height_mm")


def placed(design: Design, hint: bool = True) -> Board:
    """The board before routing: placement's parts and outline, the silk label, the design rules the routing keeps
    and, for an array, the pad's hull and the address table. Raises :class:`SpecError` as :func:`place` does."""
    pcb = design.spec.pcb
    parts, outline, circle = place(design, hint)
    rules = {"clearance": pcb.clearance_mm, "track_width": pcb.track_width_mm, "via_diameter": pcb.via_diameter_mm,
             "via_drill": pcb.via_drill_mm, "edge_clearance": pcb.edge_clearance_mm,
             "hole_clearance": HOLE_CLEARANCE_MM}
    board = Board(design.spec.name, outline, tuple(parts), (), circle, label(design, outline, parts, circle), rules,
                  pcb.thickness_mm, design.i2c_address)
    if design.array is None:
        return board
    return replace(board, pad_hull=pad_hull(design), address_table=table_lines(design))


def refusal(design: Design, hint: bool = True) -> InputError | None:
    """Why the design's board cannot be made at its size, or None: placement's :class:`SpecError` (``hint``: as
    :func:`place` takes it), else a :class:`BuildError` with the error findings of the rules placement alone decides,
    as the routed board's check would report them."""
    try:
        board = placed(design, hint)
    except SpecError as exc:
        return exc
    broken = placement_findings(board)
    return BuildError(broken) if broken else None


def fit(design: Design) -> Design:
    """``design`` with a board that holds its parts (module doc): itself where the stated or default size does, else
    with its unstated sides sized to fit (named in ``pcb_sized``, their values in ``spec.pcb``). Raises the
    :func:`refusal` of a stated size, or, with a side unstated, of the largest board the search may try (a refusal no
    size mends, such as ``pcb.clearance_mm``'s, is raised there)."""
    if refusal(design, hint=False) is None:
        return design
    pcb = design.spec.pcb
    unstated = tuple(k for k in SIDES if k not in pcb.model_fields_set)
    broken = refusal(design) if not unstated else None
    if broken is not None:
        raise broken
    need = dict(zip(SIDES, pad_room_mm(design)))
    start = {k: max(_default(k), _rounded_up(need[k])) if k in unstated else getattr(pcb, k) for k in SIDES}
    far = {k: min(start[k] + SIZE_REACH_MM, _largest(k)) if k in unstated else start[k] for k in SIDES}
    broken = refusal(resized(design, far))
    if broken is not None:
        raise _beyond_reach(broken, unstated, far)
    sizes = dict(far)
    for side in (k for k in SIDES if k in unstated):
        sizes[side] = _least(design, side, start[side], sizes)
    return replace(resized(design, sizes), pcb_sized=unstated)


def _least(design: Design, side: str, start: float, sizes: dict[str, float]) -> float:
    """The least ``side`` from ``start`` up in SIZE_STEP_MM steps whose board (its other side as ``sizes`` gives it)
    holds the parts, by bisection: ``sizes[side]`` holds them."""
    lo, hi = 0, round((sizes[side] - start) / SIZE_STEP_MM)  # steps: lo may not hold them, hi does
    while lo < hi:
        mid = (lo + hi) // 2
        if refusal(resized(design, {**sizes, side: start + mid * SIZE_STEP_MM}), hint=False) is None:
            hi = mid
        else:
            lo = mid + 1
    return start + hi * SIZE_STEP_MM


def _beyond_reach(broken: InputError, unstated: tuple[str, ...], far: dict[str, float]) -> InputError:
    """The refusal of the largest board tried; where it names a side the spec left unstated, saying so."""
    if not isinstance(broken, SpecError) or broken.key.removeprefix("pcb.") not in unstated:
        return broken
    side = broken.key.removeprefix("pcb.")
    why = f"not stated: sized to fit, and no board up to {far[side]:g} mm holds the parts"
    return SpecError(broken.key, broken.value, broken.allowed, f"{why}; {broken.hint}" if broken.hint else why)


def _rounded_up(mm: float) -> float:
    return math.ceil(mm / SIZE_STEP_MM - 1e-9) * SIZE_STEP_MM


def _default(side: str) -> float:
    return float(Pcb.model_fields[side].default)


def _largest(side: str) -> float:
    """The most the spec allows for ``side`` (its schema's bound), mm."""
    return float(next(m.le for m in Pcb.model_fields[side].metadata if getattr(m, "le", None) is not None))
