"""Closed-form normal-force models, cheapest first (both return a :class:`~.body.Curve`).

``column``
    The elastomer as a *volume-equivalent column*: each horizontal slice keeps its silicone volume, so the body
    becomes a cylinder of radius R and height H_c = V_silicone / (pi R^2), bonded at the base and loaded by a
    frictionless plate. Neo-Hookean uniaxial compression, F = mu A (lambda^-2 - lambda), times the Gent-Lindley
    bonded-face factor 1 + 2 S^2 with S = R / (4 H_c) (one bonded face and one frictionless face is half of a
    2 H_c block bonded on both faces, S = loaded area / free area).
``hertz_column``
    Hertz contact of the hemispherical cap, F = (16/3) mu sqrt(R) delta_c^(3/2) (incompressible), in series with
    the column of the cylindrical base below the cap; the force balance is solved numerically. A flat tip has no
    cap: the model is then the column.

Evaluated in N and mm (moduli converted from kPa with :data:`magfab.units.N_PER_KPA_MM2`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ...units import N_PER_KPA_MM2
from .body import FLAT, Body, Curve, MechanicsError, _check_indentation, _check_mu

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["column", "hertz_column"]


def _shape_factor(radius_mm: float, height_mm: float, bonded_faces: int) -> float:
    """Loaded area over free area: R / (2 H) bonded on both faces; R / (4 H) bonded on one and frictionless on the
    other (by symmetry half of a 2 H column bonded on both)."""
    return radius_mm / (2.0 * height_mm) if bonded_faces == 2 else radius_mm / (4.0 * height_mm)


def _column_law(mu_kPa: float, area_mm2: float, height_mm: float, radius_mm: float, bonded_faces: int = 1):
    """Force (N) and stiffness (N/mm) of the bonded neo-Hookean column as functions of the stretch lambda, with the
    Gent-Lindley factor 1 + 2 S^2."""
    s = _shape_factor(radius_mm, height_mm, bonded_faces)
    k = mu_kPa * N_PER_KPA_MM2 * area_mm2 * (1.0 + 2.0 * s * s)  # N

    def force(lam: np.ndarray) -> np.ndarray:
        return k * (lam**-2 - lam)

    def stiffness(lam: np.ndarray) -> np.ndarray:  # dF/d(shortening), shortening = (1 - lam) H
        return k * (2.0 * lam**-3 + 1.0) / height_mm

    return force, stiffness


def column(body: Body, mu_kPa: float, indentation_mm: Sequence[float] | np.ndarray) -> Curve:
    """Volume-equivalent bonded neo-Hookean column (module doc). Magnet displacement from the uniform strain.

    The magnet moves by delta * zeta_m / H_c, where zeta_m is the column coordinate of its lower face (the
    silicone volume below it over the area). Raises :class:`MechanicsError` once the column is fully compressed.
    """
    mu = _check_mu(mu_kPa)
    d = _check_indentation(indentation_mm)
    A = body.area_mm2
    Hc = body.silicone_volume_below_mm3(body.height_mm) / A
    if np.any(d >= Hc):
        raise MechanicsError(f"column: indentation {d.max():g} mm compresses the {Hc:.3f} mm column to nothing")
    lam = 1.0 - d / Hc
    faces = 2 if body.magnet_is_top_plate else 1  # a rigid magnet plate on top is a second bonded face
    force, stiffness = _column_law(mu, A, Hc, body.radius_mm, faces)
    F = force(lam)
    um = (d * body.silicone_volume_below_mm3(body.magnet_z_mm) / A / Hc if body.has_magnet
          else np.full_like(d, np.nan))
    stress = F / A * lam * 1e3  # Cauchy axial stress magnitude: N/mm^2 = MPa -> kPa; the area grows as 1/lam
    return Curve("column", mu, d, F, um, stiffness(lam), lam**-0.5, stress,
                 info={"column_height_mm": Hc, "shape_factor": _shape_factor(body.radius_mm, Hc, faces)})


def _hertz_axis_displacement(force_N: float, a_mm: float, depth_mm: np.ndarray, mu_kPa: float) -> np.ndarray:
    """Axial displacement (mm) on the axis at ``depth_mm`` below the surface of an incompressible half-space
    under a Hertz pressure of total ``force_N`` on a circle of radius ``a_mm``.

    Boussinesq for nu = 1/2: u_z = P / (4 pi mu) (1/rho + z^2/rho^3), integrated over p = p0 sqrt(1 - r^2/a^2)
    (Gauss-Legendre in r = a sin t). At depth 0 it returns pi p0 a / (8 mu), Hertz's approach.
    """
    if force_N <= 0.0 or a_mm <= 0.0:
        return np.zeros_like(depth_mm)
    p0 = 3.0 * force_N / (2.0 * math.pi * a_mm**2)  # N/mm^2
    mu = mu_kPa * N_PER_KPA_MM2  # N/mm^2
    x, w = np.polynomial.legendre.leggauss(64)
    t = 0.25 * math.pi * (x + 1.0)  # t in (0, pi/2)
    wt = 0.25 * math.pi * w
    r = a_mm * np.sin(t)
    dr = a_mm * np.cos(t)
    p = p0 * np.cos(t)
    z = np.asarray(depth_mm, dtype=float)[..., None]
    rho = np.sqrt(r * r + z * z)
    kernel = (1.0 / rho + z * z / rho**3) / (4.0 * math.pi * mu)
    return np.sum(wt * p * 2.0 * math.pi * r * dr * kernel, axis=-1)


def hertz_column(body: Body, mu_kPa: float, indentation_mm: Sequence[float] | np.ndarray) -> Curve:
    """Hertz cap (radius R, incompressible) in series with the bonded column of the cylindrical base.

    delta = delta_cap(F) + delta_column(F), solved for F by bracketing in the column stretch. The magnet moves by
    the base column's displacement at its lower face plus the Hertz half-space displacement on the axis at the
    magnet's centre. A flat tip has no cap: the result is :func:`column`, renamed.
    """
    mu = _check_mu(mu_kPa)
    d = _check_indentation(indentation_mm)
    if body.tip == FLAT:
        return replace(column(body, mu, d), model="hertz_column")
    from scipy.optimize import brentq

    R, A = body.radius_mm, body.area_mm2
    hc = body.silicone_volume_below_mm3(body.base_height_mm) / A  # silicone height of the base column
    c_hertz = 16.0 / 3.0 * mu * N_PER_KPA_MM2 * math.sqrt(R)  # N / mm^1.5
    if hc > 0.0:
        col_force, col_stiff = _column_law(mu, A, hc, R)
    F = np.zeros_like(d)
    K = np.zeros_like(d)
    lam = np.ones_like(d)
    dcap = np.zeros_like(d)
    for i, delta in enumerate(d):
        if delta == 0.0:
            continue
        if hc <= 0.0:
            dcap[i] = delta
            F[i] = c_hertz * delta**1.5
            K[i] = 1.5 * c_hertz * math.sqrt(delta)
            continue

        def gap(stretch: float, delta: float = delta) -> float:  # total approach at this stretch, minus the target
            f = float(col_force(np.float64(stretch)))
            return (f / c_hertz) ** (2.0 / 3.0) + (1.0 - stretch) * hc - delta

        lo = 1e-6
        if gap(lo) < 0.0:
            raise MechanicsError(f"hertz_column: no force balance at indentation {delta:g} mm")
        lam[i] = brentq(gap, lo, 1.0, xtol=1e-14, rtol=1e-14, maxiter=200)
        F[i] = float(col_force(np.float64(lam[i])))
        dcap[i] = (F[i] / c_hertz) ** (2.0 / 3.0)
        compliance = (2.0 / 3.0) * dcap[i] / F[i] + 1.0 / float(col_stiff(np.float64(lam[i])))
        K[i] = 1.0 / compliance
    a = np.sqrt(R * dcap)  # contact radius, mm
    p0 = np.where(a > 0, 3.0 * F / (2.0 * math.pi * np.where(a > 0, a, 1.0) ** 2), 0.0) * 1e3  # kPa
    col_stress = F / A * lam * 1e3
    if body.has_magnet:
        z_low = min(body.magnet_z_mm, body.base_height_mm)
        frac = body.silicone_volume_below_mm3(z_low) / A / hc if hc > 0 else 0.0
        depth = body.height_mm - (body.magnet_z_mm + 0.5 * body.magnet_height_mm)
        um = np.array([(1.0 - stretch) * hc * frac + float(_hertz_axis_displacement(f, ai, np.array(depth), mu))
                       for stretch, f, ai in zip(lam, F, a)])
    else:
        um = np.full_like(d, np.nan)
    return Curve("hertz_column", mu, d, F, um, K, lam**-0.5, np.maximum(p0, col_stress),
                 info={"base_column_height_mm": hc, "contact_radius_mm": a})

