"""Catalogue data (materials, magnet grades, stock magnet discs, printers, chips, parts, adhesives, assembly, the bench
kit), read from the TOML files beside this module.

Every number in a recipe is a table with its ``source``: either ``{value = x, source = "..."}`` or
``{min = a, nominal = b, max = c, source = "..."}``. Numbers are parsed by TOML, never evaluated.

The entries a spec names (magnet grade, material, chip, printer, adhesives) are taken by key in one place,
:mod:`magfab.recipes.resolve`, when the design is derived; everything downstream reads the Design's values.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from importlib import resources
from types import MappingProxyType
from typing import TypeGuard

__all__ = ["Quantity", "Recipe", "catalogue", "KINDS"]

KINDS = ("materials", "magnets", "magnet_stock", "printers", "chips", "land", "parts", "adhesives", "assembly", "bench",
         "boards")


@dataclass(frozen=True)
class Quantity:
    """A sourced number: ``nominal`` with its band [``low``, ``high``] (equal when the source gives one value)."""

    nominal: float
    low: float
    high: float
    source: str


@dataclass(frozen=True)
class Recipe:
    """One catalogue entry: sourced quantities and plain text fields (name, notes)."""

    key: str
    quantities: Mapping[str, Quantity]
    texts: Mapping[str, str]

    def __getitem__(self, name: str) -> Quantity:
        return self.quantities[name]

    @property
    def name(self) -> str:
        return self.texts.get("name", self.key)

    def __reduce__(self):
        # a mappingproxy does not pickle; a Design holding recipes goes to forked and Dask workers
        return _recipe, (self.key, dict(self.quantities), dict(self.texts))


def _recipe(key: str, quantities: dict[str, Quantity], texts: dict[str, str]) -> Recipe:
    return Recipe(key, MappingProxyType(quantities), MappingProxyType(texts))


class RecipeError(ValueError):
    """A malformed catalogue file: a bug in the package data, never user input."""


def _number(x: object) -> TypeGuard[int | float]:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _quantity(where: str, table: Mapping[str, object]) -> Quantity:
    source = table.get("source")
    if not isinstance(source, str) or not source.strip():
        raise RecipeError(f"{where}: every number needs a non-empty 'source'")
    if "value" in table:
        value = table["value"]
        if not _number(value) or set(table) != {"value", "source"}:
            raise RecipeError(f"{where}: expected {{value, source}} with a numeric value")
        v = float(value)
        return Quantity(v, v, v, source)
    try:
        low, nominal, high = (float(table[k]) for k in ("min", "nominal", "max"))  # type: ignore[arg-type]
    except (KeyError, TypeError, ValueError) as exc:
        raise RecipeError(f"{where}: expected {{value, source}} or {{min, nominal, max, source}}") from exc
    if not low <= nominal <= high:
        raise RecipeError(f"{where}: need min <= nominal <= max, got {low}, {nominal}, {high}")
    return Quantity(nominal, low, high, source)


def _entry(kind: str, key: str, table: Mapping[str, object]) -> Recipe:
    quantities: dict[str, Quantity] = {}
    texts: dict[str, str] = {}
    for name, item in table.items():
        where = f"recipes/{kind}.toml [{key}] {name}"
        if isinstance(item, dict):
            quantities[name] = _quantity(where, item)
        elif isinstance(item, str):
            texts[name] = item
        else:
            raise RecipeError(f"{where}: a bare number or other value has no source; use {{value, source}}")
    return Recipe(key, MappingProxyType(quantities), MappingProxyType(texts))


@cache
def catalogue(kind: str) -> Mapping[str, Recipe]:
    """All entries of one catalogue (one of :data:`KINDS`), by key."""
    if kind not in KINDS:
        raise KeyError(f"unknown recipe kind {kind!r}; known: {', '.join(KINDS)}")
    raw = tomllib.loads(resources.files(__name__).joinpath(f"{kind}.toml").read_text(encoding="utf-8"))
    return MappingProxyType({key: _entry(kind, key, table) for key, table in raw.items()})
