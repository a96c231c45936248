"""The elastomer as the mechanics models see it: :class:`Body` (geometry), :class:`Curve` and
:class:`Convergence` (results), the material band, and the input checks every model shares.

Units: lengths in mm, forces in N, moduli and stresses in kPa. Every check raises :class:`MechanicsError` with a
message "Input X must be ...; instead received ...".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from ...errors import ModelLimitError
from ...recipes.resolve import material as resolve_material
from ...spec import Tip
from ...units import N_PER_KPA_MM2

if TYPE_CHECKING:
    from ...design import Design
    from ...recipes.resolve import Material

__all__ = ["MechanicsError", "Body", "Curve", "Convergence", "band", "check_option"]

HEMISPHERE, FLAT = Tip.HEMISPHERE, Tip.FLAT


class MechanicsError(ModelLimitError):
    """An elastomer model could not give a trustworthy answer (bad input, inverted element, no convergence)."""


E = TypeVar("E", bound=Enum)


def check_option(kind: type[E], value: object, name: str, allowed: tuple[E, ...] | None = None) -> E:
    """``kind(value)`` (so the option's old string still works), or a :class:`MechanicsError` naming the input
    ``name``, what is allowed and what came. ``allowed`` narrows the members accepted (default: all of ``kind``)."""
    members = tuple(kind) if allowed is None else tuple(allowed)
    try:
        chosen = kind(value)
    except ValueError:
        chosen = None
    if chosen is None or chosen not in members:
        if len(members) == 2:
            what = f"{members[0].value!r} or {members[1].value!r}"
        else:
            what = "one of " + ", ".join(str(m.value) for m in members)
        raise MechanicsError(f"Input {name} must be {what}; instead received {value!r}")
    return chosen


# ---- value objects ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Body:
    """Geometry of the elastomer for mechanics, in mm, in the elastomer frame (z = 0 on the bonded base).

    ``base_height_mm`` is the cylindrical part; for a hemispherical tip the cap's radius is ``radius_mm`` and
    ``height_mm = base_height_mm + radius_mm``; for a flat tip ``base_height_mm = height_mm`` (``tip`` takes a
    :class:`magfab.spec.Tip` or its value). The magnet is a
    rigid cylinder on the axis whose lower face is ``magnet_z_mm`` above the base; ``magnet_radius_mm = 0``
    means no magnet. Its two outer circular edges are rounded with radius ``magnet_edge_radius_mm`` (0: sharp;
    a design takes the magnet recipe's sourced value). By default the magnet is bonded in solid silicone (the glue
    fills the insertion channel; :data:`~magfab.models.mechanics.MODEL_DESCRIPTION` says why); ``fe(interface=
    "sliding")`` and ``fe(void=channel_wall(...))`` model an unglued magnet and an open channel. The 0.05 mm pocket
    clearance is not modelled.
    """

    radius_mm: float
    height_mm: float
    base_height_mm: float
    tip: Tip = Tip.HEMISPHERE
    magnet_radius_mm: float = 0.0
    magnet_height_mm: float = 0.0
    magnet_z_mm: float = 0.0
    magnet_edge_radius_mm: float = 0.0

    def __post_init__(self) -> None:
        tip = check_option(Tip, self.tip, "tip")
        object.__setattr__(self, "tip", tip)
        for name in ("radius_mm", "height_mm", "base_height_mm", "magnet_radius_mm", "magnet_height_mm",
                     "magnet_z_mm", "magnet_edge_radius_mm"):
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
            re = self.magnet_edge_radius_mm
            if re > min(rm, 0.5 * self.magnet_height_mm) + tol:
                raise MechanicsError(f"Input magnet_edge_radius_mm must be at most the magnet's radius and half its "
                                     f"height ({min(rm, 0.5 * self.magnet_height_mm):g} mm); instead received {re!r}")
            if tip == HEMISPHERE and zt > hb and math.hypot(rm, zt - hb) >= R - tol:
                raise MechanicsError(f"Input magnet (corner at r = {rm:g}, z = {zt:g} mm) must lie inside the "
                                     f"hemispherical cap of radius {R:g} mm")

    @classmethod
    def from_design(cls, design: Design) -> Body:
        """The elastomer of a :class:`magfab.design.Design` (board-frame magnet height moved to the base frame);
        the magnet's edge radius is the magnet recipe's nominal ``edge_radius_mm``, capped at what the magnet
        allows."""
        rm, hm = design.magnet_radius_mm, design.magnet_height_mm
        edge = design.magnet_grade.edge_radius_mm.nominal
        return cls(radius_mm=design.elastomer_radius_mm, height_mm=design.elastomer_height_mm,
                   base_height_mm=design.base_height_mm, tip=design.tip,
                   magnet_radius_mm=rm, magnet_height_mm=hm,
                   magnet_z_mm=design.z_magnet_low_mm - design.z_elastomer_base_mm,
                   magnet_edge_radius_mm=min(edge, 0.25 * min(2.0 * rm, hm)))

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
        """Silicone volume (mm^3) between the base and height ``z_mm`` (the magnet excluded, taken as a sharp-edged
        cylinder: its rounded edges add < 0.3 % silicone for MagOne, below what the closed forms resolve)."""
        R, hb = self.radius_mm, self.base_height_mm
        z = min(max(z_mm, 0.0), self.height_mm)
        v = math.pi * R * R * min(z, hb)
        if z > hb:  # the cap: pi * integral of (R^2 - s^2) ds from 0 to z - hb
            s = z - hb
            v += math.pi * (R * R * s - s**3 / 3.0)
        if self.has_magnet:
            v -= math.pi * self.magnet_radius_mm**2 * min(max(z - self.magnet_z_mm, 0.0), self.magnet_height_mm)
        return v

    def scaled(self, factor: float) -> Body:
        """The same shape with every length multiplied by ``factor``."""
        return replace(self, radius_mm=self.radius_mm * factor, height_mm=self.height_mm * factor,
                       base_height_mm=self.base_height_mm * factor,
                       magnet_radius_mm=self.magnet_radius_mm * factor,
                       magnet_height_mm=self.magnet_height_mm * factor, magnet_z_mm=self.magnet_z_mm * factor,
                       magnet_edge_radius_mm=self.magnet_edge_radius_mm * factor)


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
    info: dict[str, object] = field(default_factory=dict)

    def scaled(self, mu_kPa: float) -> Curve:
        """The same curve for another shear modulus: forces, stiffness and stresses scale with mu (:mod:`.registry`)."""
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
    """Mesh study (:func:`~.study.convergence`): FE curves on nested meshes, errors against the finest, observed
    orders."""

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
    return mu_kPa * N_PER_KPA_MM2


# ---- material band -----------------------------------------------------------------------------------------


def band(material: Material | str, law: str = "neo-hookean") -> tuple[float, float, float]:
    """(soft, nominal, stiff) shear modulus mu in kPa of a material (a design's ``design.material``, or for scripts
    its key in recipes/materials.toml) under ``law``: the recipe's neo-Hookean band, or for "yeoh" the band of its
    Yeoh law: soft, the fitted mu less the fit's RMS error; stiff, the larger of the fitted mu plus that error and
    the recipe's judgement of the stiff end, which its neo-Hookean band records: where that band's stiff end is the
    datasheet's 100 % modulus (within :data:`DATASHEET_MATCH`), the mu at which the Yeoh law meets it, P(2) = 1.75 mu
    (1 + 4 k2 + 12 k3); where the recipe left the datasheet out (Ecoflex 00-10: 4x stiffer than the raw tests), the
    neo-Hookean band's own spread (stiff over soft) on the fitted mu. Nominal: their geometric mean (as the
    neo-Hookean bands' nominal)."""
    if isinstance(material, str):
        try:
            material = resolve_material(material)
        except KeyError as exc:
            raise MechanicsError(f"Input material {exc.args[0]}") from None
    if law != "yeoh":
        q = material.shear_modulus_kPa
        return (q.low, q.nominal, q.high)
    y = material.yeoh
    if y is None:
        raise MechanicsError(f"Input material {material.key!r} has no Yeoh law in recipes/materials.toml")
    spread = y.rms_pct / 100.0
    soft, stiff = y.mu_kPa * (1.0 - spread), y.mu_kPa * (1.0 + spread)
    q, m100 = material.shear_modulus_kPa, material.modulus_100_kPa
    if m100 is not None and abs(q.high / (m100.nominal / 1.75) - 1.0) <= DATASHEET_MATCH:
        stiff = max(stiff, m100.nominal / (1.75 * (1.0 + 4.0 * y.k2 + 12.0 * y.k3)))
    else:
        stiff = max(stiff, y.mu_kPa * q.high / q.low)
    return (soft, math.sqrt(soft * stiff), stiff)


#: How near the neo-Hookean band's stiff end must be to the datasheet's 100 % modulus (as mu = P / 1.75) for
#: :func:`band` to read it as the recipe's stiff end: relative (every sourced silicone but Ecoflex 00-10 is within
#: 0.4 %; 00-10's band ends at 8 kPa against the datasheet's 31.5).
DATASHEET_MATCH = 0.05

