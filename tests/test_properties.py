"""Property-based: over random specs, never a traceback and never a partial directory.

Specs are drawn near the valid region (so many are feasible, many are geometrically impossible) and
with garbage mixed in (wrong types, NaN, infinities, negative sizes, unknown keys).
"""

from __future__ import annotations

import math
import tomllib

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from magfab import SpecError, derive, parse_spec
from magfab.check import design_findings
from magfab.spec import Spec

pytestmark = pytest.mark.filterwarnings("ignore")

GARBAGE = st.one_of(
    st.just(float("nan")), st.just(float("inf")), st.just(-1.0), st.just(0.0), st.text(max_size=5),
    st.booleans(), st.lists(st.integers(), max_size=2), st.integers(-5, 5),
)


def _field_values(model: type[BaseModel], name: str):
    default = model.model_fields[name].get_default(call_default_factory=True)
    if isinstance(default, bool):
        return st.booleans()
    if isinstance(default, int):
        return st.integers(1, 4)
    if isinstance(default, float) or default is None:
        base = default if isinstance(default, float) else 1.0
        return st.floats(0.3 * base, 2.0 * base, allow_nan=False)
    if isinstance(default, str) and name == "name":
        return st.from_regex(r"[a-z][a-z0-9_-]{0,8}", fullmatch=True)
    return st.sampled_from([getattr(default, "value", default), "ecoflex-00-50", "fdm", "flat", "N52", "bogus"])


@st.composite
def raw_specs(draw):
    raw: dict = {}
    for section, field in Spec.model_fields.items():
        model = field.annotation
        if not (isinstance(model, type) and issubclass(model, BaseModel)):
            if draw(st.booleans()):
                raw[section] = draw(_field_values(Spec, section))
            continue
        if not draw(st.booleans()):
            continue
        table = {}
        for name in model.model_fields:
            if draw(st.integers(0, 3)) == 0:
                table[name] = draw(st.one_of(_field_values(model, name), GARBAGE) if draw(st.integers(0, 9)) == 0
                                   else _field_values(model, name))
        if draw(st.integers(0, 20)) == 0:
            table[draw(st.text(min_size=1, max_size=6))] = 1.0
        raw[section] = table
    return raw


def _toml_string(text: str) -> str:
    """A TOML basic string: quotes, backslashes and every control character (DEL too) escaped."""
    body = "".join(f"\\u{ord(ch):04x}" if ord(ch) < 0x20 or ord(ch) == 0x7F or ch in '"\\' else ch for ch in text)
    return f'"{body}"'


def _to_toml(raw: dict) -> str:
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return "nan" if math.isnan(v) else ("inf" if math.isinf(v) else repr(v))
        if isinstance(v, str):
            return _toml_string(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return str(v)

    lines = [f"{k} = {value(v)}" for k, v in raw.items() if not isinstance(v, dict)]
    for section, table in raw.items():
        if isinstance(table, dict):
            lines.append(f"[{section}]")
            lines += [f"{_toml_string(k)} = {value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(raw_specs())
def test_spec_and_design_never_crash(raw):
    text = _to_toml(raw)
    tomllib.loads(text)  # the generator itself writes valid TOML
    try:
        design = derive(parse_spec(text))
    except SpecError as exc:
        event("infeasible or invalid")
        assert exc.key and str(exc).startswith(exc.key) and "\n" not in str(exc)  # noqa: PT017 - refusing is one allowed outcome, not the expected one
        return
    assert design.d_rest_mm == pytest.approx(design.spec.sensor.d_max_mm, abs=1e-3)
    assert design.skin_mm >= design.spec.elastomer.min_skin_mm - 1e-9
    assert design.elastomer_volume_mm3 > 0
    design_findings(design)


def _cli_build_is_all_or_nothing(raw, tmp_path_factory):
    from click.testing import CliRunner

    from magfab.cli import main

    tmp = tmp_path_factory.mktemp("prop")
    spec = tmp / "spec.toml"
    spec.write_text(_to_toml(raw))
    out = tmp / "out"
    result = CliRunner().invoke(main, ["build", str(spec), "--out", str(out), "--json"])
    event(f"exit {result.exit_code}")
    assert result.exit_code in (0, 2), result.output
    assert "Traceback" not in result.output
    leftovers = sorted(p.name for p in tmp.iterdir())
    if result.exit_code == 2:
        assert leftovers == ["spec.toml"]
    else:
        assert leftovers == ["out", "spec.toml"] and (out / "manifest.json").is_file()


_CLI = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]}


@settings(max_examples=5, **_CLI)
@given(raw=raw_specs())
def test_cli_build_is_all_or_nothing(raw, tmp_path_factory):
    """A few full builds per run (each feasible one costs a whole build); the slow run tries 60."""
    _cli_build_is_all_or_nothing(raw, tmp_path_factory)


@pytest.mark.slow
@settings(max_examples=60, **_CLI)
@given(raw=raw_specs())
def test_cli_build_is_all_or_nothing_exhaustive(raw, tmp_path_factory):
    _cli_build_is_all_or_nothing(raw, tmp_path_factory)
