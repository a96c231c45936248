"""What :func:`magfab.design.derive` leaves to the stage above it: the checks that refuse a spec before any of the
build's work, each with one :class:`~magfab.errors.SpecError` naming the key. ``magfab check``, the pipeline's plan
and the design search call it right after deriving."""

from __future__ import annotations

from ..design import Design
from ..limits import Cost, check_limits
from ..reference_chip import reference_chip

__all__ = ["preflight"]


def preflight(design: Design) -> Cost:
    """Refuse ``design`` as ``magfab check`` and ``magfab build`` do: the reference chip's address and site (refused
    for an array), then what the build would cost against its limits (:mod:`magfab.limits`). Returns the cost."""
    reference_chip(design)
    return check_limits(design)
