"""The spec: defaults, the shipped schema, and one clear message for every kind of bad input."""

from __future__ import annotations

import json
from importlib import resources

import pytest

from magfab import SpecError, load_spec, parse_spec
from magfab.recipes import KINDS, catalogue
from magfab.spec import Spec, spec_schema


def test_embedded_spec_equals_the_defaults():
    # An empty spec and the commented MagOne file describe the same design: the file documents the defaults.
    assert parse_spec("", default_name="magone") == load_spec(None)


def test_shipped_schema_is_generated_from_the_model():
    shipped = json.loads(resources.files("magfab").joinpath("spec.schema.json").read_text())
    assert shipped == spec_schema(), "regenerate with: magfab schema > magfab/spec.schema.json"
    assert set(shipped["properties"]) == set(Spec.model_fields)


def test_every_recipe_number_has_a_source():
    for kind in KINDS:
        entries = catalogue(kind)
        assert entries, kind
        for entry in entries.values():
            for q in entry.quantities.values():
                assert q.source.strip() and q.low <= q.nominal <= q.high


@pytest.mark.parametrize(
    "text, key, words",
    [
        ("[magnet]\ndiametr_mm = 3", "magnet.diametr_mm", "did you mean 'diameter_mm'"),
        ("[magnett]\ndiameter_mm = 3", "magnett", "did you mean 'magnet'"),
        ("[magnet]\ndiameter_mm = -1", "magnet.diameter_mm", "greater than 0 mm"),
        ("[magnet]\ndiameter_mm = 0", "magnet.diameter_mm", "greater than 0"),
        ("[magnet]\ndiameter_mm = \"5\"", "magnet.diameter_mm", "must be a number"),
        ("[magnet]\ndiameter_mm = true", "magnet.diameter_mm", "must be a number"),
        ("[magnet]\ndiameter_mm = nan", "magnet.diameter_mm", "finite"),
        ("[magnet]\ndiameter_mm = inf", "magnet.diameter_mm", "finite"),
        ("[magnet]\ngrade = \"N53\"", "magnet.grade", "must be one of"),
        ("[elastomer]\nmaterial = \"ecoflex-00-3\"", "elastomer.material", "did you mean 'ecoflex-00-30'"),
        ("[elastomer]\ntip = \"round\"", "elastomer.tip", "'hemisphere' or 'flat'"),
        ("[mould]\ncavities = 2.5", "mould.cavities", "integer"),
        ("[mould]\ncavities = 0", "mould.cavities", "greater than or equal to 1"),
        ("[mould]\nprinter = \"laser\"", "mould.printer", "'sla' or 'fdm'"),
        ("magnet = 3", "magnet", "table"),
        ("name = \"../evil\"", "name", "pattern"),
        ("[magnet\n", "spec", "not valid TOML"),
    ],
)
def test_bad_input_names_the_key_and_what_is_allowed(text, key, words):
    with pytest.raises(SpecError) as info:
        parse_spec(text)
    assert info.value.key == key
    assert words in str(info.value)
    assert str(info.value).startswith(key)


def test_missing_file_is_a_spec_error(tmp_path):
    with pytest.raises(SpecError, match="file not found"):
        load_spec(tmp_path / "nope.toml")


def test_name_defaults_to_the_file_stem(tmp_path):
    path = tmp_path / "finger_v2.toml"
    path.write_text("[magnet]\nheight_mm = 1.5\n")
    spec = load_spec(path)
    assert spec.name == "finger_v2" and spec.magnet.height_mm == 1.5


def test_spec_is_frozen_and_hash_follows_content():
    spec = load_spec(None)
    with pytest.raises(Exception):
        spec.name = "other"  # type: ignore[misc]
    variant = spec.model_copy(update={"name": "other"})
    assert variant.sha256() != spec.sha256() and load_spec(None).sha256() == spec.sha256()


def test_readme_documents_every_key():
    from pathlib import Path

    from pydantic import BaseModel

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    for section, field in Spec.model_fields.items():
        model = field.annotation
        keys = [f"{section}.{k}" for k in model.model_fields] if isinstance(model, type) and issubclass(model, BaseModel) else [section]
        for key in keys:
            assert f"`{key}`" in readme, f"README's spec reference lacks {key}"
