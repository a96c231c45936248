"""The stock disc catalogue (recipes/magnet_stock.toml): the magnet sizes the design search may choose."""

from __future__ import annotations

import re
from fractions import Fraction

import pytest

from magfab import load_spec
from magfab.recipes import catalogue

STOCK = catalogue("magnet_stock")
GRADES = set(catalogue("magnets"))


def _grades(entry) -> list[str]:
    return entry.texts["grades"].split()


def _size(entry) -> tuple[float, float]:
    return entry["diameter_mm"].nominal, entry["height_mm"].nominal


def test_every_entry_loads_with_a_source_and_a_known_grade():
    assert len(STOCK) >= 15
    for key, entry in STOCK.items():
        assert set(entry.quantities) == {"diameter_mm", "height_mm"}, key
        for q in entry.quantities.values():
            assert q.low == q.nominal == q.high and q.source.strip(), key
        assert {"name", "grades", "vendor", "part", "source"} <= set(entry.texts), key
        assert entry.texts["source"].startswith("https://"), key
        grades = _grades(entry)
        assert grades and set(grades) <= GRADES and len(set(grades)) == len(grades), (key, grades)
        # the part number the source quotes is the entry's
        assert entry.texts["part"] in entry["diameter_mm"].source, key


def test_sizes_are_small_discs_keyed_by_their_size_and_listed_once():
    sizes = [_size(e) for e in STOCK.values()]
    assert len(set(sizes)) == len(sizes)
    for key, entry in STOCK.items():
        d, h = _size(entry)
        assert 1.0 <= d <= 10.0 and 0.5 <= h <= 5.0, (key, d, h)
        assert key == f"d{d:g}_h{h:g}".replace(".", "p"), key


def test_inch_sizes_are_converted_exactly_and_give_the_inch_value():
    inch = re.compile(r"(\d+)/(\d+) in dia\. x (\d+)/(\d+) in thick")
    seen = 0
    for key, entry in STOCK.items():
        match = inch.search(entry["diameter_mm"].source)
        if entry.texts["vendor"] != "K&J Magnetics":
            assert match is None, key
            continue
        assert match, f"{key}: an inch size must quote its inch value"
        d_in, h_in = Fraction(int(match[1]), int(match[2])), Fraction(int(match[3]), int(match[4]))
        assert Fraction(repr(entry["diameter_mm"].nominal)) == Fraction(254, 10) * d_in, key
        assert Fraction(repr(entry["height_mm"].nominal)) == Fraction(254, 10) * h_in, key
        seen += 1
    assert seen >= 3


def test_magones_magnet_size_and_grade_are_stocked():
    magnet = load_spec(None).magnet
    sizes = {_size(e): k for k, e in STOCK.items()}
    assert (magnet.diameter_mm, magnet.height_mm) == (5.0, 2.0)
    assert (magnet.diameter_mm, magnet.height_mm) in sizes
    assert any(magnet.grade in _grades(e) for e in STOCK.values())


@pytest.mark.xfail(strict=True, reason="no stored vendor source sells a 5 x 2 mm disc in N35 (MagOne's exact magnet); "
                                       "the 5 x 2 mm size is listed in N52 only. Drop this marker when one is sourced.")
def test_magones_exact_magnet_is_a_stock_article():
    assert "N35" in _grades(STOCK["d5_h2"])
