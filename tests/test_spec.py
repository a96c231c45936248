"""The spec: defaults, the shipped schema, and one clear message for every kind of bad input."""

from __future__ import annotations

import json
from importlib import resources

import pytest
from pydantic import ValidationError

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
        ("[mould]\ncavities = 0", "mould.cavities", "at least 1"),
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
    with pytest.raises(ValidationError, match="Instance is frozen"):
        spec.name = "other"  # type: ignore[misc]
    variant = spec.model_copy(update={"name": "other"})
    assert variant.sha256() != spec.sha256() and load_spec(None).sha256() == spec.sha256()


def test_readme_documents_every_key():
    from pathlib import Path
    from typing import get_args

    from pydantic import BaseModel

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    for section, field in Spec.model_fields.items():
        model = next((a for a in (field.annotation, *get_args(field.annotation))
                      if isinstance(a, type) and issubclass(a, BaseModel)), None)  # [array] is Optional
        keys = [f"{section}.{k}" for k in model.model_fields] if model else [section]
        for key in keys:
            assert f"`{key}`" in readme, f"README's spec reference lacks {key}"


# ---- parsers as strict as the formats, messages exact and bounded -----------------------------------------


def _commented_spec_lines():
    """Every commented `key = value` line of the shipped spec, with the section it sits in."""
    from magfab.spec import default_spec_text

    section, out = "", []
    for line in default_spec_text().splitlines():
        if line.startswith("["):
            section = line
        elif line.startswith("# ") and " = " in line.split("#")[1]:
            out.append((section, line[2:]))
    return out


def test_the_shipped_spec_has_commented_lines():
    assert len(_commented_spec_lines()) >= 3


@pytest.mark.parametrize("section, line", _commented_spec_lines())
def test_every_commented_line_of_the_shipped_spec_parses_when_uncommented(section, line):
    # The shear-modulus line was refused ("must be a valid tuple"): strict mode took no TOML array.
    from magfab.spec import default_spec_text

    text = default_spec_text().replace(f"# {line}", line, 1)
    spec = parse_spec(text)
    key = line.split("=")[0].strip()
    assert getattr(getattr(spec, section.strip("[]")), key) is not None


def test_shear_modulus_takes_an_array_of_three_numbers():
    assert parse_spec("[elastomer]\nshear_modulus_kPa = [15, 23.0, 39]").elastomer.shear_modulus_kPa == \
        (15.0, 23.0, 39.0)
    for bad in ("[15.0, 23.0]", "[15.0, 23.0, \"x\"]", "[39.0, 23.0, 15.0]", "[true, 1.0, 2.0]"):
        with pytest.raises(SpecError) as info:
            parse_spec(f"[elastomer]\nshear_modulus_kPa = {bad}")
        assert info.value.key == "elastomer.shear_modulus_kPa" and "three" in str(info.value)


def test_an_integral_float_is_an_integer():
    # Chosen: 12.0 is accepted for an integer key (TOML writes both; a unit conversion gives floats); 12.5 is not.
    assert parse_spec("[sensor]\ni2c_address = 12.0").sensor.i2c_address == 12
    assert isinstance(parse_spec("[mould]\ncavities = 2.0").mould.cavities, int)
    for bad in ("2.5", "1e300", "\"2\"", "true"):
        with pytest.raises(SpecError) as info:
            parse_spec(f"[mould]\ncavities = {bad}")
        assert info.value.key == "mould.cavities" and "integer" in str(info.value)


def test_a_value_at_its_bound_is_allowed_and_past_it_is_shown_exactly():
    assert parse_spec("[pad]\nlip_width_mm = 10").pad.lip_width_mm == 10.0
    with pytest.raises(SpecError) as info:
        parse_spec("[pad]\nlip_width_mm = 10.0000000001")
    # Was "pad.lip_width_mm = 10: must be less than or equal to 10 mm" (the value rounded by %g).
    assert str(info.value) == "pad.lip_width_mm = 10.0000000001: must be at most 10 mm"
    with pytest.raises(SpecError) as info:
        parse_spec("[predict]\ntolerance_pct = 0")
    assert str(info.value) == "predict.tolerance_pct = 0: must be greater than 0 %"


@pytest.mark.parametrize("text", [
    'name = "' + "x" * 1_000_000 + '"',
    '[magnet]\ngrade = "' + "N" * 1_000_000 + '"',
    '[magnet]\n"' + "k" * 1_000_000 + '" = 1',
    "[magnet]\ndiameter_mm = " + "1" * 5000,
])
def test_error_lines_are_bounded(text):
    with pytest.raises(SpecError) as info:
        parse_spec(text)
    message = str(info.value)
    assert len(message) < 300 and "\n" not in message, message[:400]
    assert "characters)" in message or "must be" in message or "not valid TOML" in message


def test_a_name_must_match_in_full():
    # Python's `$` matches before a trailing newline: "evil\n" passed re.match and reached the TOML init writes.
    from magfab.spec import is_valid_name

    assert is_valid_name("finger_v2.1") and not is_valid_name("evil\n") and not is_valid_name("a b")
    with pytest.raises(SpecError) as info:
        parse_spec("", default_name="evil\n")
    assert info.value.key == "name" and "\n" not in str(info.value)


def test_init_refuses_a_file_name_that_is_not_a_design_name(tmp_path):
    from click.testing import CliRunner

    from magfab.cli import main

    runner = CliRunner()
    bad = tmp_path / "evil\n.toml"
    result = runner.invoke(main, ["init", str(bad)])
    assert result.exit_code == 2 and not bad.exists()
    assert result.output.count("\n") == 1 and "name" in result.output
    good = tmp_path / "finger.toml"
    assert runner.invoke(main, ["init", str(good)]).exit_code == 0
    assert load_spec(good).name == "finger"
