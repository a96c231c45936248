"""An array's breakout board, from the builds a user gets: a chip under every magnet strapped to its address, two
capacitors each, one bus and one connector, every net connected, the address plan drawn, and KiCad's DRC clean on
the files as written; a board too small for the array's pad is one line."""

from __future__ import annotations

import json

import pytest
from conftest import require_kicad

from magfab import SpecError, derive, parse_spec, pcb
from magfab.board.layout import ORIGIN
from magfab.check import preflight
from magfab.export.kicad import run_tool

EXAMPLES = ("fingertip_2x2", "strip_1x5")


@pytest.fixture(scope="module")
def inspected(array_builds):
    """KiCad's reading of each built board (pcbnew), and the board file's text."""
    require_kicad()
    out = {}
    for name in EXAMPLES:
        path = array_builds[name].out_dir / "pcb" / f"{name}.kicad_pcb"
        out[name] = (json.loads(run_tool("inspect", str(path))), path.read_text())
    return out


@pytest.mark.parametrize("name", EXAMPLES)
def test_a_chip_under_every_magnet_on_its_address(array_builds, inspected, name):
    design = array_builds[name].design
    info, text = inspected[name]
    parts = {f["ref"]: f for f in info["footprints"]}
    chips = {ref: f for ref, f in parts.items() if ref.startswith("U")}
    assert len(chips) == len(design.taxels)
    pins = {v: k.removeprefix("pin_") for k, v in design.chip.texts.items() if k.startswith("pin_")}
    for t in design.taxels:
        u = chips[f"U{t.index + 1}"]
        assert (u["x"], u["y"]) == pytest.approx((ORIGIN[0] + t.x_mm, ORIGIN[1] - t.y_mm)) and not u["bottom"]
        assert u["value"].endswith(t.option_code)
        nets = {p["number"]: p["net"] for p in u["pads"] if p["number"]}
        assert [nets[pins["A1"]], nets[pins["A0"]]] == ["+3V3" if level else "GND" for level in t.address_straps]
        assert {nets[pins["SDA"]], nets[pins["SCL"]]} == {"SDA", "SCL"}
        caps = [f for ref, f in parts.items() if ref.startswith("C") and f["bottom"] and abs(f["x"] - u["x"]) < 1e-6
                and abs(f["y"] - u["y"]) < 3.0]
        assert len(caps) == 2
        assert f'(gr_text "T{t.index} 0x{t.i2c_address:02X} -{t.option_code}"' in text  # the mark beside it
        assert f"T{t.index}  U{t.index + 1}  0x{t.i2c_address:02X}  MLX90393SLW-ABA-{t.option_code}" in text  # table
    assert sum(ref.startswith("J") for ref in parts) == 1
    shape = f"{design.spec.array.rows}x{design.spec.array.cols} array: MLX90393 0x"
    assert f'(gr_text "{shape}{design.taxels[0].i2c_address:02X}-0x{design.taxels[-1].i2c_address:02X}"' in text
    found = {f.code: f for f in array_builds[name].findings}
    assert "pcb-ok" in found and "every net connected" in found["pcb-ok"].message
    assert not [c for c in found if c.startswith("pcb-") and c != "pcb-ok"]


@pytest.mark.parametrize("name", EXAMPLES)
def test_kicad_drc_of_the_built_board_is_clean(array_builds, name, tmp_path):
    require_kicad()
    path = array_builds[name].out_dir / "pcb" / f"{name}.kicad_pcb"
    counts = json.loads(run_tool("drc", str(path), str(tmp_path / "drc.rpt")))["counts"]
    assert counts["violations"] == 0 and counts["unconnected pads"] == 0, (tmp_path / "drc.rpt").read_text()
    gerbers = array_builds[name].out_dir / "pcb" / "gerbers"
    assert (gerbers / f"{name}-F_Cu.gbr").stat().st_size > 10_000


def test_a_board_too_small_for_the_array_is_one_line():
    with pytest.raises(SpecError) as err:
        pcb.board(derive(parse_spec('[array]\nrows = 1\ncols = 5\npitch_mm = 14\n'
                                    '[pcb]\nwidth_mm = 60\nheight_mm = 34')))
    assert "pcb.width_mm" in str(err.value) and "76.5 mm" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("name", EXAMPLES)
def test_the_address_plan_is_the_board_as_kicad_reads_it(array_builds, inspected, name):
    design = array_builds[name].design
    info, _ = inspected[name]
    parts = {f["ref"]: f for f in info["footprints"]}
    pins = {v: k.removeprefix("pin_") for k, v in design.chip.texts.items() if k.startswith("pin_")}
    plan = pcb.address_plan(design)
    assert [r["taxel"] for r in plan] == [t.index for t in design.taxels]
    assert len({r["address"] for r in plan}) == len(plan)  # one bus: every address once
    for r, t in zip(plan, design.taxels):
        u = parts[r["designator"]]
        assert (u["x"], u["y"]) == pytest.approx((r["kicad_x_mm"], r["kicad_y_mm"]))
        assert (r["x_mm"], r["y_mm"], r["address"], r["polarity"]) == (t.x_mm, t.y_mm, t.i2c_address, t.polarity)
        assert u["value"] == r["order_code"] and r["order_code"].endswith(t.option_code)
        nets = {p["number"]: p["net"] for p in u["pads"] if p["number"]}
        assert (nets[pins["A1"]], nets[pins["A0"]]) == (r["a1_net"], r["a0_net"])
        assert (r["a1"], r["a0"]) == tuple(t.address_straps)
        for c in r["capacitors"]:
            assert parts[c]["bottom"] and abs(parts[c]["x"] - u["x"]) < 1e-6 and abs(parts[c]["y"] - u["y"]) < 3.0


def test_a_single_taxel_plan_is_its_one_chip():
    design = derive(parse_spec(""))
    (row,) = pcb.address_plan(design)
    assert (row["designator"], row["address"], row["x_mm"], row["y_mm"]) == ("U1", design.i2c_address, 0.0, 0.0)
    assert (row["a1"], row["a0"]) == tuple(design.address_straps) and row["capacitors"] == ("C1", "C2")


def test_no_room_for_the_connector_gives_the_height_that_fits_the_array():
    """The pad fits but the connector does not (80 mm wide: the screw holes crowd the bottom edge): one line naming
    the least height that holds this array's pad and connector at that width (not the single taxel's 30 x 28), and
    that board places."""
    import re

    from magfab.board.placement import place

    strip = "[array]\nrows = 1\ncols = 5\npitch_mm = 14\n[pcb]\nwidth_mm = 80\nheight_mm = {}"
    with pytest.raises(SpecError) as err:
        place(derive(parse_spec(strip.format(22))))
    text = str(err.value)
    assert "Qwiic connector" in text and "default pad" not in text and "\n" not in text, text
    height = float(re.search(r"pcb\.height_mm = ([\d.]+)\)", text)[1])
    place(derive(parse_spec(strip.format(height))))
    with pytest.raises(SpecError):
        place(derive(parse_spec(strip.format(height - 0.5))))


def test_an_array_split_over_two_buses_has_a_connector_and_pull_ups_for_each(two_bus_build, tmp_path):
    """``array.buses = 2`` (the fingertip example on a QT Py RP2040), as KiCad reads the built board: the even taxels'
    chips on SDA/SCL to J1, the odd ones' on SDA_B/SCL_B to J2 (the address plan's ``bus``), R1, R2 pulling the first
    bus up and R3, R4 the second, every net connected and KiCad's DRC clean."""
    require_kicad()
    design = two_bus_build.design
    path = two_bus_build.out_dir / "pcb" / f"{design.spec.name}.kicad_pcb"
    info = json.loads(run_tool("inspect", str(path)))
    parts = {f["ref"]: f for f in info["footprints"]}
    pins = {v: k.removeprefix("pin_") for k, v in design.chip.texts.items() if k.startswith("pin_")}
    plan = pcb.address_plan(design)
    assert [r["bus"] for r in plan] == [0, 1, 0, 1]
    for r in plan:
        nets = {p["number"]: p["net"] for p in parts[r["designator"]]["pads"] if p["number"]}
        assert (nets[pins["SDA"]], nets[pins["SCL"]]) == (("SDA", "SCL"), ("SDA_B", "SCL_B"))[r["bus"]]
    for ref, (sda, scl) in (("J1", ("SDA", "SCL")), ("J2", ("SDA_B", "SCL_B"))):
        assert {p["net"] for p in parts[ref]["pads"] if p["net"]} == {"GND", "+3V3", sda, scl}
    pulled = {ref: {p["net"] for p in parts[ref]["pads"]} for ref in ("R1", "R2", "R3", "R4")}
    assert pulled == {"R1": {"+3V3", "SDA"}, "R2": {"+3V3", "SCL"}, "R3": {"+3V3", "SDA_B"}, "R4": {"+3V3", "SCL_B"}}
    assert sum(ref.startswith("J") for ref in parts) == 2
    text = path.read_text()
    for r in plan:  # the drawing's address table names each chip's connector
        assert f"T{r['taxel']}  {r['designator']}  {r['address_hex']}" in text
        assert f"A0={'3V3' if r['a0'] else 'GND'}  {('J1', 'J2')[r['bus']]}" in text
    counts = json.loads(run_tool("drc", str(path), str(tmp_path / "drc.rpt")))["counts"]
    assert counts["violations"] == 0 and counts["unconnected pads"] == 0, (tmp_path / "drc.rpt").read_text()


def test_a_second_bus_is_refused_for_one_taxel_and_for_an_arduino():
    """A second bus needs two taxels to split and a board with two I2C controllers: one line each, naming the key."""
    with pytest.raises(SpecError) as err:
        parse_spec("[array]\nrows = 1\ncols = 1\nbuses = 2")
    assert "buses" in str(err.value) and "two taxels" in str(err.value)
    with pytest.raises(SpecError) as err:
        preflight(derive(parse_spec("[array]\nrows = 1\ncols = 2\npitch_mm = 14\nbuses = 2")))
    assert err.value.key == "array.buses" and "rp2040" in str(err.value) and "\n" not in str(err.value)
