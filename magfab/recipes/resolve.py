"""The one place a spec's catalogue keys (magnet grade, elastomer material, chip, printer, adhesive and release
agent) become recipe values.

:func:`magfab.design.derive` calls these once; the models then read typed fields (``design.magnet_grade.remanence_T``,
``design.material.density_g_cm3``) and never look a key up again, so a grade or material is resolved in one place and
a misspelt field is an AttributeError at the line that reads it rather than a KeyError deep in a model.

Each number stays a :class:`~magfab.recipes.Quantity` (nominal, band, source) exactly as the catalogue gives it.
The values are frozen and picklable (a Design travels to forked and Dask workers).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from . import Quantity, Recipe, RecipeError, catalogue

__all__ = ["MagnetGrade", "Material", "YeohLaw", "yeoh_fitted", "magnet_grade", "material", "chip", "board", "printer",
           "adhesive"]


@dataclass(frozen=True)
class MagnetGrade:
    """A sintered NdFeB grade (recipes/magnets.toml), with the stock part's coating and rating from
    recipes/assembly.toml (``magnet-<grade>``) where that file has them."""

    key: str  # the spec's magnet.grade, e.g. "N42"
    name: str
    remanence_T: Quantity  # Br band: min / nominal / max of the grade table
    density_g_cm3: Quantity
    br_temperature_coefficient_pct_per_C: Quantity  # alpha(Br), %/C: the value the firmware divides by
    br_temperature_coefficient_spread_pct_per_C: Quantity  # where an unmeasured magnet's alpha(Br) may lie
    edge_radius_mm: Quantity  # the disc's edge break (the mechanics FE rounds the magnet with it)
    coating: str = ""  # recipes/assembly.toml; "" when it has no entry for the grade
    max_operating_temp_C: Quantity | None = None  # recipes/assembly.toml; None when it has no entry


@dataclass(frozen=True)
class YeohLaw:
    """A silicone's Yeoh law (recipes/materials.toml's yeoh_* rows): mu = 2 C10 in kPa, k2 = C20/C10, k3 = C30/C10,
    fitted over stretches 1 to ``stretch_max`` with RMS relative error ``rms_pct``."""

    mu_kPa: float
    k2: float
    k3: float
    stretch_max: float
    rms_pct: float


@dataclass(frozen=True)
class Material:
    """A casting silicone (recipes/materials.toml): the numbers the models and the silicone quantities read, and the
    whole entry (``recipe``) for the checklist's prose (degassing, inhibition, cure schedule and their sources)."""

    key: str  # the spec's elastomer.material, e.g. "ecoflex-00-30"
    name: str
    shear_modulus_kPa: Quantity  # neo-Hookean mu band: soft / nominal / stiff
    density_g_cm3: Quantity
    pot_life_min: Quantity
    cure_time_h: Quantity
    cure_temperature_C: Quantity
    mix_ratio_by_weight: str  # "1A:1B", "10A:1B"
    recipe: Recipe
    yeoh: YeohLaw | None = None  # the large-strain law; None where the recipes hold no fit (predict.material_law)
    modulus_100_kPa: Quantity | None = None  # the datasheet's stress at 100 % strain, where it reports one


def _q(recipe: Recipe, kind: str, name: str) -> Quantity:
    if name not in recipe.quantities:
        raise RecipeError(f"recipes/{kind}.toml [{recipe.key}] needs {name}")
    return recipe[name]


def _entry(kind: str, key: str) -> Recipe:
    """One entry by key; the spec has already checked the key exists (spec._known), so a miss is a bug."""
    entries = catalogue(kind)
    if key not in entries:
        raise KeyError(f"must be one of {', '.join(sorted(entries))} (recipes/{kind}.toml); instead received {key!r}")
    return entries[key]


@cache  # frozen values of a cached catalogue: derive (once per design of a search) pays nothing
def magnet_grade(key: str) -> MagnetGrade:
    """The grade ``key`` of recipes/magnets.toml as a :class:`MagnetGrade`."""
    r = _entry("magnets", key)
    part = catalogue("assembly").get(f"magnet-{key.lower()}")
    return MagnetGrade(
        key=r.key, name=r.name, remanence_T=_q(r, "magnets", "remanence_T"),
        density_g_cm3=_q(r, "magnets", "density_g_cm3"),
        br_temperature_coefficient_pct_per_C=_q(r, "magnets", "br_temperature_coefficient_pct_per_C"),
        br_temperature_coefficient_spread_pct_per_C=_q(r, "magnets", "br_temperature_coefficient_spread_pct_per_C"),
        edge_radius_mm=_q(r, "magnets", "edge_radius_mm"),
        coating=part.texts.get("coating", "") if part is not None else "",
        max_operating_temp_C=part.quantities.get("max_operating_temp_C") if part is not None else None,
    )


@cache
def material(key: str) -> Material:
    """The silicone ``key`` of recipes/materials.toml as a :class:`Material`."""
    r = _entry("materials", key)
    if "mix_ratio_by_weight" not in r.texts:
        raise RecipeError(f"recipes/materials.toml [{key}] needs mix_ratio_by_weight")
    return Material(
        key=r.key, name=r.name, shear_modulus_kPa=_q(r, "materials", "shear_modulus_kPa"),
        density_g_cm3=_q(r, "materials", "density_g_cm3"), pot_life_min=_q(r, "materials", "pot_life_min"),
        cure_time_h=_q(r, "materials", "cure_time_h"), cure_temperature_C=_q(r, "materials", "cure_temperature_C"),
        mix_ratio_by_weight=r.texts["mix_ratio_by_weight"], recipe=r, yeoh=_yeoh(r),
        modulus_100_kPa=r.quantities.get("modulus_100_kPa"),
    )


@cache
def yeoh_fitted() -> tuple[str, ...]:
    """The silicones the recipes fit a Yeoh law for (predict.material_law = "yeoh"), sorted."""
    return tuple(sorted(k for k, r in catalogue("materials").items() if "yeoh_mu_kPa" in r.quantities))


_YEOH = ("yeoh_mu_kPa", "yeoh_k2", "yeoh_k3", "yeoh_stretch_max", "yeoh_fit_rms_pct")


def _yeoh(r: Recipe) -> YeohLaw | None:
    """The entry's Yeoh law: all of its rows, or none of them."""
    present = [k for k in _YEOH if k in r.quantities]
    if not present:
        return None
    if len(present) != len(_YEOH):
        raise RecipeError(f"recipes/materials.toml [{r.key}] has {', '.join(present)} but needs all of "
                          f"{', '.join(_YEOH)}")
    return YeohLaw(*(r[k].nominal for k in _YEOH))


@cache
def chip(key: str) -> Recipe:
    """The chip ``key`` of recipes/chips.toml. Left a :class:`Recipe`: its readers (footprint, firmware, noise) take
    families of keys by pattern (``sensitivity_z_gain<n>``, ``i2c_base_address_<code>``, ``pin_<n>``)."""
    return _entry("chips", key)


@cache
def board(key: str) -> Recipe:
    """The readout board ``key`` of recipes/boards.toml (its microcontroller, pins, flash, connector)."""
    return _entry("boards", key)


@cache
def printer(key: str) -> Recipe:
    """The printer ``key`` of recipes/printers.toml."""
    return _entry("printers", key)


@cache
def adhesive(key: str) -> Recipe:
    """The adhesive or release agent ``key`` of recipes/adhesives.toml (read as prose and cure times by the bench
    papers, so left a :class:`Recipe`)."""
    return _entry("adhesives", key)
