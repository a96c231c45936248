"""Shear figures of the prediction: shear as the bench applies it, through the contact patch under the scan's
normal preload (:mod:`magfab.models.mechanics.shear_surface`), read by the chip as the lateral field of a magnet
that shifts and tilts (:mod:`magfab.models.field.tilt`).

    S_s(delta) = [dBx/dshift * shift + dBx/dtilt * tilt] per newton of lateral force, at the gap d_rest - drop(delta)

The magnet's shift and tilt per newton come from the mode-1 FE linearised about the normal curve's own converged
states (one solve per probed preload, on the chosen mesh; at delta = 0 the indenter holds the patch within the
Hertz radius of the scan step). Sensitivity and resolution span the material and grade bands and the preloads
inside the predicted normal range; the shear range is the lateral travel of the magnet at rest (its radius, or
where the strongest magnet's lateral field reaches the chip's xy full scale) times the magnet's lateral stiffness
at rest. Linear in 1/mu: one solve serves the material band.

Units: G, N, mm, rad.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..units import MN_PER_N
from . import field as fieldmod
from . import mechanics as mech

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["ShearFigures", "shear_figures", "shear_probe_depths"]

#: What the shear figures model, in one sentence for the report's models table.
SHEAR_DESCRIPTION = ("Mode-1 (Fourier) FE linearised about the preloaded large-strain state, lateral load through "
                     "the indenter's stuck contact patch, the magnet shifting and tilting; field of the shifted, "
                     "tilted magnet at the chip (the tilt cancels part of the shift's field at rest)")


@dataclass(frozen=True)
class ShearFigures:
    """Shear (lateral) load over the material band; forces N, stiffness N/mm, sensitivity G/N, tilt rad/N.

    ``stiffness_N_per_mm``: lateral force per lateral shift of the magnet, at rest; ``preload_indentation_mm``: the
    normal preloads probed along the scan (within the normal range); the ``*_along_scan`` maps give, per material,
    one value per preload (sensitivity for the nominal grade)."""

    stiffness_N_per_mm: Mapping[str, float]
    sensitivity_G_per_N: tuple[float, float]  # over the materials, grades and preloads within the normal range
    resolution_mN: float
    range_N: float
    range_by_material_N: Mapping[str, float]
    range_limit: str
    sensitivity_at_rest_G_per_N: Mapping[str, float]  # per material, nominal magnet grade
    tilt_at_rest_rad_per_N: Mapping[str, float]
    preload_indentation_mm: tuple[float, ...]
    preload_force_N: Mapping[str, tuple[float, ...]]
    stiffness_along_scan_N_per_mm: Mapping[str, tuple[float, ...]]
    indenter_stiffness_along_scan_N_per_mm: Mapping[str, tuple[float, ...]]
    sensitivity_along_scan_G_per_N: Mapping[str, tuple[float, ...]]

    def as_json(self) -> dict[str, object]:
        return {
            "stiffness_N_per_mm": dict(self.stiffness_N_per_mm), "sensitivity_G_per_N": list(self.sensitivity_G_per_N),
            "resolution_mN": self.resolution_mN, "range_N": self.range_N,
            "range_by_material_N": dict(self.range_by_material_N), "range_limit": self.range_limit,
            "sensitivity_at_rest_G_per_N": dict(self.sensitivity_at_rest_G_per_N),
            "tilt_at_rest_rad_per_N": dict(self.tilt_at_rest_rad_per_N),
            "along_scan": {
                "indentation_mm": list(self.preload_indentation_mm),
                "normal_force_N": {k: list(v) for k, v in self.preload_force_N.items()},
                "magnet_stiffness_N_per_mm": {k: list(v) for k, v in self.stiffness_along_scan_N_per_mm.items()},
                "indenter_stiffness_N_per_mm": {k: list(v) for k, v in
                                                self.indenter_stiffness_along_scan_N_per_mm.items()},
                "sensitivity_G_per_N": {k: list(v) for k, v in self.sensitivity_along_scan_G_per_N.items()},
            },
        }


def shear_probe_depths(design: Design, indentation: np.ndarray) -> np.ndarray:
    """The preloads (mm) the shear response is solved at: every third point of the normal curve's indentation
    grid up to the scan depth, and the scan depth (about 0.5 mm apart on MagOne: 7 mode-1 solves)."""
    depth = float(design.spec.calibration.scan_z_mm)
    d = np.asarray(indentation, dtype=float)
    return np.unique(np.append(d[d <= depth + 1e-9][::3], min(depth, float(d[-1]))))


def rest_response(design: Design, body: mech.Body, mu_kPa: float) -> mech.ShearResponse:
    """The shear response at rest only, on the FE's default mesh: for a normal curve from a closed form (no FE load
    path to probe; the shear is solved by the FE whatever the normal model)."""
    return mech.shear_response(body, mu_kPa, (0.0,), rest_indentation_mm=design.spec.calibration.scan_step_mm)


def shear_figures(design: Design, nz: Mapping[str, float], magnets: Mapping[str, fieldmod.Magnet],
                  full_scale_xy_G: float, fmodel: str, mus: Mapping[str, float], response: mech.ShearResponse,
                  depth_end_mm: float) -> tuple[ShearFigures, dict[str, np.ndarray]]:
    """The shear figures (module doc) from ``response`` (at the nominal modulus ``mus["nominal"]``); preloads deeper
    than ``depth_end_mm`` (where the normal range ends) are reported but left out of the sensitivity span."""
    band = {k: response.scaled(mu) for k, mu in mus.items()}
    gap = design.d_rest_mm - response.magnet_drop_mm
    s = {(k, b): np.asarray(fieldmod.lateral_field(m, gap, r.displacement_mm_per_N, r.tilt_rad_per_N))
         for k, r in band.items() for b, m in magnets.items()}
    inside = response.indentation_mm <= depth_end_mm + 1e-9
    inside[0] = True
    span = np.array([v[inside] for v in s.values()])
    res_mN = MN_PER_N * nz["total_xy_G"] / np.maximum(np.abs(span), 1e-300)
    ks = {k: float(r.magnet_stiffness_N_per_mm[0]) for k, r in band.items()}
    # The shear range: lateral travel of the magnet at rest up to its radius or the chip's xy full scale.
    r = np.linspace(0.0, design.magnet_radius_mm, 21)
    br = {b: np.asarray(fieldmod.bz_br(magnets[b], design.d_rest_mm, r, model=fmodel, rtol=None)[1])
          for b in ("nominal", "high")}
    br_high = br["high"]
    limits = {"lateral travel = magnet radius": design.magnet_radius_mm}
    over = np.nonzero(br_high > full_scale_xy_G)[0]
    if over.size:
        limits["chip full scale"] = _crossing(r, br_high, full_scale_xy_G, int(over[0]))
    binding = min(limits, key=lambda k: limits[k])
    shear_range = {k: float(v * limits[binding]) for k, v in ks.items()}

    def per_material(values: Mapping[str, np.ndarray]) -> dict[str, tuple[float, ...]]:
        return {k: tuple(float(x) for x in v) for k, v in values.items()}

    figures = ShearFigures(
        stiffness_N_per_mm=ks,
        sensitivity_G_per_N=(float(np.abs(span).min()), float(np.abs(span).max())),
        resolution_mN=float(res_mN.max()),
        range_N=min(shear_range.values()),
        range_by_material_N=shear_range,
        range_limit=binding,
        sensitivity_at_rest_G_per_N={k: float(s[(k, "nominal")][0]) for k in band},
        tilt_at_rest_rad_per_N={k: float(v.tilt_rad_per_N[0]) for k, v in band.items()},
        preload_indentation_mm=tuple(float(x) for x in response.indentation_mm),
        preload_force_N=per_material({k: v.normal_force_N for k, v in band.items()}),
        stiffness_along_scan_N_per_mm=per_material({k: v.magnet_stiffness_N_per_mm for k, v in band.items()}),
        indenter_stiffness_along_scan_N_per_mm=per_material({k: v.stiffness_N_per_mm for k, v in band.items()}),
        sensitivity_along_scan_G_per_N=per_material({k: s[(k, "nominal")] for k in band}),
    )
    arrays = {"u_shear": np.asarray(response.magnet_drop_mm), "r": r, "br_high": br_high,
              "dbr_nominal": np.gradient(br["nominal"], r, edge_order=2),
              **{f"sfs_{k}_{b}": v for (k, b), v in s.items()}}
    return figures, arrays


def _crossing(x: np.ndarray, y: np.ndarray, level: float, k: int) -> float:
    """Where y first reaches ``level`` (y[k] is the first sample beyond it), by linear interpolation."""
    if k == 0:
        return float(x[0])
    x0, x1, y0, y1 = x[k - 1], x[k], y[k - 1], y[k]
    return float(x0 + (level - y0) * (x1 - x0) / (y1 - y0))
