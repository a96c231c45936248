"""The IPC-7351B land calculator: toleranced package dimensions in, land edges out (mm).

The equations (IPC-7351B sec. 3.1.5; docs/models.md, M24), for a pair of terminals across a body of length L with
terminals T long and W wide:

    Z_max = L_min + 2 J_T + sqrt(C_L^2 + F^2 + P^2)           (outer land edges)
    G_min = S_max,rms - 2 J_H - sqrt(C_S,rms^2 + F^2 + P^2)   (inner land edges), S = L - 2T
    X_max = W_min + 2 J_S + sqrt(C_W^2 + F^2 + P^2)           (land width)

where C is a tolerance (max - min), J the toe/heel/side fillet goals of the package family and density
level, F the board fabrication and P the placement tolerance; S's tolerance is taken as the RMS of the
tolerances it is made of. Each is rounded to the table's round-off. Drawing and writing the footprint
is :mod:`magfab.board.footprint`'s job.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..recipes import Quantity, Recipe

__all__ = ["Band", "Land", "ipc_land"]


@dataclass(frozen=True)
class Band:
    """A toleranced dimension, mm."""

    min: float
    nominal: float
    max: float

    @classmethod
    def of(cls, q: Quantity) -> Band:
        return cls(q.low, q.nominal, q.high)

    @property
    def tol(self) -> float:
        return self.max - self.min


@dataclass(frozen=True)
class Land:
    """Result of the IPC equations for one pair of terminals, mm."""

    z_max: float
    g_min: float
    x_max: float

    @property
    def length(self) -> float:
        return (self.z_max - self.g_min) / 2

    @property
    def centre(self) -> float:
        return (self.z_max + self.g_min) / 4


def _round(x: float, base: float) -> float:
    return round(round(x / base) * base, 6)


def ipc_land(span: Band, terminal: Band, width: Band, goals: Recipe, tolerances: Recipe) -> Land:
    """IPC-7351B lands for terminals ``terminal`` long and ``width`` wide at each end of ``span``."""
    f = tolerances["fabrication_mm"].nominal
    p = tolerances["placement_mm"].nominal
    toe, heel, side = (goals[k].nominal for k in ("toe_mm", "heel_mm", "side_mm"))
    base = goals["round_mm"].nominal
    s_max = span.max - 2 * terminal.min
    s_min = span.min - 2 * terminal.max
    s_tol_rms = math.sqrt(span.tol**2 + 2 * terminal.tol**2)
    s_max_rms = s_max - ((s_max - s_min) - s_tol_rms) / 2
    z = span.min + 2 * toe + math.sqrt(span.tol**2 + f**2 + p**2)
    g = s_max_rms - 2 * heel - math.sqrt(s_tol_rms**2 + f**2 + p**2)
    x = width.min + 2 * side + math.sqrt(width.tol**2 + f**2 + p**2)
    return Land(_round(z, base), _round(g, base), _round(x, base))
