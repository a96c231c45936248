"""The lateral field at the chip from a magnet that moves sideways and tilts (shear: a tilt of the magnet reads as
translation; docs/models.md, M16).

Frame as :mod:`.magnet`: the magnet at rest centred at the origin, axis on z, magnetised along +z; the chip on the
axis at ``gap`` below the lower face, (0, 0, -(H/2 + gap)). Under a lateral load along +x the magnet's lower-face
centre moves by ``shift`` (mm) along +x and the magnet turns by ``tilt`` (rad) about the y axis through that
centre, positive when its top leans towards +x (the rotation R_y(tilt) takes e_z to (sin tilt, 0, cos tilt));
the mechanics (:mod:`magfab.models.mechanics.shear_surface`) reports the same two quantities in the same frame.

Linearised (what the sensitivity needs; docs/models.md, M16), on the axis, with Bz0(z) the axial field (M6) and
Bz0' its derivative (positive below the magnet), by the paraxial expansion B_rho = -r/2 Bz0' (so dBx/dx = -Bz0'/2 on
the axis):

    dBx/dshift = Bz0'/2                      (the magnet moves, the chip sees it at -shift: dBr/dr at the axis)
    dBx/dtilt  = Bz0 - gap Bz0'/2            (the field vector turns with the magnet, and the chip, seen from the
                                              turned magnet, sits gap * tilt off its axis towards -x')

The two terms of dBx/dtilt have opposite signs. Far from the magnet the second wins (a dipole's ratio
gap Bz0'/(2 Bz0) is 3 gap / (2 D), D = gap + H/2: above 1 once gap > H), so a magnet leaning along the load cancels
part of the field its translation makes; close to it the first wins and the tilt adds. MagOne's crossover is at a
gap of 4.2 mm (1.7 R): at rest (6 mm) the tilt cancels, at the end of a 3 mm scan (gap 3.8 mm) it adds a little.
:func:`tilted_field` is the exact (non-linear) field of the moved magnet, from the exact kernel; the tests pin both
against magpylib's rotated ``Cylinder``. Fields in G, lengths in mm, angles in rad.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .closed_forms import axis_bz, axis_dbz_dz
from .exact import exact
from .magnet import Magnet

__all__ = ["lateral_rates", "lateral_field", "tilted_field"]


def _gap(gap_mm: ArrayLike) -> np.ndarray:
    g = np.asarray(gap_mm, dtype=float)
    if not np.all(np.isfinite(g)) or np.any(g <= 0.0):
        raise ValueError(f"gap_mm must be finite and > 0; instead received {gap_mm!r}")
    return g


def lateral_rates(magnet: Magnet, gap_mm: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(dBx/dshift in G/mm, dBx/dtilt in G/rad) at the chip on the axis, ``gap_mm`` below the lower face (any
    shape; results broadcast to it). Closed form from the axial field (module doc); exact for an axially magnetised
    cylinder."""
    g = _gap(gap_mm)
    z = -(0.5 * magnet.height_mm + g)
    slope = np.asarray(axis_dbz_dz(magnet, z, 1))  # dBz/dz on the axis, > 0 below the magnet
    d_shift = 0.5 * slope
    d_tilt = np.asarray(axis_bz(magnet, z)) - g * d_shift
    return d_shift[()], d_tilt[()]


def lateral_field(magnet: Magnet, gap_mm: ArrayLike, shift_mm: ArrayLike, tilt_rad: ArrayLike) -> np.ndarray:
    """Lateral field Bx at the chip, G, to first order in the magnet's lateral displacement ``shift_mm`` (mm, of its
    lower-face centre) and its tilt ``tilt_rad`` (rad) at axial gap ``gap_mm`` (mm); inputs broadcast together.

    With the displacement and tilt per newton of shear force (mm/N, rad/N) this is the shear sensitivity, G/N."""
    d_shift, d_tilt = lateral_rates(magnet, gap_mm)
    return (d_shift * np.asarray(shift_mm, dtype=float) + d_tilt * np.asarray(tilt_rad, dtype=float))[()]


def tilted_field(magnet: Magnet, gap_mm: ArrayLike, shift_mm: ArrayLike = 0.0, tilt_rad: ArrayLike = 0.0) -> np.ndarray:
    """Exact field (Bx, By, Bz) in G at the chip (0, 0, -(H/2 + gap)) of the magnet moved by ``shift_mm`` along +x
    and turned by ``tilt_rad`` about the y axis through its moved lower-face centre; inputs broadcast together,
    result of their shape + (3,). B(p) = Rot B0(Rot^T (p - c) + c0), c0 = (0, 0, -H/2) and c = c0 + shift e_x."""
    g, s, t = np.broadcast_arrays(_gap(gap_mm), np.asarray(shift_mm, dtype=float), np.asarray(tilt_rad, dtype=float))
    shape = g.shape
    g, s, t = g.ravel(), s.ravel(), t.ravel()
    cos, sin = np.cos(t), np.sin(t)
    # p - c = (-s, 0, -g); Rot^T = R_y(-t): (x, z) -> (x cos - z sin, x sin + z cos)
    dx, dz = -s, -g
    local = np.column_stack([dx * cos - dz * sin, np.zeros_like(g), dx * sin + dz * cos - 0.5 * magnet.height_mm])
    b = exact(magnet, local)
    out = np.column_stack([b[:, 0] * cos + b[:, 2] * sin, b[:, 1], -b[:, 0] * sin + b[:, 2] * cos])
    return out.reshape((*shape, 3))
