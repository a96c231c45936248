"""The bench's silicone (:mod:`magfab.models.silicone`) as findings: what to weigh, and a warning when the work of a
pour nears the silicone's pot life."""

from __future__ import annotations

from ..design import Design
from ..errors import Finding, Severity
from ..models.silicone import quantities

__all__ = ["fabrication_findings"]


def fabrication_findings(design: Design) -> list[Finding]:
    q = quantities(design)
    out = [Finding(Severity.INFO, "silicone",
                   f"weigh {q.part_a_g:.1f} g part A and {q.part_b_g:.1f} g part B of {q.material} per pour "
                   f"({q.pours} pour(s), {q.total_g:.1f} g in all): the mould holds {q.mould_holds_mL:.2f} mL, plus "
                   f"{q.waste_pct:g} % waste", "fabrication.waste_pct")]
    if q.bench_time_min > 0.8 * q.pot_life_min:
        out.append(Finding(Severity.WARNING, "pot-life",
                           f"weighing, mixing, degassing and pouring {q.cavities} cavities takes about "
                           f"{q.bench_time_min:g} min, more than 80 % of the {q.pot_life_min:g} min pot life: pour "
                           "fewer cavities per batch or choose a slower silicone", "mould.cavities"))
    return out
