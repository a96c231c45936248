"""The reference chip on the board ([reference]): where the magnets leave the field quiet, on the next address, with
its own decoupling, on the bus; the board taller by what it needs, the BOM ordering it, KiCad's DRC clean."""

from __future__ import annotations

import json

import pytest
from conftest import require_kicad

from magfab import SpecError, derive, parse_spec, pcb
from magfab.board.layout import ORIGIN
from magfab.board.placement import board_size_mm
from magfab.check import preflight
from magfab.export.bom import bom_rows
from magfab.export.kicad import run_tool
from magfab.models.reference import Travel, site
from magfab.reference_chip import reference_chip


@pytest.fixture(scope="module")
def with_reference():
    design = derive(parse_spec('name = "ref"\n[reference]\n'))
    return design, pcb.board(design)


def test_the_reference_stands_where_no_magnet_is_heard_on_the_next_address(with_reference):
    design, board = with_reference
    ref = reference_chip(design)
    quiet = site(design, Travel.bound(design), 10.0)
    assert (ref.x_mm, ref.y_mm) == quiet.xy_mm and max(quiet.motion_G) <= max(quiet.noise_G)
    assert ref.designator == "U2" and ref.i2c_address == design.i2c_address + 1 and ref.address_straps == (0, 1)
    parts = {p.ref: p for p in board.parts}
    u2 = parts["U2"]
    assert (u2.x, u2.y) == pytest.approx((ORIGIN[0] + ref.x_mm, ORIGIN[1] - ref.y_mm)) and not u2.bottom
    pins = {v: k.removeprefix("pin_") for k, v in design.chip.texts.items() if k.startswith("pin_")}
    assert [u2.nets[pins["A1"]], u2.nets[pins["A0"]]] == ["GND", "+3V3"]
    assert {u2.nets[pins["SDA"]], u2.nets[pins["SCL"]]} == {"SDA", "SCL"}
    caps = [p for p in board.parts if p.ref.startswith("C") and p.bottom and abs(p.x - u2.x) < 1e-6
            and abs(p.y - u2.y) < 3.0]
    assert len(caps) == 2
    x0, y0, x1, y1 = board.outline
    assert y0 < u2.y - 3 and (x1 - x0, y1 - y0) == pytest.approx(board_size_mm(design))
    assert board_size_mm(design)[1] > design.spec.pcb.height_mm
    assert any("ref 0x0D" in t.text for t in board.label)
    codes = [f.code for f in pcb.findings(board)]
    assert codes == ["pcb-ok"], codes
    rows = [r for r in bom_rows(design) if "reference chip" in " ".join(map(str, r.values()))]
    assert len(rows) == 1 and "U2" in " ".join(map(str, rows[0].values()))


def test_without_the_section_the_board_is_as_before():
    design = derive(parse_spec(""))
    assert reference_chip(design) is None and board_size_mm(design) == (30.0, 30.0)


def test_an_array_with_a_reference_is_refused_in_one_line():
    with pytest.raises(SpecError) as err:
        preflight(derive(parse_spec("[array]\nrows = 1\ncols = 5\npitch_mm = 14\n[pcb]\nwidth_mm = 80\n[reference]\n")))
    assert str(err.value).startswith("reference") and "single taxel" in str(err.value) and "\n" not in str(err.value)


def test_kicad_drc_of_the_board_with_a_reference_is_clean(with_reference, tmp_path):
    require_kicad()
    _, board = with_reference
    for rel, data in pcb.files(board).items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_bytes(data)
    counts = json.loads(run_tool("drc", str(tmp_path / f"{board.name}.kicad_pcb"), str(tmp_path / "drc.rpt")))["counts"]
    assert counts["violations"] == 0 and counts["unconnected pads"] == 0, (tmp_path / "drc.rpt").read_text()
