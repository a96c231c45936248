"""The unit-mistake guard (magfab.plausible) against a generator of the mistake: a magnet size or a modulus drawn
anywhere in the span the recipes source, then typed a unit's factor off, is refused at the key the user typed with
the value meant; values drawn within the guard's factor of the span are not refused by it; and `magfab check` says so
in one line, exit 2, writing nothing."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.design import derive
from magfab.errors import SpecError
from magfab.errors import number_text as fmt
from magfab.plausible import UNIT, plausible, spans
from magfab.spec import parse_spec

MAGNET = ("magnet.diameter_mm", "magnet.height_mm")
MODULUS = "elastomer.shear_modulus_kPa"


def _within(key: str) -> st.SearchStrategy[float]:
    lo, hi, *_ = spans()[key]
    return st.floats(lo, hi)


def _toml(key: str, value) -> str:
    section, name = key.split(".")
    return f"[{section}]\n{name} = {value!r}\n".replace("(", "[").replace(")", "]")


@settings(max_examples=30, deadline=None)
@given(key=st.sampled_from(MAGNET), data=st.data())
def test_a_magnet_typed_in_metres_is_refused_at_its_key(key, data):
    meant = data.draw(_within(key))
    typed = meant / UNIT
    with pytest.raises(SpecError) as info:
        derive(parse_spec(_toml(key, typed)))
    assert info.value.key == key, str(info.value)
    assert f"did you mean {fmt(typed * UNIT)} mm?" in str(info.value)


@settings(max_examples=30, deadline=None)
@given(data=st.data(), factor=st.sampled_from([UNIT, 1.0 / UNIT]))
def test_a_modulus_a_unit_off_is_refused_at_its_key(data, factor):
    band = sorted(data.draw(st.lists(_within(MODULUS), min_size=3, max_size=3)))
    typed = tuple(x * factor for x in band)
    with pytest.raises(SpecError) as info:
        derive(parse_spec(_toml(MODULUS, typed)))
    assert info.value.key == MODULUS, str(info.value)
    if max(typed) <= 1.0e5:  # past it the spec's own bound refuses first (the key named, without the guess)
        meant = ", ".join(fmt(x / factor) for x in typed)
        assert f"did you mean [{meant}] kPa?" in str(info.value)


@settings(max_examples=40, deadline=None)
@given(key=st.sampled_from([*MAGNET, MODULUS]), data=st.data())
def test_values_within_the_factor_are_the_designers(key, data):
    """Log-uniform over the span widened by the key's factor either way: never refused by the guard (the design's
    own checks judge the geometry)."""
    lo, hi, factor, *_ = spans()[key]
    u = data.draw(st.floats(math.log(lo / factor) + 1e-9, math.log(hi * factor) - 1e-9))
    value = math.exp(u)
    if key == MODULUS:
        value = (value, value, value)
    if key == "magnet.diameter_mm" and value > 50.0:  # the spec's own bound, below the guard's
        return
    plausible(parse_spec(_toml(key, value)))


@pytest.mark.parametrize("text, key, meant", [
    ("[magnet]\ndiameter_mm = 0.005\n", "magnet.diameter_mm", "did you mean 5 mm?"),
    ("[elastomer]\nshear_modulus_kPa = [15000, 23000, 39000]\n", MODULUS, "did you mean [15, 23, 39] kPa?"),
])
def test_check_says_it_in_one_line(tmp_path, text, key, meant):
    (tmp_path / "spec.toml").write_text(text)
    run = subprocess.run([sys.executable, "-m", "magfab.cli", "check", "spec.toml"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{key} = " in lines[0] and meant in lines[0], run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["spec.toml"]
