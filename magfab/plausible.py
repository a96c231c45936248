"""Inputs no physical sensor has: a size, a distance or a modulus a unit's factor away from every sourced part is
refused, naming the key the user typed, before a derived key can break on it; and a material law the recipes hold
no data for.

Each guarded key is compared with the span the recipes source for it: the stock magnets' diameters and heights
(recipes/magnet_stock.toml), the magnet's distances from the sensing point (``sensor.d_max_mm``, ``d_min_mm``: from
the chips' least sensing depth, recipes/chips.toml, to twice the largest stock diameter, the far end of docs/models.md
M18's 1-2 diameters) and the silicones' shear modulus bands (recipes/materials.toml, for a spec's own
``elastomer.shear_modulus_kPa``). A value more than the key's factor outside that span is refused (:data:`FACTOR`
for a magnet's size or distance; :data:`MODULUS_FACTOR` for a modulus, whose sourced span is already 140 times wide,
so that any band inside it typed :data:`UNIT` times off lands outside); when a factor of :data:`UNIT` (a unit
prefix: metres typed as millimetres, MPa or Pa as kPa) brings it inside the span, the refusal says so. Within the
factor, a value is the designer's (a custom magnet, an unusual batch) and the design's own checks judge it.

Without this, ``magnet.diameter_mm = 0.005`` (metres typed as millimetres) was refused as
``elastomer.insert_channel_diameter_mm = 2.0: must be at most the pocket diameter 0.105 mm``, a key the user did not
touch, and ``shear_modulus_kPa = [15000, 23000, 39000]`` (MPa read as kPa) was accepted and printed a range of 1,026 N.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache

from .errors import SpecError
from .errors import number_text as _fmt
from .recipes import catalogue
from .recipes.resolve import yeoh_fitted
from .spec import MaterialLawChoice, MechanicsModel, Spec
from .spec_options import CLOSED_FORMS

__all__ = ["FACTOR", "MODULUS_FACTOR", "UNIT", "plausible", "spans"]

#: How far outside the stock magnets' span a size may lie before it is refused (either way).
FACTOR = 10.0
#: The same for a shear modulus: 2.3-2,970 kPa passes, against 7-990 kPa sourced.
MODULUS_FACTOR = 3.0
#: The unit mistake a refusal suggests undoing: a factor of a thousand.
UNIT = 1000.0


@cache
def spans() -> dict[str, tuple[float, float, float, str, str]]:
    """Each guarded key's sourced span: (lowest, highest, the factor allowed past them, unit, what the span is)."""
    stock = catalogue("magnet_stock").values()
    moduli = [r["shear_modulus_kPa"] for r in catalogue("materials").values()]
    diameters = [r["diameter_mm"].nominal for r in stock]
    heights = [r["height_mm"].nominal for r in stock]
    # The magnet's distances: from the chip's sensing depth below its package top (no magnet comes nearer) to twice
    # the largest stock diameter (docs/models.md M18: d_max at 1-2 magnet diameters).
    depth = min(r["sensing_depth_mm"].low for r in catalogue("chips").values() if "sensing_depth_mm" in r.quantities)
    reach = (depth, 2.0 * max(diameters), FACTOR, "mm", "the distances a magnet can sit from the sensing point")
    return {
        "sensor.d_max_mm": reach, "sensor.d_min_mm": reach,
        "magnet.diameter_mm": (min(diameters), max(diameters), FACTOR, "mm", "the stock magnets' diameters"),
        "magnet.height_mm": (min(heights), max(heights), FACTOR, "mm", "the stock magnets' heights"),
        "elastomer.shear_modulus_kPa": (min(q.low for q in moduli), max(q.high for q in moduli), MODULUS_FACTOR,
                                        "kPa", "the sourced silicones' shear moduli"),
    }


def plausible(spec: Spec) -> None:
    """Refuse (:class:`SpecError`, naming the key) a guarded value more than its key's factor outside its sourced
    span (module doc)."""
    values: dict[str, Sequence[float]] = {"magnet.diameter_mm": (spec.magnet.diameter_mm,),
                                          "magnet.height_mm": (spec.magnet.height_mm,),
                                          "sensor.d_max_mm": (spec.sensor.d_max_mm,),
                                          "sensor.d_min_mm": (spec.sensor.d_min_mm,)}
    if spec.elastomer.shear_modulus_kPa is not None:
        values["elastomer.shear_modulus_kPa"] = spec.elastomer.shear_modulus_kPa
    for key, xs in values.items():
        lo, hi, factor, unit, what = spans()[key]
        if all(lo / factor <= x <= hi * factor for x in xs):
            continue
        shown = xs[0] if len(xs) == 1 else list(xs)
        hint = ""
        for f in (1.0 / UNIT, UNIT):
            if all(lo <= x * f <= hi for x in xs):
                meant = ", ".join(_fmt(x * f) for x in xs)
                hint = f"did you mean {meant if len(xs) == 1 else '[' + meant + ']'} {unit}? a factor of " \
                       f"{_fmt(UNIT)} off"
        raise SpecError(key, shown, f"more than {_fmt(factor)} times outside {what} ({_fmt(lo)}-{_fmt(hi)} {unit})",
                        hint)
    _law_has_data(spec)


def _law_has_data(spec: Spec) -> None:
    """Refuse the Yeoh law for a silicone the recipes hold no Yeoh fit for (there is nothing to fit it from), or with
    a closed-form mechanics model (they are neo-Hookean)."""
    if spec.predict.material_law != MaterialLawChoice.YEOH:
        return
    model = MechanicsModel(spec.predict.mechanics_model)
    if model in CLOSED_FORMS:
        raise SpecError("predict.material_law", "yeoh", f"needs the FE: predict.mechanics_model = "
                        f"'{model.value}' is a neo-Hookean closed form; use 'auto' or 'fe'")
    fitted = yeoh_fitted()
    if spec.elastomer.material not in fitted:
        raise SpecError("predict.material_law", "yeoh", f"recipes/materials.toml holds no Yeoh fit for "
                        f"{spec.elastomer.material} (fitted: {', '.join(fitted)}); use 'neo-hookean'")
