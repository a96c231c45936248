"""The reference chip (:mod:`magfab.models.reference`) as findings."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..design import Design
from ..errors import Finding, Severity
from ..models.reference import Travel, site

__all__ = ["reference_findings"]


def reference_findings(design: Design, section: Mapping[str, Any] | None) -> list[Finding]:
    """The reference chip as findings: a warning when the magnets are heard at its place (it would subtract the
    taxels' own presses), info with what it rejects otherwise."""
    if section is None:
        return []
    chip, where, rej = section["chip"], section["site"], section["rejection"]
    motion, noise_G = where["motion_G"], where["noise_G"]
    if not section["quiet"]:
        quiet = site(design, Travel.bound(design), 0.0)
        return [Finding(Severity.WARNING, "reference-loud",
                        f"the magnets move the field at the reference chip {chip['designator']} "
                        f"({chip['distance_mm']:g} mm beyond the taxels) by up to {motion[0]:.2f} G (x/y) and "
                        f"{motion[1]:.2f} G (z), above the chip's {noise_G[0]:.2f} / {noise_G[1]:.2f} G noise: its "
                        "subtraction would take part of each press with it; at least "
                        f"{quiet.xy_mm[1] - max(t.y_mm for t in design.taxels):g} mm (or omit distance_mm)",
                        "reference.distance_mm")]
    turned = section["rotation"]
    near = [d for d in rej["dipole"] if d["median"] < 1.0]
    return [Finding(Severity.INFO, "reference",
                    f"reference chip {chip['designator']} (0x{chip['i2c_address']:02X}) {chip['separation_mm']:g} mm "
                    f"from the sensing chip, where the magnets move the field by at most {max(motion):.2f} G: a "
                    f"uniform field is rejected {rej['uniform']:.0f}x (turning the sensor: "
                    f"{abs(turned['without']['normal_rest_mN']):.1f} -> {abs(turned['with']['normal_rest_mN']):.1f} mN "
                    f"at rest); a dipole {rej['dipole'][-1]['distance_mm']:g} mm away "
                    f"{rej['dipole'][-1]['median']:.1f}x"
                    + (f", one {near[-1]['distance_mm']:g} mm away not at all (its field differs at the two chips)"
                       if near else ""), "reference")]
