"""How much silicone a pour takes: per pour and in all (the mould's cavities, the lid's holes, the waste allowance),
and the bench time against the pot life. The checklist and the bill of materials both read it."""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

from ..errors import SpecError
from ..recipes import Recipe

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["Quantities", "quantities", "mix_ratio", "silicone_recipe", "MIN_BATCH_G", "MIX_MIN", "DEGAS_MIN",
           "POUR_MIN_PER_CAVITY"]

#: Minutes at the bench per pour, before the silicone is in the mould: weigh and mix (3), degas (5), pour
#: and close the lid (2 per cavity). Our estimate of a careful first-timer; checked against the pot life.
MIX_MIN, DEGAS_MIN, POUR_MIN_PER_CAVITY = 3.0, 5.0, 2.0
#: Lowest total mass weighed per batch: a 0.1 g kitchen scale then errs by at most 1 % per part.
MIN_BATCH_G = 10.0


def mix_ratio(text: str, where: str) -> tuple[float, float]:
    """(A, B) parts by weight from a recipe's ratio text: "1A:1B", "10:1 (base : curing agent)", "100A:42B"."""
    m = re.match(r"\s*(\d+(?:\.\d+)?)\s*A?\s*:\s*(\d+(?:\.\d+)?)", text)
    if not m:
        raise SpecError(where, text, "must start with a ratio like 1A:1B or 10:1")
    return float(m.group(1)), float(m.group(2))


@dataclass(frozen=True)
class Quantities:
    """Silicone per pour and in all, g; times, min."""

    material: str
    sensors: int
    cavities: int
    pours: int
    part_volume_mL: float  # one cast part (the cavity minus the pocket core)
    holes_volume_mL: float  # the lid's fill and vent holes, filled to the top, per pour
    mould_holds_mL: float  # per pour
    density_g_cm3: float
    waste_pct: float
    batch_g: float  # mixed per pour
    part_a_g: float
    part_b_g: float
    ratio: tuple[float, float]
    total_g: float  # over all pours
    pot_life_min: float
    bench_time_min: float  # weigh, mix, degas and pour one batch
    cure_time_h: float
    cure_temperature_C: float | None

    def as_dict(self) -> dict[str, object]:
        return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in asdict(self).items()}


def silicone_recipe(design: Design) -> Recipe:
    """The spec's silicone in recipes/materials.toml."""
    return design.material.recipe


def _override(value: float | None, recipe: Recipe, key: str, spec_key: str) -> float:
    if value is not None:
        return float(value)
    if key not in recipe.quantities:
        raise SpecError(spec_key, "(recipe)", f"is needed: recipes/materials.toml gives no {key} for "
                        f"{recipe.key!r}, so set it in the spec")
    return recipe[key].nominal


def quantities(design: Design) -> Quantities:
    """How much silicone to weigh per pour and in all (cavities, the lid's holes, the waste allowance)."""
    spec = design.spec
    fab = spec.fabrication
    rec = silicone_recipe(design)
    density = _override(fab.density_g_cm3, rec, "density_g_cm3", "fabrication.density_g_cm3")
    pot = _override(fab.pot_life_min, rec, "pot_life_min", "fabrication.pot_life_min")
    cure = _override(fab.cure_time_h, rec, "cure_time_h", "fabrication.cure_time_h")
    ratio = mix_ratio(rec.texts.get("mix_ratio_by_weight", ""), f"recipes/materials.toml:{rec.key}.mix_ratio_by_weight")
    cavities = design.cavities
    holes = [d for x, y, d in design.lid_holes[len(design.pin_positions_x_mm):]]  # sprues and vents
    holes_mm3 = sum(math.pi * d * d / 4 * design.lid_thickness_mm for d in holes)
    part_mm3 = design.elastomer_volume_mm3
    holds_mm3 = cavities * part_mm3 + holes_mm3
    batch = max(holds_mm3 / 1000.0 * density * (1 + fab.waste_pct / 100.0), MIN_BATCH_G)
    a, b = ratio
    pours = math.ceil(fab.sensors * design.parts_per_sensor / cavities)
    temp = rec["cure_temperature_C"].nominal if "cure_temperature_C" in rec.quantities else None
    return Quantities(
        material=rec.name, sensors=fab.sensors, cavities=cavities, pours=pours, part_volume_mL=part_mm3 / 1000.0,
        holes_volume_mL=holes_mm3 / 1000.0, mould_holds_mL=holds_mm3 / 1000.0, density_g_cm3=density,
        waste_pct=fab.waste_pct, batch_g=batch, part_a_g=batch * a / (a + b), part_b_g=batch * b / (a + b),
        ratio=ratio, total_g=batch * pours, pot_life_min=pot,
        bench_time_min=MIX_MIN + DEGAS_MIN + POUR_MIN_PER_CAVITY * cavities, cure_time_h=cure, cure_temperature_C=temp,
    )
