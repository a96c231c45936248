"""An array's breakout board, from the builds a user gets: a chip under every magnet strapped to its address, two
capacitors each, one bus and one connector, every net connected, the address plan drawn, and KiCad's DRC clean on
the files as written; a board too small for the array's pad is one line."""

from __future__ import annotations

import json

import pytest

from conftest import require_kicad
from magfab import SpecError, derive, parse_spec
from magfab import pcb
from magfab.board.layout import ORIGIN
from magfab.export.kicad import run_tool

EXAMPLES = ("fingertip_2x2", "strip_1x5")


@pytest.fixture(scope="module")
def boards(array_builds):
    return {name: (array_builds[name].design, pcb.board(array_builds[name].design)) for name in EXAMPLES}


@pytest.mark.parametrize("name", EXAMPLES)
def test_a_chip_under_every_magnet_on_its_address(boards, name):
    design, board = boards[name]
    chips = {p.ref: p for p in board.parts if p.ref.startswith("U")}
    assert len(chips) == len(design.taxels)
    pins = {v: k for k, v in design.chip.texts.items() if k.startswith("pin_")}
    a1_pad, a0_pad = pins["A1"].removeprefix("pin_"), pins["A0"].removeprefix("pin_")
    for t in design.taxels:
        u = chips[f"U{t.index + 1}"]
        assert (u.x, u.y) == pytest.approx((ORIGIN[0] + t.x_mm, ORIGIN[1] - t.y_mm)) and not u.bottom
        assert u.value.endswith(t.option_code)
        want = ["+3V3" if level else "GND" for level in t.address_straps]
        assert [u.nets[a1_pad], u.nets[a0_pad]] == want
        caps = [p for p in board.parts if p.ref.startswith("C") and p.bottom and abs(p.x - u.x) < 1e-6
                and abs(p.y - u.y) < 3.0]
        assert len(caps) == 2
    assert sum(p.ref.startswith("J") for p in board.parts) == 1
    assert not board.unrouted and not [f for f in pcb.findings(board) if f.severity.value != "info"]
    # the plan drawn: a mark beside each chip and the table beside the board
    assert [m.text for m in board.marks] == [f"T{t.index} 0x{t.i2c_address:02X}" for t in design.taxels]
    assert len(board.address_table) == len(design.taxels) + 1


@pytest.mark.parametrize("name", EXAMPLES)
def test_kicad_reads_the_built_board_and_its_drc_is_clean(array_builds, boards, name, tmp_path):
    require_kicad()
    path = array_builds[name].out_dir / "pcb" / f"{name}.kicad_pcb"
    design, board = boards[name]
    assert path.read_bytes() == pcb.files(board)[f"{name}.kicad_pcb"]  # the build wrote this board
    info = json.loads(run_tool("inspect", str(path)))
    assert sum(f["ref"].startswith("U") for f in info["footprints"]) == len(design.taxels)
    counts = json.loads(run_tool("drc", str(path), str(tmp_path / "drc.rpt")))["counts"]
    assert counts["violations"] == 0 and counts["unconnected pads"] == 0, (tmp_path / "drc.rpt").read_text()
    gerbers = array_builds[name].out_dir / "pcb" / "gerbers"
    assert (gerbers / f"{name}-F_Cu.gbr").stat().st_size > 10_000


def test_a_board_too_small_for_the_array_is_one_line():
    with pytest.raises(SpecError) as err:
        derived = derive(parse_spec('[array]\nrows = 1\ncols = 5\npitch_mm = 14\n[pcb]\nwidth_mm = 60\nheight_mm = 34'))
        pcb.board(derived)
    assert "pcb.width_mm" in str(err.value) and "76.5 mm" in str(err.value) and "\n" not in str(err.value)
