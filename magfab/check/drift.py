"""The drift budget (:mod:`magfab.models.drift`) as findings: a warning where an error under the stated conditions
exceeds the resolution, info otherwise."""

from __future__ import annotations

from ..design import Design
from ..errors import Finding, Severity
from ..models.drift import Drift

__all__ = ["drift_findings"]


def _severity(error_mN: float, resolution_mN: float) -> Severity:
    return Severity.WARNING if abs(error_mN) > resolution_mN else Severity.INFO


def drift_findings(design: Design, d: Drift) -> list[Finding]:
    """The drift budget as findings: a warning where an error under the stated conditions exceeds the resolution,
    info otherwise."""
    res_n, res_s = d.resolution_mN["normal"], d.resolution_mN["shear"]
    t = d.temperature
    compensated = bool(design.spec.firmware.temperature)
    case = "with" if compensated else "without"
    worst_n = max(t.worst["normal_rest"][case], t.worst["normal_end"][case])
    env = d.conditions
    span = f"{env['temperature_min_C']:g}-{env['temperature_max_C']:g} C"
    out = [Finding(
        _severity(worst_n, res_n), "drift-temperature",
        f"temperature: {abs(t.per_C['normal_rest']['without']):.1f} mN/C at rest and "
        f"{abs(t.per_C['normal_end']['without']):.1f} mN/C at the end of the normal range uncompensated; over "
        f"{span} (calibrated at {t.calibration_C:g} C) up to "
        f"{max(t.worst['normal_rest']['without'], t.worst['normal_end']['without']):.0f} mN without and "
        f"{max(t.worst['normal_rest']['with'], t.worst['normal_end']['with']):.1f} mN with the chip-temperature "
        f"compensation{'' if compensated else ' (off: firmware.temperature is false)'}, against a {res_n:.1f} mN "
        "resolution", "environment.temperature_max_C")]
    r = d.rotation
    out.append(Finding(_severity(max(abs(r.normal_rest_mN), abs(r.normal_end_mN)), res_n), "drift-rotation",
                       f"{r.what}: {r.field_G:.2f} G on an axis, {abs(r.normal_rest_mN):.1f} mN normal at rest, "
                       f"{abs(r.normal_end_mN):.1f} mN at the end of the range, {abs(r.shear_mN):.1f} mN shear, "
                       f"against {res_n:.1f} / {res_s:.1f} mN resolution (normal / shear)", "environment.rotation_deg"))
    if d.stray is not None:
        s = d.stray
        out.append(Finding(_severity(max(abs(s.normal_rest_mN), abs(s.normal_end_mN)), res_n), "drift-stray",
                           f"{s.what}: {s.field_G:.3g} G on an axis, {abs(s.normal_rest_mN):.1f} mN normal at rest, "
                           f"{abs(s.shear_mN):.1f} mN shear, against {res_n:.1f} / {res_s:.1f} mN resolution",
                           "environment.stray_distance_mm"))
    return out
