"""Elastomer force models: normal force against indentation, magnet displacement, and shear stiffness.

A rigid flat frictionless indenter pushes the elastomer's top down by ``delta`` (the indentation, mm).
Every normal model returns a :class:`Curve` (force, magnet displacement, stiffness, peak stretch and
stress against indentation). Cheapest first:

``column``
    Closed form. The elastomer as a *volume-equivalent column*: each horizontal slice keeps its silicone
    volume, so the body becomes a cylinder of radius R and height H_c = V_silicone / (pi R^2), bonded at the
    base and loaded by a frictionless plate. Neo-Hookean uniaxial compression, F = mu A (lambda^-2 - lambda),
    times the Gent-Lindley bonded-face factor 1 + 2 S^2 with S = R / (4 H_c) (one bonded face and one
    frictionless face is half of a 2 H_c block bonded on both faces, S = loaded area / free area).
``hertz_column``
    Closed form. Hertz contact of the hemispherical cap, F = (16/3) mu sqrt(R) delta_c^(3/2) (incompressible),
    in series with the column of the cylindrical base below the cap; the force balance is solved numerically.
    A flat tip has no cap: the model is then the column.
``fe``
    Axisymmetric large-strain finite elements built on scikit-fem: incompressible neo-Hookean (or Yeoh), mixed
    displacement-pressure formulation with Taylor-Hood P2/P1 triangles (inf-sup stable, so no volumetric
    locking) and an exact incompressibility constraint (Lagrange multiplier, no penalty); base bonded; magnet a
    rigid inclusion (every node on the magnet's surface shares one axial displacement and has zero radial
    displacement); indenter by an active set on the surface nodes (frictionless: only the axial displacement of a
    node in contact is constrained). Newton iterations with load stepping, automatic step cutting, and failure
    detection: element inversion, Newton non-convergence and excessive distortion raise :class:`MechanicsError`
    naming the indentation.

Shear: :func:`shear_stiffness` (Timoshenko closed form, or a small-strain Fourier-mode-1 FE of the same
axisymmetric body under a lateral load on the magnet).

Units: lengths in mm, forces in N, moduli and stresses in kPa at the API; the closed forms are evaluated in SI.
The FE solves the dimensionless problem (lengths in mm, stresses in units of mu) and converts to SI in one place,
:func:`_newton_per_mu_mm2`.

Scaling law used for the material band: an incompressible material with one modulus (neo-Hookean, or Yeoh with
fixed C20/C10 and C30/C10) under prescribed indentation has a displacement field independent of mu, and every
force and stress proportional to mu. One solve therefore gives the soft, nominal and stiff curves
(:meth:`Curve.scaled`, :func:`band_curves`); all three models obey it, and a test checks it.

Known limit (measured by bench/mechanics.py): with the magnet bonded and its edges sharp, as the paper's model
has it, the silicone at the magnet's lower outer edge is crushed while the magnet is pushed down. The strain there
is singular, so the indentation at which the FE reports excessive distortion (or, without the stretch limit,
element inversion) falls as the mesh is refined (MagOne: 2.4 mm at a 1 mm mesh, 2.0 mm at 0.5 mm, 1.6 mm at
0.25 mm), while the force up to that point converges. The paper's 3 mm range was "limited by stress concentration
at the magnet edge": the same effect. ``fe(..., on_failure="truncate")`` returns the curve up to the failure and
says where and why, for a caller that uses the failure as the range limit.

scikit-fem (and scipy's sparse solvers) are imported inside the functions that need them, so importing this
module is cheap.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from ..spec import Tip

if TYPE_CHECKING:
    from ..design import Design
    from ..recipes import Recipe

__all__ = [
    "MechanicsError",
    "Body",
    "Curve",
    "Convergence",
    "band",
    "band_curves",
    "column",
    "hertz_column",
    "fe",
    "convergence",
    "shear_stiffness",
    "shear_compliance",
    "MODELS",
    "SHEAR_MODELS",
    "measure",
]

HEMISPHERE, FLAT = Tip.HEMISPHERE, Tip.FLAT
#: Largest principal stretch (and smallest, as its inverse) the FE accepts before calling the mesh too distorted
#: to trust: 10 is Ecoflex's elongation at break (~900 %), beyond which no silicone answer is physical.
STRETCH_LIMIT = 10.0
#: Default FE mesh size for a build, as a fraction of the elastomer radius (0.5 mm for MagOne).
BUILD_MESH_FRACTION = 1.0 / 12.0


class MechanicsError(ValueError):
    """An elastomer model could not give a trustworthy answer (bad input, inverted element, no convergence)."""


# ---- value objects ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Body:
    """Geometry of the elastomer for mechanics, in mm, in the elastomer frame (z = 0 on the bonded base).

    ``base_height_mm`` is the cylindrical part; for a hemispherical tip the cap's radius is ``radius_mm`` and
    ``height_mm = base_height_mm + radius_mm``; for a flat tip ``base_height_mm = height_mm`` (``tip`` takes a
    :class:`magfab.spec.Tip` or its value). The magnet is a
    rigid cylinder on the axis whose lower face is ``magnet_z_mm`` above the base; ``magnet_radius_mm = 0``
    means no magnet. The insertion channel and the pocket clearance are not modelled (a bonded magnet, solid
    silicone).
    """

    radius_mm: float
    height_mm: float
    base_height_mm: float
    tip: Tip = Tip.HEMISPHERE
    magnet_radius_mm: float = 0.0
    magnet_height_mm: float = 0.0
    magnet_z_mm: float = 0.0

    def __post_init__(self) -> None:
        try:
            tip = Tip(self.tip)
        except ValueError:
            raise MechanicsError(f"Input tip must be 'hemisphere' or 'flat'; instead received {self.tip!r}") from None
        object.__setattr__(self, "tip", tip)
        for name in ("radius_mm", "height_mm", "base_height_mm", "magnet_radius_mm", "magnet_height_mm",
                     "magnet_z_mm"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v < 0.0:
                raise MechanicsError(f"Input {name} must be a finite number >= 0; instead received {v!r}")
            object.__setattr__(self, name, v)
        R, H, hb = self.radius_mm, self.height_mm, self.base_height_mm
        if R <= 0.0 or H <= 0.0:
            raise MechanicsError(f"Input radius_mm and height_mm must be > 0; instead received {R!r}, {H!r}")
        tol = 1e-9 * max(R, H)
        if tip == FLAT and abs(hb - H) > tol:
            raise MechanicsError(f"Input base_height_mm must equal height_mm ({H:g}) for a flat tip; "
                                 f"instead received {hb!r}")
        if tip == HEMISPHERE and abs(hb + R - H) > tol:
            raise MechanicsError(f"Input base_height_mm must be height_mm - radius_mm ({H - R:g}) for a "
                                 f"hemispherical tip; instead received {hb!r}")
        if (self.magnet_radius_mm > 0.0) != (self.magnet_height_mm > 0.0):
            raise MechanicsError("Input magnet_radius_mm and magnet_height_mm must both be > 0 (a magnet) or "
                                 f"both 0 (none); instead received {self.magnet_radius_mm!r}, "
                                 f"{self.magnet_height_mm!r}")
        if self.has_magnet:
            rm, zm, zt = self.magnet_radius_mm, self.magnet_z_mm, self.magnet_top_mm
            if zm <= tol:
                raise MechanicsError(f"Input magnet_z_mm must be > 0 (the magnet cannot touch the bonded base); "
                                     f"instead received {zm!r}")
            if rm > R + tol or zt > H + tol:
                raise MechanicsError(f"Input magnet ({rm:g} mm radius, top at {zt:g} mm) must fit inside the "
                                     f"elastomer ({R:g} mm radius, {H:g} mm high)")
            if tip == HEMISPHERE and zt > hb and math.hypot(rm, zt - hb) >= R - tol:
                raise MechanicsError(f"Input magnet (corner at r = {rm:g}, z = {zt:g} mm) must lie inside the "
                                     f"hemispherical cap of radius {R:g} mm")

    @classmethod
    def from_design(cls, design: "Design") -> "Body":
        """The elastomer of a :class:`magfab.design.Design` (board-frame magnet height moved to the base frame)."""
        return cls(radius_mm=design.elastomer_radius_mm, height_mm=design.elastomer_height_mm,
                   base_height_mm=design.base_height_mm, tip=design.tip,
                   magnet_radius_mm=design.magnet_radius_mm, magnet_height_mm=design.magnet_height_mm,
                   magnet_z_mm=design.z_magnet_low_mm - design.z_elastomer_base_mm)

    @property
    def has_magnet(self) -> bool:
        return self.magnet_radius_mm > 0.0

    @property
    def magnet_top_mm(self) -> float:
        return self.magnet_z_mm + self.magnet_height_mm

    @property
    def magnet_is_top_plate(self) -> bool:
        """A flat tip whose magnet spans the top face: the indenter then pushes the magnet itself."""
        return (self.has_magnet and self.tip == FLAT and self.magnet_radius_mm >= self.radius_mm * (1 - 1e-9)
                and self.magnet_top_mm >= self.height_mm * (1 - 1e-12))

    @property
    def area_mm2(self) -> float:
        return math.pi * self.radius_mm**2

    def silicone_volume_below_mm3(self, z_mm: float) -> float:
        """Silicone volume (mm^3) between the base and height ``z_mm`` (the magnet excluded)."""
        R, hb = self.radius_mm, self.base_height_mm
        z = min(max(z_mm, 0.0), self.height_mm)
        v = math.pi * R * R * min(z, hb)
        if z > hb:  # the cap: pi * integral of (R^2 - s^2) ds from 0 to z - hb
            s = z - hb
            v += math.pi * (R * R * s - s**3 / 3.0)
        if self.has_magnet:
            v -= math.pi * self.magnet_radius_mm**2 * min(max(z - self.magnet_z_mm, 0.0), self.magnet_height_mm)
        return v

    def scaled(self, factor: float) -> "Body":
        """The same shape with every length multiplied by ``factor``."""
        return replace(self, radius_mm=self.radius_mm * factor, height_mm=self.height_mm * factor,
                       base_height_mm=self.base_height_mm * factor,
                       magnet_radius_mm=self.magnet_radius_mm * factor,
                       magnet_height_mm=self.magnet_height_mm * factor, magnet_z_mm=self.magnet_z_mm * factor)


@dataclass(frozen=True, eq=False)
class Curve:
    """A force-indentation curve for one shear modulus. Arrays have shape (n,), one entry per indentation.

    ``magnet_displacement_mm`` is the magnet's axial displacement, positive downwards (towards the chip), NaN
    without a magnet. ``stiffness_N_per_mm`` is dF/d(indentation). ``max_stretch`` is the largest principal
    stretch anywhere in the body (FE) or in the column; ``max_stress_kPa`` the largest principal Cauchy stress
    magnitude (FE: over the quadrature points, so it grows under refinement at the magnet's sharp edge, a
    stress singularity; column: the axial stress; Hertz: the larger of the peak contact pressure and the column
    stress). ``mesh_mm`` is the FE mesh size (None for closed forms).
    """

    model: str
    mu_kPa: float
    indentation_mm: np.ndarray
    force_N: np.ndarray
    magnet_displacement_mm: np.ndarray
    stiffness_N_per_mm: np.ndarray
    max_stretch: np.ndarray
    max_stress_kPa: np.ndarray
    mesh_mm: float | None = None
    info: Mapping[str, object] = field(default_factory=dict)

    def scaled(self, mu_kPa: float) -> "Curve":
        """The same curve for another shear modulus: forces, stiffness and stresses scale with mu (module doc)."""
        k = _check_mu(mu_kPa) / self.mu_kPa
        info = dict(self.info)
        if "tangent_N_per_mm" in info:
            info["tangent_N_per_mm"] = np.asarray(info["tangent_N_per_mm"]) * k
        return replace(self, mu_kPa=float(mu_kPa), force_N=self.force_N * k,
                       stiffness_N_per_mm=self.stiffness_N_per_mm * k, max_stress_kPa=self.max_stress_kPa * k,
                       info=info)

    def rows(self) -> list[tuple[float, float]]:
        """(indentation_mm, force_N) pairs, for JSON."""
        return [(float(d), float(f)) for d, f in zip(self.indentation_mm, self.force_N)]


@dataclass(frozen=True, eq=False)
class Convergence:
    """Mesh study (:func:`convergence`): FE curves on nested meshes, errors against the finest, observed orders."""

    mesh_mm: np.ndarray
    force_N: np.ndarray  # (n_mesh, n_indentation)
    error: np.ndarray  # (n_mesh - 1,)
    rate: float
    rates: np.ndarray  # (n_mesh - 2,)
    reference_mesh_mm: float
    time_s: np.ndarray


def _check_mu(mu_kPa: float) -> float:
    mu = float(mu_kPa)
    if not math.isfinite(mu) or mu <= 0.0:
        raise MechanicsError(f"Input mu_kPa must be a finite shear modulus > 0; instead received {mu_kPa!r}")
    return mu


def _check_indentation(indentation_mm: Sequence[float] | np.ndarray) -> np.ndarray:
    d = np.atleast_1d(np.asarray(indentation_mm, dtype=float))
    if d.ndim != 1 or d.size == 0 or not np.all(np.isfinite(d)) or np.any(d < 0.0) or np.any(np.diff(d) < 0.0):
        raise MechanicsError("Input indentation_mm must be a non-empty, non-decreasing 1-D array of finite "
                             f"values >= 0; instead received {indentation_mm!r}")
    return d


def _newton_per_mu_mm2(mu_kPa: float) -> float:
    """Force in N of one dimensionless FE force unit (mu * mm^2) at shear modulus mu_kPa: kPa * mm^2 = 1e-3 N."""
    return mu_kPa * 1e3 * 1e-6


# ---- material band -----------------------------------------------------------------------------------------


def band(material_recipe: "Recipe | str") -> tuple[float, float, float]:
    """(soft, nominal, stiff) neo-Hookean shear modulus in kPa from a materials recipe (or its catalogue key)."""
    if isinstance(material_recipe, str):
        from ..recipes import catalogue

        materials = catalogue("materials")
        if material_recipe not in materials:
            raise MechanicsError(f"Input material must be one of {', '.join(sorted(materials))}; "
                                 f"instead received {material_recipe!r}")
        material_recipe = materials[material_recipe]
    if "shear_modulus_kPa" not in material_recipe.quantities:
        raise MechanicsError(f"Input material {material_recipe.key!r} must give shear_modulus_kPa")
    q = material_recipe["shear_modulus_kPa"]
    return (q.low, q.nominal, q.high)


def band_curves(body: Body, mu_band_kPa: Sequence[float], model: str = "fe",
                indentation_mm: Sequence[float] | np.ndarray = (0.0,), **options: object) -> dict[str, Curve]:
    """Curves for (soft, nominal, stiff) moduli from ONE solve at the nominal modulus, scaled by mu.

    ``mu_band_kPa`` is what :func:`band` returns; ``model`` a key of :data:`MODELS`; ``options`` go to the model.
    Returns {"soft": ..., "nominal": ..., "stiff": ...}.
    """
    soft, nominal, stiff = (float(m) for m in mu_band_kPa)
    if model not in MODELS:
        raise MechanicsError(f"Input model must be one of {', '.join(MODELS)}; instead received {model!r}")
    ref = MODELS[model](body, nominal, indentation_mm, **options)
    return {"soft": ref.scaled(soft), "nominal": ref, "stiff": ref.scaled(stiff)}


# ---- closed forms --------------------------------------------------------------------------------------------


def _shape_factor(radius_mm: float, height_mm: float, bonded_faces: int) -> float:
    """Loaded area over free area: R / (2 H) bonded on both faces; R / (4 H) bonded on one and frictionless on the
    other (by symmetry half of a 2 H column bonded on both)."""
    return radius_mm / (2.0 * height_mm) if bonded_faces == 2 else radius_mm / (4.0 * height_mm)


def _column_law(mu_kPa: float, area_mm2: float, height_mm: float, radius_mm: float, bonded_faces: int = 1):
    """Force (N) and stiffness (N/mm) of the bonded neo-Hookean column as functions of the stretch lambda, with the
    Gent-Lindley factor 1 + 2 S^2."""
    s = _shape_factor(radius_mm, height_mm, bonded_faces)
    k = mu_kPa * 1e3 * area_mm2 * 1e-6 * (1.0 + 2.0 * s * s)  # N

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
    if body.has_magnet:
        um = d * body.silicone_volume_below_mm3(body.magnet_z_mm) / A / Hc
    else:
        um = np.full_like(d, np.nan)
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
    mu = mu_kPa * 1e-3  # N/mm^2
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
    c_hertz = 16.0 / 3.0 * mu * 1e-3 * math.sqrt(R)  # N / mm^1.5
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

        def gap(l: float) -> float:  # total approach at column stretch l, minus the target
            f = float(col_force(np.float64(l)))
            return (f / c_hertz) ** (2.0 / 3.0) + (1.0 - l) * hc - delta

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
        um = np.array([(1.0 - l) * hc * frac + float(_hertz_axis_displacement(f, ai, np.array(depth), mu))
                       for l, f, ai in zip(lam, F, a)])
    else:
        um = np.full_like(d, np.nan)
    return Curve("hertz_column", mu, d, F, um, K, lam**-0.5, np.maximum(p0, col_stress),
                 info={"base_column_height_mm": hc, "contact_radius_mm": a})


# ---- FE: mesh --------------------------------------------------------------------------------------------------

_AXIS, _BASE, _OUTER, _MAGNET = 1, 2, 4, 8


@dataclass(frozen=True, eq=False)
class _Mesh:
    """A triangulation of the body's (r, z) profile in mm, counter-clockwise, with boundary tags per vertex."""

    p: np.ndarray  # (2, n_vertices)
    t: np.ndarray  # (3, n_triangles)
    tags: np.ndarray  # (n_vertices,) bitmask of _AXIS, _BASE, _OUTER, _MAGNET
    h: float
    min_angle_deg: float


def _inside(body: Body, r: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Strictly inside the silicone (outside the magnet)."""
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    if body.tip == FLAT:
        outer = (r > 0) & (r < R) & (z > 0) & (z < H)
    else:
        outer = (r > 0) & (z > 0) & (((r < R) & (z <= hb)) | ((z > hb) & (r * r + (z - hb) ** 2 < R * R)))
    if body.has_magnet:
        outer &= ~((r < body.magnet_radius_mm) & (z > body.magnet_z_mm) & (z < body.magnet_top_mm))
    return outer


def _intervals_minus(a: float, b: float, c: float, d: float) -> list[tuple[float, float]]:
    """[a, b] without the open interval (c, d)."""
    if d <= a or c >= b:
        return [(a, b)]
    out = []
    if c > a:
        out.append((a, c))
    if d < b:
        out.append((d, b))
    return out


def _boundary_pieces(body: Body) -> list[tuple[str, tuple, int]]:
    """Boundary pieces of the silicone profile: ("seg", (r0, z0, r1, z1), tag) or
    ("arc", (r_centre, z_centre, radius, angle0, angle1), tag)."""
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    rm, zm, zt = body.magnet_radius_mm, body.magnet_z_mm, body.magnet_top_mm
    mag = body.has_magnet
    pieces: list[tuple[str, tuple, int]] = []
    for z0, z1 in _intervals_minus(0.0, H, zm, zt) if mag else [(0.0, H)]:
        pieces.append(("seg", (0.0, z0, 0.0, z1), _AXIS))
    pieces.append(("seg", (0.0, 0.0, R, 0.0), _BASE))
    side_cut = mag and rm >= R * (1 - 1e-12)
    for z0, z1 in _intervals_minus(0.0, hb, zm, zt) if side_cut else [(0.0, hb)]:
        pieces.append(("seg", (R, z0, R, z1), _OUTER))
    if body.tip == FLAT:
        top_cut = mag and zt >= H * (1 - 1e-12)
        for r0, r1 in _intervals_minus(0.0, R, 0.0, rm) if top_cut else [(0.0, R)]:
            pieces.append(("seg", (r1, H, r0, H), _OUTER))
    else:
        pieces.append(("arc", (0.0, hb, R, 0.0, 0.5 * math.pi), _OUTER))
    if mag:
        pieces.append(("seg", (0.0, zm, rm, zm), _MAGNET))
        pieces.append(("seg", (rm, zm, rm, zt), _MAGNET))
        pieces.append(("seg", (rm, zt, 0.0, zt), _MAGNET))
    return pieces


def _sample_piece(kind: str, geo: tuple, h: float) -> np.ndarray:
    """Points (2, n) along one boundary piece, both ends included, spacing at most h."""
    if kind == "seg":
        r0, z0, r1, z1 = geo
        n = max(1, math.ceil(math.hypot(r1 - r0, z1 - z0) / h - 1e-9))
        s = np.linspace(0.0, 1.0, n + 1)
        return np.vstack([r0 + s * (r1 - r0), z0 + s * (z1 - z0)])
    rc, zc, rad, a0, a1 = geo
    n = max(2, math.ceil(rad * (a1 - a0) / h - 1e-9))
    a = np.linspace(a0, a1, n + 1)
    pts = np.vstack([rc + rad * np.cos(a), zc + rad * np.sin(a)])
    for i, ang in ((0, a0), (-1, a1)):  # exact ends, so they merge with the neighbouring pieces
        pts[:, i] = (rc + rad * round(math.cos(ang)), zc + rad * round(math.sin(ang)))
    return pts


def _lattice_mesh(body: Body, h: float) -> _Mesh:
    """Deterministic mesh of size ~h: boundary points every <= h, an equilateral lattice inside (kept >= h/2 from
    the boundary), Delaunay, a few Laplacian smoothing sweeps of the interior points, and checks."""
    from scipy.spatial import Delaunay, cKDTree

    scale = max(body.radius_mm, body.height_mm)
    key = 1e-9 * scale
    merged: dict[tuple[int, int], list] = {}
    dense = []
    for kind, geo, tag in _boundary_pieces(body):
        for r, z in _sample_piece(kind, geo, h).T:
            k = (round(r / key), round(z / key))
            if k in merged:
                merged[k][2] |= tag
            else:
                merged[k] = [r, z, tag]
        dense.append(_sample_piece(kind, geo, h / 8.0))
    bnd = np.array([(v[0], v[1]) for v in merged.values()]).T
    btag = np.array([v[2] for v in merged.values()], dtype=np.int64)

    dz = h * math.sqrt(3.0) / 2.0
    rows = np.arange(1, int(body.height_mm / dz) + 2)
    cols = np.arange(0, int(body.radius_mm / h) + 2)
    rr = (cols[None, :] + 0.5 * (rows[:, None] % 2)) * h
    zz = np.broadcast_to(rows[:, None] * dz, rr.shape)
    r, z = rr.ravel(), zz.ravel()
    keep = _inside(body, r, z)
    r, z = r[keep], z[keep]
    dist, _ = cKDTree(np.hstack(dense).T).query(np.vstack([r, z]).T)
    keep = dist > 0.5 * h
    p = np.hstack([bnd, np.vstack([r[keep], z[keep]])])
    tags = np.concatenate([btag, np.zeros(int(keep.sum()), dtype=np.int64)])

    t = Delaunay(p.T, qhull_options="Qbb Qc Qz Q12").simplices.T
    t = _orient(p, t)
    cr, cz = p[:, t].mean(axis=1)
    area = _areas(p, t)
    t = t[:, _inside(body, cr, cz) & (area > 1e-10 * h * h)]
    t = _smooth(p, t, tags == 0, sweeps=4)
    return _finish(body, p, t, h)


def _areas(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    a, b, c = p[:, t[0]], p[:, t[1]], p[:, t[2]]
    return 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _orient(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    t = t.copy()
    neg = _areas(p, t) < 0
    t[1, neg], t[2, neg] = t[2, neg].copy(), t[1, neg].copy()
    return t


def _smooth(p: np.ndarray, t: np.ndarray, movable: np.ndarray, sweeps: int) -> np.ndarray:
    """Laplacian smoothing of the movable points in place (kept only while every triangle stays positive)."""
    n = p.shape[1]
    edges = np.hstack([t[[0, 1]], t[[1, 2]], t[[2, 0]]])
    edges = np.unique(np.sort(edges, axis=0), axis=1)
    deg = np.bincount(edges.ravel(), minlength=n).astype(float)
    used = deg > 0
    for _ in range(sweeps):
        acc = np.zeros_like(p)
        for a, b in ((0, 1), (1, 0)):
            np.add.at(acc, (slice(None), edges[a]), p[:, edges[b]])
        new = p.copy()
        m = movable & used
        new[:, m] = acc[:, m] / deg[m]
        if np.all(_areas(new, t) > 0):
            p[:, :] = new
        else:
            break
    return t


def _finish(body: Body, p: np.ndarray, t: np.ndarray, h: float) -> _Mesh:
    """Drop unused points, project boundary points onto the cap, tag the boundary geometrically, and check."""
    used = np.zeros(p.shape[1], dtype=bool)
    used[t.ravel()] = True
    renum = np.cumsum(used) - 1
    p, t = p[:, used].copy(), renum[t]
    edges = np.sort(np.hstack([t[[0, 1]], t[[1, 2]], t[[2, 0]]]), axis=0)
    uniq, counts = np.unique(edges, axis=1, return_counts=True)
    bedges = uniq[:, counts == 1]
    on_boundary = np.zeros(p.shape[1], dtype=bool)
    on_boundary[bedges.ravel()] = True
    tags = _tag(body, p, on_boundary)
    if np.any(on_boundary & (tags == 0)) or bedges.shape[1] != int(on_boundary.sum()):
        raise MechanicsError(f"fe: mesh generation failed for mesh_mm = {h:g} (the triangulation does not follow "
                             "the body's outline); try another mesh size")
    if np.any(_areas(p, t) <= 0):
        raise MechanicsError(f"fe: mesh generation produced an inverted triangle for mesh_mm = {h:g}")
    return _Mesh(p, t, tags, h, _min_angle(p, t))


def _tag(body: Body, p: np.ndarray, on_boundary: np.ndarray) -> np.ndarray:
    """Boundary tags from geometry; boundary points near the cap are projected onto the sphere first."""
    r, z = p
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    tol = 1e-7 * max(R, H)
    tags = np.zeros(p.shape[1], dtype=np.int64)
    tags[on_boundary & (r < tol)] |= _AXIS
    tags[on_boundary & (z < tol)] |= _BASE
    if body.has_magnet:
        rm, zm, zt = body.magnet_radius_mm, body.magnet_z_mm, body.magnet_top_mm
        on_side = (np.abs(r - rm) < tol) & (z > zm - tol) & (z < zt + tol)
        on_face = ((np.abs(z - zm) < tol) | (np.abs(z - zt) < tol)) & (r < rm + tol)
        tags[on_boundary & (on_side | on_face)] |= _MAGNET
    outer = on_boundary & (np.abs(r - R) < tol) & (z < hb + tol)
    if body.tip == FLAT:
        outer |= on_boundary & (np.abs(z - H) < tol)
    else:
        cap = on_boundary & (z > hb - tol) & (tags & (_AXIS | _MAGNET) == 0) | (
            on_boundary & (r < tol) & (z > H - tol))
        rho = np.hypot(r[cap], z[cap] - hb)
        p[0, cap] = r[cap] * R / rho  # chord midpoints of a refined mesh move onto the sphere
        p[1, cap] = hb + (z[cap] - hb) * R / rho
        outer |= cap
    tags[outer] |= _OUTER
    return tags


def _min_angle(p: np.ndarray, t: np.ndarray) -> float:
    best = 180.0
    for i in range(3):
        a, b, c = p[:, t[i]], p[:, t[(i + 1) % 3]], p[:, t[(i + 2) % 3]]
        u, v = b - a, c - a
        cos = np.sum(u * v, axis=0) / (np.linalg.norm(u, axis=0) * np.linalg.norm(v, axis=0))
        best = min(best, float(np.degrees(np.arccos(np.clip(cos, -1, 1))).min()))
    return best


@lru_cache(maxsize=16)
def _body_mesh(body: Body, h: float, refine: int = 0, refine_near_apex_mm: float = 0.0) -> _Mesh:
    """The mesh of size h, then ``refine`` rounds of refinement (uniform, or of the triangles within
    ``refine_near_apex_mm`` of the top of the axis), new boundary points moved onto the cap.

    Meshes are made for the body scaled to unit radius and then scaled back, so similar bodies get similar meshes
    (exactly, for a scale factor that is a power of two): what the scaling-invariance test relies on."""
    if not (math.isfinite(h) and h > 0.0):
        raise MechanicsError(f"Input mesh_mm must be a finite size > 0; instead received {h!r}")
    if h > 0.5 * min(body.radius_mm, body.height_mm):
        raise MechanicsError(f"Input mesh_mm must be at most half the body's radius and height; "
                             f"instead received {h!r}")
    unit = body.radius_mm
    m = _unit_mesh(body.scaled(1.0 / unit), h / unit, refine, refine_near_apex_mm / unit)
    return _Mesh(m.p * unit, m.t, m.tags, m.h * unit, m.min_angle_deg)


@lru_cache(maxsize=16)
def _unit_mesh(body: Body, h: float, refine: int, refine_near: float) -> _Mesh:
    """_body_mesh for a body of unit radius; ``h`` of the result is the size away from any local refinement."""
    mesh = _lattice_mesh(body, h)
    from skfem import MeshTri

    for _ in range(refine):
        m = MeshTri(mesh.p, np.ascontiguousarray(mesh.t), sort_t=False)
        if refine_near > 0.0:
            c = m.p[:, m.t].mean(axis=1)
            m = m.refined(np.nonzero(np.hypot(c[0], c[1] - body.height_mm) < refine_near)[0])
        else:
            m = m.refined()
        p = np.array(m.p, dtype=float)
        mesh = _finish(body, p, _orient(p, np.array(m.t)), mesh.h if refine_near > 0.0 else mesh.h / 2.0)
    return mesh


def _clear_caches() -> None:
    """Forget meshes and discretisations (for cold timings)."""
    for f in (_body_mesh, _unit_mesh, _axisym, _mode1_matrix):
        f.cache_clear()


# ---- FE: axisymmetric large-strain discretisation ---------------------------------------------------------------


@dataclass(eq=False)
class _Axisym:
    """Taylor-Hood P2/P1 axisymmetric discretisation of a mesh (all arrays precomputed, mm units).

    Unknowns: u_r at the N P2 nodes, then u_z, then p at the M vertices. Per quadrature point the deformation
    gradient is g = (F_rr, F_rz, F_zr, F_zz, F_thth) = g0 + B u_e; weights include 2 pi r.
    """

    mesh: _Mesh
    N: int
    M: int
    B: np.ndarray  # (nel, nq, 5, 12)
    Bt: np.ndarray  # (nel, 12, nq * 5), B transposed for the element integrals
    psi: np.ndarray  # (nel, nq, 3)
    psi_t: np.ndarray  # (nel, 3, nq)
    w: np.ndarray  # (nel, nq)
    edofs: np.ndarray  # (nel, 15)
    doflocs: np.ndarray  # (2, N)
    dof_tags: np.ndarray  # (N,)
    corner_r: np.ndarray  # (nel, 3) scalar P2 dofs of the corners (= vertex indices)
    pattern: tuple  # (unique keys' rows, cols, inverse) for fast sparse assembly


def _values(field) -> np.ndarray:
    """A scikit-fem DiscreteField's values (an ndarray subclass since 11; a named tuple with .value before)."""
    return np.asarray(field if isinstance(field, np.ndarray) else field.value)


def _scalar_p2(mesh: _Mesh):
    from skfem import Basis, ElementTriP1, ElementTriP2, MeshTri

    m = MeshTri(mesh.p, np.ascontiguousarray(mesh.t), sort_t=False)  # keep the counter-clockwise corner order
    sb = Basis(m, ElementTriP2(), intorder=4)
    pb = Basis(m, ElementTriP1(), quadrature=sb.quadrature)
    phi = np.stack([_values(sb.basis[i][0]) for i in range(6)], axis=-1)  # (nel, nq, 6)
    grad = np.stack([sb.basis[i][0].grad for i in range(6)], axis=-1)  # (2, nel, nq, 6)
    psi = np.stack([_values(pb.basis[i][0]) for i in range(3)], axis=-1)
    rq = _values(sb.global_coordinates())[0]  # (nel, nq)
    # P2 dof tags: vertices keep theirs, a boundary edge's midpoint gets the tags both ends share.
    nv = m.p.shape[1]
    tags = np.zeros(sb.N, dtype=np.int64)
    tags[:nv] = mesh.tags
    bf = m.boundary_facets()
    fv = m.facets[:, bf]
    tags[nv + bf] = mesh.tags[fv[0]] & mesh.tags[fv[1]]
    return m, sb, pb, phi, grad, psi, rq, tags


def _pattern(edofs: np.ndarray):
    n = edofs.shape[1]
    rows = np.repeat(edofs, n, axis=1).ravel()
    cols = np.tile(edofs, (1, n)).ravel()
    nd = int(edofs.max()) + 1
    keys, inverse = np.unique(rows.astype(np.int64) * nd + cols, return_inverse=True)
    return keys // nd, keys % nd, inverse.ravel(), nd


def _sparse(pattern, ke: np.ndarray):
    from scipy.sparse import csr_matrix

    r, c, inv, nd = pattern
    data = np.bincount(inv, weights=ke.ravel(), minlength=r.size)
    return csr_matrix((data, (r, c)), shape=(nd, nd))


@lru_cache(maxsize=8)
def _axisym(mesh: _Mesh) -> _Axisym:
    m, sb, pb, phi, grad, psi, rq, tags = _scalar_p2(mesh)
    nel, nq = rq.shape
    B = np.zeros((nel, nq, 5, 12))
    B[:, :, 0, :6] = grad[0]
    B[:, :, 1, :6] = grad[1]
    B[:, :, 4, :6] = phi / rq[..., None]
    B[:, :, 2, 6:] = grad[0]
    B[:, :, 3, 6:] = grad[1]
    N, M = sb.N, pb.N
    ed = sb.element_dofs.T
    edofs = np.hstack([ed, N + ed, 2 * N + pb.element_dofs.T])
    w = sb.dx * 2.0 * math.pi * rq
    Bt = np.ascontiguousarray(B.reshape(nel, nq * 5, 12).transpose(0, 2, 1))
    psi_t = np.ascontiguousarray(psi.transpose(0, 2, 1))
    return _Axisym(mesh, N, M, B, Bt, psi, psi_t, w, edofs, sb.doflocs, tags, m.t.T.copy(), _pattern(edofs))


_G0 = np.array([1.0, 0.0, 0.0, 1.0, 1.0])
# Second derivatives of J = (F_rr F_zz - F_rz F_zr) F_thth with respect to g (a symmetric constant pattern, times
# the entries of g listed in _HJ).
_HJ = ((0, 3, 4), (1, 2, 4), (0, 4, 3), (3, 4, 0), (1, 4, 2), (2, 4, 1))  # (i, j, index of g; sign below)
_HJ_SIGN = (1.0, -1.0, 1.0, 1.0, -1.0, -1.0)


def _kinematics(g: np.ndarray):
    a, b, c, d, h = (g[..., i] for i in range(5))
    det2 = a * d - b * c
    J = det2 * h
    j = np.stack([d * h, -c * h, -b * h, a * h, det2], axis=-1)
    Hm = np.zeros(g.shape + (5,))
    for (i, k, s), sign in zip(_HJ, _HJ_SIGN):
        v = sign * g[..., s]
        Hm[..., i, k] = v
        Hm[..., k, i] = v
    return det2, J, j, Hm


@dataclass(frozen=True)
class _Material:
    """Incompressible Yeoh in units of mu = 2 C10: W = 1/2 [(I1-3) + k2 (I1-3)^2 + k3 (I1-3)^3 - 2 ln J] + p (J-1).

    k2 = C20/C10, k3 = C30/C10; k2 = k3 = 0 is neo-Hookean. The -ln J term makes the reference state stress-free
    at p = 0; with J = 1 enforced it changes nothing else.
    """

    k2: float = 0.0
    k3: float = 0.0

    def response(self, g: np.ndarray, p: np.ndarray):
        """(dW/dg, d2W/dg2, dJ/dg, J, det2) at every point; g (..., 5), p (...)."""
        det2, J, j, Hm = _kinematics(g)
        s = np.sum(g * g, axis=-1) - 3.0
        f1 = 0.5 * (1.0 + 2.0 * self.k2 * s + 3.0 * self.k3 * s * s)  # dW/dI1
        f2 = 0.5 * (2.0 * self.k2 + 6.0 * self.k3 * s)  # d2W/dI1^2
        Jinv = 1.0 / J
        S = 2.0 * f1[..., None] * g + (p - Jinv)[..., None] * j
        D = (2.0 * f1)[..., None, None] * np.eye(5) + (p - Jinv)[..., None, None] * Hm
        D += (Jinv * Jinv)[..., None, None] * j[..., :, None] * j[..., None, :]
        if self.k2 or self.k3:
            D += (4.0 * f2)[..., None, None] * g[..., :, None] * g[..., None, :]
        return S, D, j, J, det2

    def cauchy(self, g: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Principal Cauchy stresses (..., 3) in units of mu: sigma = (2 W_1 b - I) / J + p I."""
        s = np.sum(g * g, axis=-1) - 3.0
        f1 = 0.5 * (1.0 + 2.0 * self.k2 * s + 3.0 * self.k3 * s * s)
        a, b, c, d, h = (g[..., i] for i in range(5))
        J = (a * d - b * c) * h
        b11, b12, b22 = a * a + b * b, a * c + b * d, c * c + d * d
        mean, rad = 0.5 * (b11 + b22), np.sqrt(0.25 * (b11 - b22) ** 2 + b12 * b12)
        bev = np.stack([mean + rad, mean - rad, h * h], axis=-1)
        return (2.0 * f1[..., None] * bev - 1.0) / J[..., None] + p[..., None]


def _stretches(g: np.ndarray) -> np.ndarray:
    """Principal stretches (..., 3): in-plane from C's 2x2 block, and the hoop stretch."""
    a, b, c, d, h = (g[..., i] for i in range(5))
    c11, c12, c22 = a * a + c * c, a * b + c * d, b * b + d * d
    mean, rad = 0.5 * (c11 + c22), np.sqrt(0.25 * (c11 - c22) ** 2 + c12 * c12)
    return np.sqrt(np.stack([mean + rad, np.maximum(mean - rad, 0.0), h * h], axis=-1))


class _StepFailure(Exception):
    """One load step failed; the march cuts the step before giving up with a MechanicsError."""


@dataclass(frozen=True, eq=False)
class _State:
    """A converged load step: the solution, its contact set, residual and tangent at x, and a factorisation of the
    reduced tangent for that contact set (from the last Newton iterate; None if there was none)."""

    x: np.ndarray
    active: np.ndarray
    iterations: int
    R: np.ndarray
    K: object
    lu: object


def _factor(K):
    from scipy.sparse.linalg import splu

    # COLAMD with threshold pivoting: the saddle-point matrix has a zero pressure block, so some pivoting is needed
    return splu(K.tocsc(), permc_spec="COLAMD", diag_pivot_thresh=0.01)


class _Indentation:
    """Newton solver for the indentation problem on one discretisation (dimensionless: mu = 1, mm)."""

    MAX_ITER = 30

    def __init__(self, body: Body, disc: _Axisym, material: _Material, base_bonded: bool = True):
        self.body, self.disc, self.mat = body, disc, material
        N, M = disc.N, disc.M
        self.ndof = 2 * N + M
        t = disc.dof_tags
        self.plate = body.magnet_is_top_plate
        on_magnet = ((t & _MAGNET) != 0) & ((t & _BASE) == 0)
        fixed_r = ((t & (_AXIS | (_BASE if base_bonded else 0))) != 0) | on_magnet
        fixed_z = ((t & _BASE) != 0) | on_magnet
        self.magnet_z = np.nonzero(on_magnet)[0] + N
        self.candidates = np.nonzero(((t & _OUTER) != 0) & ((t & (_BASE | _MAGNET)) == 0))[0]
        self.Z = disc.doflocs[1]
        self.base_free = np.concatenate([np.nonzero(~fixed_r)[0], N + np.nonzero(~fixed_z)[0],
                                         2 * N + np.arange(M)])
        scale = max(body.radius_mm, body.height_mm)
        # Residuals are nodal forces in mu * mm^2; the indenter force is ~0.1-10 scale^2, so 1e-9 scale^2 is a
        # relative accuracy of ~1e-10 on it (Newton converges quadratically: one iteration more would give 1e-20).
        self.tol = 1e-9 * scale * scale
        self.set_tol = 1e-4 * scale * scale  # revise the contact set once the residual is this small
        self.gap_tol = 1e-9 * scale

    # -- constraints --
    def constraints(self, active: np.ndarray, delta: float):
        """(T, g, prescribed, load) for the active contact nodes at ``delta``.

        Admissible states are x = T y + g: T (ndof x nfree) maps the unknowns (free dofs, and the magnet's common
        axial displacement) to all dofs; g holds the prescribed values on the ``prescribed`` dofs (the bonded base,
        the axis, the magnet's radial displacement, the nodes touching the indenter); ``load`` is d g / d delta.
        """
        from scipy.sparse import csr_matrix

        N = self.disc.N
        act = self.candidates[active]
        free = np.setdiff1d(self.base_free, N + act, assume_unique=True)
        rows, cols = [free], [np.arange(free.size)]
        n = free.size
        g = np.zeros(self.ndof)
        prescribed = np.ones(self.ndof, dtype=bool)
        prescribed[free] = False
        g[N + act] = (self.body.height_mm - delta) - self.Z[act]
        load = np.zeros(self.ndof)
        load[N + act] = -1.0
        if self.body.has_magnet:
            if self.plate:
                g[self.magnet_z] = -delta
                load[self.magnet_z] = -1.0
            else:
                rows.append(self.magnet_z)
                cols.append(np.full(self.magnet_z.size, n))
                prescribed[self.magnet_z] = False
                n += 1
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        T = csr_matrix((np.ones(rows.size), (rows, cols)), shape=(self.ndof, n))
        return T, g, prescribed, load

    # -- physics --
    def fields(self, x: np.ndarray):
        """g (nel, nq, 5) and p (nel, nq) at the quadrature points."""
        d = self.disc
        g = _G0 + np.matmul(d.B, x[d.edofs[:, None, :12, None]])[..., 0]
        p = np.matmul(d.psi, x[d.edofs[:, 12:, None]])[..., 0]
        return g, p

    def admissible(self, x: np.ndarray) -> bool:
        """No inversion: det of the in-plane block, the hoop stretch and every deformed corner triangle > 0."""
        g, _ = self.fields(x)
        det2 = g[..., 0] * g[..., 3] - g[..., 1] * g[..., 2]
        if not (np.all(det2 > 0) and np.all(g[..., 4] > 0) and np.all(np.isfinite(g))):
            return False
        d = self.disc
        corners = d.corner_r
        pr = d.mesh.p[0][corners] + x[corners]
        pz = d.mesh.p[1][corners] + x[d.N + corners]
        area = (pr[:, 1] - pr[:, 0]) * (pz[:, 2] - pz[:, 0]) - (pz[:, 1] - pz[:, 0]) * (pr[:, 2] - pr[:, 0])
        return bool(np.all(area > 0))

    def assemble(self, x: np.ndarray):
        """Residual (ndof,) and tangent (sparse) at x: R = dPi/dx, K = d2Pi/dx2."""
        d = self.disc
        g, p = self.fields(x)
        S, D, j, J, _ = self.mat.response(g, p)
        w = d.w
        nel, nq = w.shape
        Bt = d.Bt  # (nel, 12, nq * 5)
        Ru = np.matmul(Bt, (S * w[..., None]).reshape(nel, nq * 5, 1))[..., 0]
        Rp = np.matmul(d.psi_t, ((J - 1.0) * w)[..., None])[..., 0]
        R = np.bincount(d.edofs.ravel(), weights=np.hstack([Ru, Rp]).ravel(), minlength=self.ndof)
        DB = np.matmul(D * w[..., None, None], d.B).reshape(nel, nq * 5, 12)
        ke = np.zeros((nel, 15, 15))
        ke[:, :12, :12] = np.matmul(Bt, DB)
        jpsi = (j * w[..., None])[..., :, None] * d.psi[:, :, None, :]  # (nel, nq, 5, 3)
        Kup = np.matmul(Bt, jpsi.reshape(nel, nq * 5, 3))
        ke[:, :12, 12:] = Kup
        ke[:, 12:, :12] = np.transpose(Kup, (0, 2, 1))
        return R, _sparse(d.pattern, ke)

    # -- one load step --
    def solve(self, x: np.ndarray, active: np.ndarray, delta: float) -> _State:
        """Newton with an active set at indentation ``delta`` from the admissible guess x.

        Each iteration solves the tangent problem for the residual and the still-unmet prescribed values together
        (so a new contact node or a new indentation enters as a consistent tangent step, not a jump), then halves
        the step until no element inverts. Once the residual is small, nodes that penetrate the indenter join the
        contact set and nodes that pull on it leave (a semi-smooth Newton); the step is done when the residual
        vanishes and the set no longer changes. Raises _StepFailure.
        """
        N, c, top = self.disc.N, self.candidates, self.body.height_mm - delta
        active = active | (self.Z[c] + x[N + c] > top + self.gap_tol)
        T, g, prescribed, _ = self.constraints(active, delta)
        lu = None
        for it in range(1, self.MAX_ITER + 1):
            R, K = self.assemble(x)
            rem = np.where(prescribed, g - x, 0.0)
            r = T.T @ R
            if not np.all(np.isfinite(r)):
                raise _StepFailure("non-finite residual (element inversion)")
            res, pending = np.max(np.abs(r), initial=0.0), np.max(np.abs(rem))
            if res <= self.set_tol and pending <= self.gap_tol:
                add = ~active & (self.Z[c] + x[N + c] > top + self.gap_tol)
                drop = active & (-R[N + c] < -self.tol)
                if add.any() or drop.any():
                    active = (active & ~drop) | add
                    T, g, prescribed, _ = self.constraints(active, delta)
                    rem = np.where(prescribed, g - x, 0.0)
                    r = T.T @ R
                    lu = None
                elif res <= self.tol:
                    return _State(x, active, it, R, K, lu)
            lu = _factor(T.T @ K @ T)
            dx = T @ lu.solve(-(r + T.T @ (K @ rem))) + rem
            alpha = 1.0
            for _ in range(12):
                trial = x + alpha * dx
                if self.admissible(trial):
                    break
                alpha *= 0.5
            else:
                raise _StepFailure("element inversion (det F <= 0) that no Newton line search avoids")
            x = trial
        raise _StepFailure(f"Newton did not converge in {self.MAX_ITER} iterations")

    def rest(self) -> _State:
        """The unloaded state (x = 0, nothing in contact)."""
        x = np.zeros(self.ndof)
        R, K = self.assemble(x)
        return _State(x, np.zeros(self.candidates.size, dtype=bool), 0, R, K, None)

    def force(self, state: _State, delta: float) -> tuple[float, float]:
        """(force, d force / d delta) on the indenter, in mu * mm^2 and mu * mm: the reaction and its consistent
        tangent with the converged contact set (at delta = 0 the nodes touching the indenter count as in contact)."""
        active, lu = state.active, state.lu
        if delta == 0.0:
            touching = self.Z[self.candidates] + state.x[self.disc.N + self.candidates] >= \
                self.body.height_mm - self.gap_tol
            if np.any(touching & ~active):
                active, lu = active | touching, None
        T, _, _, load = self.constraints(active, delta)
        F = float(load @ state.R)
        if not np.any(load):
            return F, 0.0
        K = state.K
        Kr = T.T @ K @ T
        b = -(T.T @ (K @ load))
        if lu is None:
            y = _factor(Kr).solve(b)
        else:  # the factorisation is one Newton step old: two rounds of iterative refinement make it exact
            y = lu.solve(b)
            for _ in range(2):
                y += lu.solve(b - Kr @ y)
        dx = T @ y + load
        return F, float(load @ (K @ dx))

    def magnet_displacement(self, x: np.ndarray) -> float:
        return float(-x[self.magnet_z[0]]) if self.body.has_magnet else math.nan

    def extremes(self, x: np.ndarray) -> tuple[float, float, float]:
        """(largest principal stretch, smallest principal stretch, largest |principal Cauchy stress| / mu)."""
        g, p = self.fields(x)
        lam = _stretches(g)
        sig = self.mat.cauchy(g, p)
        return float(lam.max()), float(lam.min()), float(np.abs(sig).max())


def fe(body: Body, mu_kPa: float, indentation_mm: Sequence[float] | np.ndarray, mesh_mm: float | None = None,
       material: str = "neo-hookean", yeoh_ratios: tuple[float, float] | None = None, refine: int = 0,
       refine_near_apex_mm: float = 0.0, stretch_limit: float = STRETCH_LIMIT, base_bonded: bool = True,
       on_failure: str = "raise") -> Curve:
    """Axisymmetric large-strain FE of the indentation (module doc). Returns a :class:`Curve`.

    ``mesh_mm``: element size in mm (default ``radius / 12``, 0.5 mm for MagOne); ``refine``: extra refinement
    rounds (uniform, or near the apex within ``refine_near_apex_mm``). ``material``: "neo-hookean", or "yeoh" with
    ``yeoh_ratios = (C20/C10, C30/C10)`` (C10 = mu/2). No Yeoh coefficients are in the recipes (the sourced data
    are neo-Hookean fits), so Yeoh needs the ratios given explicitly. ``base_bonded = False`` lets the base slide
    (frictionless), for checks against the homogeneous uniaxial solution.

    Steps through the indentations in order, halving a failing step (down to 1/64 of it). On element inversion,
    Newton non-convergence, or a principal stretch beyond ``stretch_limit`` (or below its inverse) it raises
    :class:`MechanicsError` naming the indentation; with ``on_failure = "truncate"`` it instead returns the curve
    up to the last indentation reached, with the failure in ``info["failure"]`` and ``info["failed_at_mm"]``.
    """
    mu = _check_mu(mu_kPa)
    d = _check_indentation(indentation_mm)
    mat = _material(material, yeoh_ratios)
    if on_failure not in ("raise", "truncate"):
        raise MechanicsError(f"Input on_failure must be 'raise' or 'truncate'; instead received {on_failure!r}")
    h = float(mesh_mm) if mesh_mm is not None else body.radius_mm * BUILD_MESH_FRACTION
    mesh = _body_mesh(body, h, int(refine), float(refine_near_apex_mm))
    prob = _Indentation(body, _axisym(mesh), mat, bool(base_bonded))
    state = prob.rest()
    out = np.zeros((d.size, 5))
    hist: list[tuple[float, np.ndarray]] = [(0.0, state.x)]
    current, iterations, cuts, done = 0.0, 0, 0, 0
    info: dict[str, object] = {"elements": int(mesh.t.shape[1]), "dofs": int(prob.ndof),
                               "min_angle_deg": mesh.min_angle_deg, "material": material}
    try:
        for i, target in enumerate(d):
            step = target - current
            while current < target:
                trial = min(current + step, target)
                guess = _extrapolate(hist, trial)
                if not prob.admissible(guess):
                    guess = state.x.copy()
                try:
                    new = prob.solve(guess, state.active.copy(), trial)
                except _StepFailure as exc:
                    step *= 0.5
                    cuts += 1
                    if step < (target - current) / 64.0:
                        raise MechanicsError(f"fe (mesh {mesh.h:g} mm): {exc} at indentation {trial:.4g} mm "
                                             f"(last converged {current:.4g} mm)") from None
                    continue
                iterations += new.iterations
                lmax, lmin, _ = prob.extremes(new.x)
                if lmax > stretch_limit or lmin < 1.0 / stretch_limit:
                    raise MechanicsError(f"fe (mesh {mesh.h:g} mm): excessive distortion at indentation "
                                         f"{trial:.4g} mm: principal stretches {lmin:.3g} to {lmax:.3g} leave "
                                         f"[1/{stretch_limit:g}, {stretch_limit:g}]")
                state, current = new, trial
                hist = (hist + [(current, state.x)])[-2:]
            F, K = prob.force(state, target)
            lmax, _, smax = prob.extremes(state.x)
            out[i] = (F, K, prob.magnet_displacement(state.x), lmax, smax)
            done = i + 1
    except MechanicsError as exc:
        if on_failure == "raise":
            raise
        info.update(failure=str(exc), failed_at_mm=float(d[done]) if done < d.size else math.nan)
    unit = _newton_per_mu_mm2(mu)
    out, d = out[:done], d[:done]
    F, tangent = out[:, 0] * unit, out[:, 1] * unit
    info.update(newton_iterations=iterations, step_cuts=cuts, tangent_N_per_mm=tangent)
    return Curve("fe", mu, d, F, out[:, 2], _smooth_stiffness(d, F, tangent), out[:, 3], out[:, 4] * mu,
                 mesh_mm=mesh.h, info=info)


def _smooth_stiffness(d: np.ndarray, F: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """dF/d(delta) along an FE curve: second-order differences of the force where there are neighbours, else
    the consistent tangent. The tangent is exact for the discrete model but jumps by a few % each time a surface
    node enters contact; differences of the converged forces average over those jumps. At zero indentation the
    tangent is kept (a hemispherical cap's force grows as delta^1.5 there, which differences cannot follow)."""
    k = tangent.copy()
    if d.size >= 3 and np.all(np.diff(d) > 0):
        k[1:] = np.gradient(F, d, edge_order=2)[1:]
    return k


def _extrapolate(hist: list[tuple[float, np.ndarray]], delta: float) -> np.ndarray:
    """Linear predictor along the solution path from the last two converged states."""
    if len(hist) < 2:
        return hist[-1][1].copy()
    (d0, x0), (d1, x1) = hist
    if d1 <= d0:
        return x1.copy()
    return x1 + (x1 - x0) * ((delta - d1) / (d1 - d0))


def _material(material: str, yeoh_ratios: tuple[float, float] | None) -> _Material:
    if material == "neo-hookean":
        if yeoh_ratios is not None:
            raise MechanicsError("Input yeoh_ratios must be omitted for material 'neo-hookean'")
        return _Material()
    if material == "yeoh":
        if yeoh_ratios is None:
            raise MechanicsError("Input yeoh_ratios = (C20/C10, C30/C10) must be given for material 'yeoh': the "
                                 "recipes hold only neo-Hookean moduli, so there are no sourced Yeoh coefficients")
        k2, k3 = (float(v) for v in yeoh_ratios)
        return _Material(k2, k3)
    raise MechanicsError(f"Input material must be 'neo-hookean' or 'yeoh'; instead received {material!r}")


def convergence(body: Body, mu_kPa: float, indentation_mm: Sequence[float] | np.ndarray,
                base_mesh_mm: float | None = None, levels: int = 3, **options: object) -> Convergence:
    """FE on nested meshes (a base mesh, then ``levels`` uniform refinements halving the size) against the finest.

    ``error[k]`` = max over the curve of |F_k - F_finest| / max |F_finest|; ``rate`` the observed order of the
    last three meshes, log2(|F_{L-2} - F_{L-1}| / |F_{L-1} - F_L|) (Richardson: it needs no reference solution);
    ``rates`` every such triple's order, coarse to fine. Times are cold (caches cleared).
    """
    if int(levels) < 2:
        raise MechanicsError(f"Input levels must be at least 2 (three meshes give one rate); "
                             f"instead received {levels!r}")
    h0 = float(base_mesh_mm) if base_mesh_mm is not None else body.radius_mm / 6.0
    forces, times, sizes = [], [], []
    for k in range(int(levels) + 1):
        _clear_caches()
        t0 = time.perf_counter()
        c = fe(body, mu_kPa, indentation_mm, mesh_mm=h0, refine=k, **options)
        times.append(time.perf_counter() - t0)
        forces.append(c.force_N)
        sizes.append(c.mesh_mm)
    F = np.array(forces)
    err = np.max(np.abs(F[:-1] - F[-1]), axis=1) / np.max(np.abs(F[-1]))
    diffs = np.max(np.abs(np.diff(F, axis=0)), axis=1)
    rates = np.log2(diffs[:-1] / diffs[1:])
    return Convergence(np.array(sizes), F, err, float(rates[-1]), rates, sizes[-1], np.array(times))


# ---- shear ----------------------------------------------------------------------------------------------------


def _timoshenko_shear(body: Body, mu_kPa: float, ends: str) -> float:
    """G A / h / (1 + c h^2 / (9 R^2)) in N/mm for the column of height h = magnet_z below the magnet; c = 4 with
    the magnet free to tilt, 1 with it guided (BRIEF sec. 3)."""
    h, R = body.magnet_z_mm, body.radius_mm
    c = 4.0 if ends == "free" else 1.0
    return mu_kPa * 1e-3 * body.area_mm2 / h / (1.0 + c * h * h / (9.0 * R * R))


@lru_cache(maxsize=8)
def _mode1_matrix(mesh: _Mesh):
    """Small-strain, incompressible, Fourier mode-1 stiffness (mu = 1, mm) of the axisymmetric body.

    Displacement u_r = U_r cos(t), u_t = -U_t sin(t), u_z = U_z cos(t); pressure P cos(t). Strain amplitudes
    (e_rr, e_tt, e_zz, g_rz, g_rt, g_tz) = (U_r,r, (U_r-U_t)/r, U_z,z, U_r,z + U_z,r, U_t,r + (U_r-U_t)/r,
    U_t,z + U_z/r); energy pi * integral of [e_rr^2 + e_tt^2 + e_zz^2 + (g_rz^2 + g_rt^2 + g_tz^2)/2] r dr dz
    with the constraint that the divergence e_rr + e_tt + e_zz vanishes (P as its multiplier).
    """
    m, sb, pb, phi, grad, psi, rq, tags = _scalar_p2(mesh)
    nel, nq = rq.shape
    B = np.zeros((nel, nq, 6, 18))
    ur, ut, uz = slice(0, 6), slice(6, 12), slice(12, 18)
    inv_r = phi / rq[..., None]
    B[:, :, 0, ur] = grad[0]
    B[:, :, 1, ur] = inv_r
    B[:, :, 1, ut] = -inv_r
    B[:, :, 2, uz] = grad[1]
    B[:, :, 3, ur] = grad[1]
    B[:, :, 3, uz] = grad[0]
    B[:, :, 4, ut] = grad[0] - inv_r
    B[:, :, 4, ur] = inv_r
    B[:, :, 5, ut] = grad[1]
    B[:, :, 5, uz] = inv_r
    w = sb.dx * math.pi * rq
    C = np.array([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])
    Kuu = np.einsum("eqia,eqib->eab", B, B * (C[None, None, :, None] * w[..., None, None]))
    div = B[:, :, 0] + B[:, :, 1] + B[:, :, 2]  # (nel, nq, 18)
    Kup = np.einsum("eqa,eqk->eak", div * w[..., None], psi)
    N, M = sb.N, pb.N
    ed = sb.element_dofs.T
    edofs = np.hstack([ed, N + ed, 2 * N + ed, 3 * N + pb.element_dofs.T])
    ke = np.zeros((nel, 21, 21))
    ke[:, :18, :18] = Kuu
    ke[:, :18, 18:] = Kup
    ke[:, 18:, :18] = np.transpose(Kup, (0, 2, 1))
    return _sparse(_pattern(edofs), ke), N, M, tags, sb.doflocs


def _fe_shear(body: Body, mesh_mm: float | None, ends: str) -> float:
    """Lateral force on the magnet per unit lateral displacement of its lower-face centre, mu * mm (mu = 1)."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.linalg import spsolve

    if not body.has_magnet:
        raise MechanicsError("shear: the FE shear load is applied to the magnet; the body has none")
    h = float(mesh_mm) if mesh_mm is not None else body.radius_mm * BUILD_MESH_FRACTION
    K, N, M, tags, loc = _mode1_matrix(_body_mesh(body, h))
    nd = 3 * N + M
    r, z = loc
    axis = (tags & _AXIS) != 0
    base = (tags & _BASE) != 0
    mag = ((tags & _MAGNET) != 0) & ~base
    # Rigid magnet: U_r = U_t = s + phi (z - z_m), U_z = -phi r. Axis: U_z = 0, U_t tied to U_r. Base: zero.
    free_r = ~base & ~mag
    free_tz = free_r & ~axis
    idx = np.arange(N)
    free = np.concatenate([idx[free_r], N + idx[free_tz], 2 * N + idx[free_tz], 3 * N + np.arange(M)])
    col = np.full(nd, -1)
    col[free] = np.arange(free.size)
    tie = idx[axis & free_r]  # U_t on the axis follows U_r
    rows = [free, N + tie]
    cols = [col[free], col[tie]]
    vals = [np.ones(free.size), np.ones(tie.size)]
    n = free.size
    s_vec = np.zeros(nd)  # prescribed lateral translation s = 1
    s_vec[idx[mag]] = 1.0
    s_vec[N + idx[mag]] = 1.0
    phi_vec = np.zeros(nd)  # tilt about the lower face's centre
    phi_vec[idx[mag]] = z[mag] - body.magnet_z_mm
    phi_vec[N + idx[mag]] = z[mag] - body.magnet_z_mm
    phi_vec[2 * N + idx[mag]] = -r[mag]
    if ends == "free":
        nz = np.nonzero(phi_vec)[0]
        rows.append(nz)
        cols.append(np.full(nz.size, n))
        vals.append(phi_vec[nz])
        n += 1
    T = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(nd, n))
    y = spsolve((T.T @ K @ T).tocsc(), -(T.T @ (K @ s_vec)))
    x = T @ y + s_vec
    return float(s_vec @ (K @ x))


def shear_stiffness(body: Body, mu_kPa: float, model: str = "timoshenko", ends: str = "free",
                    mesh_mm: float | None = None) -> float:
    """Lateral stiffness at the magnet, N/mm: lateral force on the magnet per unit lateral displacement of the
    centre of its lower face, for a small displacement.

    ``ends``: "free" (the magnet tilts freely: force through the lower-face centre, no moment) or "guided" (the
    magnet held level). ``model``: "timoshenko", the column of radius R and height magnet_z below the magnet,
    G A / h / (1 + c h^2/(9 R^2)) with c = 4 (free) or 1 (guided); or "fe", the small-strain incompressible FE of
    the axisymmetric body under this non-axisymmetric load (Fourier mode 1, Taylor-Hood, exact in 3-D for the
    axisymmetric geometry). Linear in mu.
    """
    mu = _check_mu(mu_kPa)
    if ends not in ("free", "guided"):
        raise MechanicsError(f"Input ends must be 'free' or 'guided'; instead received {ends!r}")
    if not body.has_magnet:
        raise MechanicsError("shear: the shear stiffness is defined at the magnet; the body has none")
    if model == "timoshenko":
        if mesh_mm is not None:
            raise MechanicsError("Input mesh_mm must be omitted for the timoshenko model")
        return _timoshenko_shear(body, mu, ends)
    if model == "fe":
        return _fe_shear(body, mesh_mm, ends) * _newton_per_mu_mm2(mu)
    raise MechanicsError(f"Input model must be one of {', '.join(SHEAR_MODELS)}; instead received {model!r}")


def shear_compliance(body: Body, mu_kPa: float, model: str = "timoshenko", ends: str = "free",
                     mesh_mm: float | None = None) -> float:
    """Magnet lateral displacement per unit shear force on it, mm/N: 1 / :func:`shear_stiffness`."""
    return 1.0 / shear_stiffness(body, mu_kPa, model, ends, mesh_mm)


# ---- registry and measurement ----------------------------------------------------------------------------------

#: Normal-force models by name, cheapest first: callable(body, mu_kPa, indentation_mm, **options) -> Curve.
MODELS: Mapping[str, Callable[..., Curve]] = {"column": column, "hertz_column": hertz_column, "fe": fe}
#: Shear models by name, for shear_stiffness(model=...).
SHEAR_MODELS = ("timoshenko", "fe")


def measure(body: Body, mu_kPa: float, delta_max_mm: float, mesh_sizes_mm: Sequence[float] = (1.0, 0.75, 0.5, 0.35),
            reference_mesh_mm: float = 0.2, points: int = 13) -> dict[str, object]:
    """Speed against accuracy of every normal model on one body, for the chart.

    Runs the finest FE mesh (``reference_mesh_mm``) as the reference, then each closed form and the FE at each mesh
    size, on ``points`` indentations from 0 to ``delta_max_mm``. If the reference fails before ``delta_max_mm``
    (element inversion or excessive distortion), everything is compared over the range it reached and the failure
    is reported. Times are wall-clock seconds with caches cleared (meshing included).

    Returns {"rows": [{"model", "mesh_mm", "error", "time_s", "force_end_N", "failure"}...] (reference last),
    "compared_to_mm": float, "reference_failure": str | None}, where ``error`` is max |F - F_ref| / max |F_ref|
    over the compared range.
    """
    d = np.linspace(0.0, float(delta_max_mm), int(points))

    def timed(fn: Callable[[np.ndarray], Curve], dd: np.ndarray) -> tuple[Curve | None, float, str | None]:
        _clear_caches()
        t0 = time.perf_counter()
        try:
            c = fn(dd)
        except MechanicsError as exc:
            return None, time.perf_counter() - t0, str(exc)
        return c, time.perf_counter() - t0, None

    ref, t_ref, _ = timed(lambda dd: fe(body, mu_kPa, dd, mesh_mm=reference_mesh_mm, on_failure="truncate"), d)
    assert ref is not None
    reached = ref.indentation_mm
    if reached.size < 2:
        raise MechanicsError(f"measure: the reference FE (mesh {reference_mesh_mm:g} mm) failed at once: "
                             f"{ref.info.get('failure')}")
    scale = float(np.max(np.abs(ref.force_N)))
    runs: list[tuple[str, float | None, Callable[[np.ndarray], Curve]]] = [
        ("column", None, lambda dd: column(body, mu_kPa, dd)),
        ("hertz_column", None, lambda dd: hertz_column(body, mu_kPa, dd)),
    ]
    for h in sorted((float(v) for v in mesh_sizes_mm), reverse=True):
        runs.append(("fe", h, lambda dd, h=h: fe(body, mu_kPa, dd, mesh_mm=h)))
    rows: list[dict[str, object]] = []
    for name, h, fn in runs:
        c, t, failure = timed(fn, reached)
        err = math.nan if c is None else float(np.max(np.abs(c.force_N - ref.force_N)) / scale)
        rows.append({"model": name, "mesh_mm": h, "error": err, "time_s": t,
                     "force_end_N": math.nan if c is None else float(c.force_N[-1]), "failure": failure})
    rows.append({"model": "fe", "mesh_mm": float(reference_mesh_mm), "error": 0.0, "time_s": t_ref,
                 "force_end_N": float(ref.force_N[-1]), "failure": None})
    return {"rows": rows, "compared_to_mm": float(reached[-1]), "reference_failure": ref.info.get("failure")}
