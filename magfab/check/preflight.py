"""What :func:`magfab.design.derive` leaves to the stage above it: the checks that refuse a spec before any of the
build's work, each with one line naming the key, and the board's size. ``magfab check``, the pipeline's plan and the
design search call it right after deriving, and go on with the design it returns."""

from __future__ import annotations

from ..board.fit import fit
from ..design import Design
from ..limits import check_limits
from ..reference_chip import reference_chip
from .links import serial_links

__all__ = ["preflight"]


def preflight(design: Design) -> Design:
    """Refuse ``design`` as ``magfab check`` and ``magfab build`` do, and return the design they go on with: the
    reference chip's address and site (refused for an array), a baud or I2C clock the readout board cannot make
    (:mod:`magfab.check.links`), what the build would cost against its limits (:mod:`magfab.limits`), then the board
    (:func:`magfab.board.fit.fit`: a size the spec states that does not hold the parts is refused as the build's
    board would refuse it; an unstated one too small for them is sized to fit, in the design returned)."""
    reference_chip(design)
    serial_links(design)
    check_limits(design)
    return fit(design)
