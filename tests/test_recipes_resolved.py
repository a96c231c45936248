"""The spec's catalogue keys are resolved once, in magfab/recipes/resolve.py, into typed values the Design carries;
no other module looks a grade, material, chip or printer up by key, and the typed values are the catalogue's own."""

from __future__ import annotations

import ast
import pickle
from dataclasses import fields
from pathlib import Path

import pytest

from magfab import derive, load_spec, parse_spec
from magfab.models import field as F
from magfab.models import mechanics as mech
from magfab.models.mechanics import MechanicsError
from magfab.recipes import Quantity, catalogue, resolve

PACKAGE = Path(__file__).resolve().parents[1] / "magfab"
RESOLVER = PACKAGE / "recipes" / "resolve.py"
#: Catalogues whose entry a spec key names: only the resolver takes one of their entries by key.
RESOLVED = ("magnets", "materials", "chips", "printers")


def _is_catalogue(node: ast.AST) -> bool:
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "catalogue"


def _mentions_spec(node: ast.AST) -> bool:
    return any((isinstance(n, ast.Attribute) and n.attr == "spec") or (isinstance(n, ast.Name) and n.id == "spec")
               for n in ast.walk(node))


def _keyed_lookups(source: str) -> list[int]:
    """Lines of ``catalogue(kind)[key]``, ``catalogue(kind).get(key)`` and ``name = catalogue(kind)`` (then indexed
    later) for the resolved kinds, or for a kind the code only knows at run time; and of any catalogue (or a name bound
    to one) indexed by a spec value. Listing or iterating a whole catalogue (the spec's check of which keys exist, the
    inverse design's search space, the acceptance table of every grade) is not a lookup."""
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    bound = {t.id for node in ast.walk(tree) if isinstance(node, ast.Assign)
             for target, value in _pairs(node) if _is_catalogue(value) for t in [target] if isinstance(t, ast.Name)}
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and _mentions_spec(node.slice) and (
                _is_catalogue(node.value) or (isinstance(node.value, ast.Name) and node.value.id in bound)):
            found.add(node.lineno)
        if not (_is_catalogue(node) and node.args):
            continue
        kind = node.args[0]
        if isinstance(kind, ast.Constant) and kind.value not in RESOLVED:
            continue
        up = parents.get(node)
        if isinstance(up, ast.Tuple):  # a, b = catalogue(x), catalogue(y)
            up = parents.get(up)
        if (isinstance(up, ast.Subscript) and up.value is node) or isinstance(up, (ast.Assign, ast.NamedExpr)) or (
                isinstance(up, ast.Attribute) and up.attr in {"get", "__getitem__"}):
            found.add(node.lineno)
    return sorted(found)


def _pairs(node: ast.Assign) -> list[tuple[ast.AST, ast.AST]]:
    """(target, value) of an assignment, tuples unpacked element by element."""
    out = []
    for target in node.targets:
        if isinstance(target, ast.Tuple) and isinstance(node.value, ast.Tuple):
            out += list(zip(target.elts, node.value.elts))
        else:
            out.append((target, node.value))
    return out


def test_only_the_resolver_looks_up_a_grade_material_chip_or_printer_by_key():
    modules = sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts and p != RESOLVER)
    offenders = [f"{p.relative_to(PACKAGE.parent)}:{line}" for p in modules for line in _keyed_lookups(p.read_text())]
    assert offenders == [], "read design.magnet_grade / .material / .chip / .printer (magfab/recipes/resolve.py)"


def test_the_lookup_check_sees_a_planted_lookup():
    planted = ('a = catalogue("magnets")[spec.magnet.grade]\n'
               'b = catalogue("chips").get("mlx90393")\n'
               'materials = catalogue("materials")\n'
               'c = catalogue(kind)[key]\n'
               'd = catalogue("adhesives")[design.spec.fabrication.adhesive]\n'
               'glues, parts = catalogue("adhesives"), catalogue("parts")\n'
               'e = glues[spec.fabrication.release_agent]\n')
    assert _keyed_lookups(planted) == [1, 2, 3, 4, 5, 7]
    listing = ('known = sorted(catalogue("magnets"))\n'
               'for name, g in catalogue("magnets").items(): pass\n'
               'ok = key in catalogue(kind)\n'
               'land = catalogue("land")["tolerances"]\n')
    assert _keyed_lookups(listing) == []
    assert _keyed_lookups(RESOLVER.read_text())  # the resolver's own lookups are seen (and allowed there only)


def test_the_stock_magnet_part_is_looked_up_by_grade_only_in_the_resolver():
    hits = [p for p in PACKAGE.rglob("*.py") if p != RESOLVER and "magnet-{" in p.read_text()]
    assert hits == []


@pytest.mark.parametrize("key", sorted(catalogue("magnets")))
def test_a_grade_is_the_catalogues_numbers_with_their_sources(key):
    entry, grade = catalogue("magnets")[key], resolve.magnet_grade(key)
    assert grade.key == key and grade.name == entry.name
    numbers = [f.name for f in fields(grade) if f.name in entry.quantities]
    assert set(numbers) == set(entry.quantities)  # every number of the grade's entry, none dropped
    for name in numbers:
        q = getattr(grade, name)
        assert q == entry[name] and q.source.strip() and q.low <= q.nominal <= q.high


@pytest.mark.parametrize("key", sorted(catalogue("magnets")))
def test_a_grade_carries_its_stock_parts_coating_and_rating(key):
    part = catalogue("assembly")[f"magnet-{key.lower()}"]
    grade = resolve.magnet_grade(key)
    assert grade.coating == part.texts["coating"]
    assert grade.max_operating_temp_C == part["max_operating_temp_C"]
    assert grade.density_g_cm3.nominal == part["density_g_cm3"].nominal  # the two files agree where both give it


@pytest.mark.parametrize("key", sorted(catalogue("materials")))
def test_a_material_is_the_catalogues_numbers_with_their_sources(key):
    entry, mat = catalogue("materials")[key], resolve.material(key)
    assert mat.key == key and mat.name == entry.name and mat.recipe is entry
    for f in fields(mat):
        if f.type == "Quantity":
            q = getattr(mat, f.name)
            assert isinstance(q, Quantity) and q == entry[f.name] and q.source.strip()
    assert mat.mix_ratio_by_weight == entry.texts["mix_ratio_by_weight"]
    assert mech.band(mat) == mech.band(key) == (entry["shear_modulus_kPa"].low, entry["shear_modulus_kPa"].nominal,
                                                entry["shear_modulus_kPa"].high)


def test_an_unknown_key_names_what_is_allowed():
    with pytest.raises(KeyError, match="N42"):
        resolve.magnet_grade("N99")
    with pytest.raises(MechanicsError, match=r"Input material must be one of .*ecoflex-00-30.*'unobtainium'"):
        mech.band("unobtainium")


def test_the_design_carries_the_specs_grade_material_chip_and_printer():
    d = derive(parse_spec('[magnet]\ngrade = "N52"\n[elastomer]\nmaterial = "dragon-skin-10"'))
    assert d.magnet_grade == resolve.magnet_grade("N52") and d.magnet_grade.remanence_T.nominal == 1.44
    assert d.material == resolve.material("dragon-skin-10")
    assert d.chip is catalogue("chips")[d.spec.sensor.chip]
    assert d.printer is catalogue("printers")[d.spec.mould.printer.value]
    # the models read the design's values: the field's remanence band is the grade's
    for band in ("low", "nominal", "high"):
        assert F.Magnet.from_design(d, band).remanence_T == getattr(d.magnet_grade.remanence_T, band)
    assert F.Magnet.from_spec(d.spec) == F.Magnet.from_design(d)


def test_the_design_resolves_every_catalogue_key_the_spec_has():
    from magfab.spec import _CATALOGUE_KEYS

    d = derive(load_spec(None))
    held = {("magnet", "grade"): d.magnet_grade.key, ("elastomer", "material"): d.material.key,
            ("sensor", "chip"): d.chip.key, ("fabrication", "adhesive"): d.adhesive.key,
            ("fabrication", "release_agent"): d.release_agent.key}
    assert set(held) == set(_CATALOGUE_KEYS)  # a new catalogue key in the spec needs a home in the Design
    assert held == {(s, k): getattr(getattr(d.spec, s), k) for s, k in _CATALOGUE_KEYS}
    assert d.printer.key == d.spec.mould.printer.value  # an Enum in the spec, a recipe in the Design


def test_design_json_does_not_change_with_the_typed_values():
    out = derive(load_spec(None)).as_dict()
    assert not {"magnet_grade", "material", "adhesive", "release_agent"} & set(out) and out["chip"] == "mlx90393"


def test_a_design_pickles_whole_and_cheaply():
    d = derive(load_spec(None))
    blob = pickle.dumps(d)
    back = pickle.loads(blob)
    assert back.magnet_grade == d.magnet_grade and back.material == d.material
    assert back.chip == d.chip and back.printer == d.printer and back.as_dict() == d.as_dict()
    assert len(blob) < 200_000  # sourced recipe text included; a Dask task or a forked pipe carries it easily
