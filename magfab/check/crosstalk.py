"""An array's crosstalk budget (:mod:`magfab.models.crosstalk`) as findings."""

from __future__ import annotations

import numpy as np

from ..design import Design
from ..errors import Finding, Severity
from ..models.crosstalk import Crosstalk

__all__ = ["crosstalk_findings"]

#: Warn when the neighbours' magnets shift a magnet sideways at rest by more than this fraction of its shear travel:
#: the tip then rests off centre and one side of its shear range is short by that fraction (the shift is linear in
#: the softest shear stiffness, so past a few tenths it is only an order of magnitude).
SHIFT_WARN = 0.1


def crosstalk_findings(design: Design, xt: Crosstalk) -> list[Finding]:
    """Warnings when the budget is over the tolerance at this pitch (naming the least pitches) or the neighbours push
    a chip past its full scale; the figures as info."""
    out: list[Finding] = []

    def least(d: dict[str, float | None]) -> str:
        return ", ".join(f"{k} polarity {_pitch_words(v, xt.sweep_mm)}" for k, v in d.items())

    worst = float(xt.worst_mN.max())
    tol = f"{xt.tolerance_mN:.2f} mN"
    if worst > xt.tolerance_mN:
        out.append(Finding(Severity.WARNING, "array-crosstalk",
                           f"a neighbour moving through its range makes a taxel misread up to {worst:.1f} mN (after "
                           f"the host's compensation), more than the {tol} tolerance at {xt.pitch_mm:g} mm pitch; the "
                           f"least pitch within it: {least(xt.min_pitch_compensated_mm)} (without the dynamic "
                           f"compensation: {least(xt.min_pitch_mm)}); or raise array.crosstalk_mN", "array.pitch_mm"))
    if xt.saturation_G > xt.full_scale_G:
        out.append(Finding(Severity.WARNING, "array-saturation",
                           f"with its neighbours' field a chip reads {xt.saturation_G:.0f} G when its magnet is at "
                           f"d_min, past the {xt.full_scale_G:.0f} G full scale", "sensor.d_min_mm"))
    if xt.saturation_xy_G > xt.full_scale_xy_G:
        out.append(Finding(Severity.WARNING, "array-saturation",
                           f"with its neighbours' field a chip reads up to {xt.saturation_xy_G:.0f} G across when its "
                           f"magnet slides through its shear travel, past the {xt.full_scale_xy_G:.0f} G full scale of "
                           f"its x and y axes", "array.pitch_mm"))
    shifts = np.hypot(*xt.predisplacement_mm.T)
    shift, k = float(shifts.max()), int(np.argmax(shifts))
    if shift > SHIFT_WARN * xt.shear_travel_mm:
        out.append(Finding(Severity.WARNING, "array-magnet-force",
                           f"the other magnets {'pull' if xt.force_exact_mN < 0 else 'push'} taxel {k}'s magnet "
                           f"sideways with {np.hypot(*xt.magnet_forces_mN[k]):.0f} mN at rest, about {shift:.2f} mm "
                           f"through the softest shear stiffness ({100 * shift / xt.shear_travel_mm:.0f} % of its "
                           f"{xt.shear_travel_mm:.1f} mm shear travel): the tip rests off centre and its shear range "
                           f"is that much shorter on one side; widen the pitch", "array.pitch_mm"))
    mech = f"; through the skin up to {xt.mechanical_mN.max():.1f} mN" if xt.coupling_curve is not None else ""
    out.append(Finding(Severity.INFO, "array-crosstalk-budget",
                       f"crosstalk: a moving neighbour reads as up to {xt.field_mN.max():.1f} mN, "
                       f"{xt.residual_mN.max():.2f} mN after compensation; every neighbour pressed "
                       f"{xt.common_mN.max():.1f} mN ({xt.common_residual_mN.max():.2f} compensated){mech}; the "
                       f"nearest magnets {'repel' if xt.force_exact_mN > 0 else 'attract'} with "
                       f"{abs(xt.force_exact_mN):.1f} mN at rest (dipoles {abs(xt.force_mN):.1f}), which shifts a "
                       f"magnet sideways by up to {shift * 1000:.0f} um ({100 * shift / xt.shear_travel_mm:.1f} % of "
                       f"its shear travel, a static shift); the least pitch within the {tol} tolerance with the host's "
                       f"compensation: {least(xt.min_pitch_compensated_mm)} (without it: {least(xt.min_pitch_mm)})"))
    return out


def _pitch_words(value: float | None, sweep: np.ndarray) -> str:
    """A least pitch for a sentence: past the sweep, at the sweep's start (the parts' own minimum: the budget is met
    wherever the parts fit, so the parts set it, not the crosstalk), or its value."""
    if value is None:
        return f"more than {sweep[-1]:.0f} mm"
    if value <= sweep[0] + 1e-9:
        return f"{value:.1f} mm (the parts' minimum: within tolerance wherever they fit)"
    return f"{value:.1f} mm"
