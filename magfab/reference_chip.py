"""The optional reference MLX90393 (``[reference]`` in the spec): where it stands on the board and how it is
addressed, before any prediction (the board is drawn side by side with the physics).

Its site is :func:`magfab.models.reference.site` for the travel the geometry allows (:meth:`Travel.bound`: every
magnet pressed to d_min or slid by the elastomer's radius less the magnet's), so what the prediction later finds at
the predicted travel can only be quieter; ``reference.distance_mm`` places it nearer or farther by hand (the
prediction then says how loud the magnets are there). Its address is the next the taxels' plan leaves (one more chip
on the bus), its designator the next U.
"""

from __future__ import annotations

from .design import Design, address_plan
from .errors import SpecError
from .models.reference import ReferenceChip, Travel, site
from .spec import Environment

__all__ = ["reference_chip", "temperature_span_C"]


def temperature_span_C(design: Design) -> float:
    """The environment's temperature span (its defaults without an ``[environment]`` section)."""
    env = design.spec.environment or Environment()
    return env.temperature_max_C - env.temperature_min_C


def reference_chip(design: Design) -> ReferenceChip | None:
    """The reference chip of ``design`` (module doc), or None without a ``[reference]`` section."""
    spec = design.spec
    if spec.reference is None:
        return None
    n = len(design.taxels)
    if design.array is not None:
        raise SpecError("reference", "present", "is for a single taxel: an array's firmware sends every chip's field "
                        "and its host compensation reads no reference chip yet", "omit [reference] or [array]")
    address, code, straps = address_plan(spec, design.chip, n + 1)[n]
    where = site(design, Travel.bound(design), temperature_span_C(design), spec.reference.distance_mm)
    top = max(t.y_mm for t in design.taxels)
    return ReferenceChip(n, where.xy_mm[0], where.xy_mm[1], where.xy_mm[1] - top, where.separation_mm, address, code,
                         straps)
