"""The bench papers of an array: the BOM orders each option code for its chips, the checklist carries the address
plan and each magnet's orientation (the same table the board's silkscreen and array.json carry)."""

from __future__ import annotations

import csv
import io

import pytest

from magfab.design import derive
from magfab.export.bom import bom_csv
from magfab.export.checklist import checklist_md
from magfab.spec import parse_spec


@pytest.fixture(scope="module")
def strip():
    return derive(parse_spec('[array]\nrows = 1\ncols = 5\npitch_mm = 14.0\npolarity = "alternating"\n'
                             '[fabrication]\nsensors = 2\n', "strip"))


def test_the_bom_orders_every_chip_by_its_option_code(strip):
    rows = list(csv.DictReader(io.StringIO(bom_csv(strip))))
    chips = {r["part"]: r for r in rows if r["item"] == "Hall sensor IC"}
    assert {p: int(r["quantity"]) for p, r in chips.items()} == \
        {"MLX90393SLW-ABA-011-RE": 8, "MLX90393SLW-ABA-012-RE": 2}
    assert "U5 (taxel 4, 0x10)" in chips["MLX90393SLW-ABA-012-RE"]["description"]
    by_item = {r["item"]: r for r in rows}
    assert int(by_item["Magnet"]["quantity"]) == 10 and int(by_item["Capacitor"]["quantity"]) == 20


def test_the_checklist_carries_the_address_plan_and_the_orientation(strip):
    md = checklist_md(strip)
    assert "| 4 | 28, 0 | U5 | MLX90393SLW-ABA-012 | 0x10 | 0, 0 | up (to the tip) |" in md
    assert "| 1 | -14, 0 | U2 | MLX90393SLW-ABA-011 | 0x0D | 0, 1 | down (to the chip) |" in md
    assert "taxel(s) 1, 3 take theirs south face (undotted) first" in md
    assert "place U1-U5 (U1, U2, U3, U4 from the -011 reel; U5 from the -012 reel)" in md
    single = checklist_md(derive(parse_spec("")))
    assert "address plan" not in single and "place U1 (pin 1" in single
