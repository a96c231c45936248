"""The breakout board: our own checks (and that they catch what they claim), the fit with the pad, and
KiCad itself loading the board, running its DRC and plotting Gerbers."""

from __future__ import annotations

import dataclasses
import json
import re

import pytest
from conftest import require_kicad

from magfab import SpecError, derive, load_spec, parse_spec, pcb
from magfab.board.placement import label as place_label
from magfab.board.placement import place
from magfab.board.route import Copper
from magfab.errors import Severity
from magfab.export.kicad import run_tool


@pytest.fixture(scope="module")
def design():
    return derive(load_spec(None))


@pytest.fixture(scope="module")
def board(design):
    return pcb.board(design)


def _codes(found):
    return {f.code for f in found if f.severity is Severity.ERROR}


def test_default_board_passes_our_checks(board):
    found = pcb.findings(board)
    assert not _codes(found), found
    assert any(f.code == "pcb-ok" for f in found)
    assert not board.unrouted


def test_chip_sits_under_the_pad_and_holes_match_it(board, design):
    u1 = next(p for p in board.parts if p.ref == "U1")
    cx, cy, r = board.pad_circle
    assert (u1.x, u1.y) == (cx, cy) == pcb.ORIGIN
    assert r == design.pad_radius_mm
    x0, y0, x1, y1 = board.outline
    assert ((x0 + x1) / 2, (y0 + y1) / 2) == (cx, cy)
    holes = {(round(p.x - cx, 6), round(cy - p.y, 6), p.footprint.pads[0].drill)
             for p in board.parts if p.ref in {"H1", "H2"}}
    assert holes == set(design.alignment_holes)


def test_top_side_keeps_clear_of_the_pad(board):
    cx, cy, r = board.pad_circle
    for p in board.parts:
        if p.bottom or p.ref in {"U1", "H1", "H2"}:
            continue
        box = p.box(p.footprint.courtyard)
        dx = max(box[0] - cx, 0.0, cx - box[2])
        dy = max(box[1] - cy, 0.0, cy - box[3])
        assert (dx * dx + dy * dy) ** 0.5 >= r, p.ref


def test_nets_follow_the_chip_recipe(board):
    u1 = next(p for p in board.parts if p.ref == "U1")
    assert u1.nets["15"] == u1.nets["8"] == u1.nets["2"] == "+3V3"  # VDD, VDDIO, CS high for I2C
    assert u1.nets["13"] == u1.nets["17"] == "GND"
    assert (u1.nets["3"], u1.nets["5"]) == ("SCL", "SDA")
    assert u1.nets["4"].startswith("unconnected-(U1-NC")
    j1 = next(p for p in board.parts if p.ref == "J1")
    assert [j1.nets[n] for n in "1234"] == ["GND", "+3V3", "SDA", "SCL"]  # Qwiic order
    caps = [p for p in board.parts if p.ref.startswith("C")]
    assert len(caps) == 2 and all(p.bottom and p.value == "100nF" for p in caps)


@pytest.mark.parametrize("address, a1, a0", [(0x0C, "GND", "GND"), (0x0D, "GND", "+3V3"), (0x0E, "+3V3", "GND"),
                                             (0x0F, "+3V3", "+3V3")])
def test_address_straps(address, a1, a0):
    d = derive(parse_spec(f"[sensor]\ni2c_address = {address}\n"))
    parts, outline, circle = place(d)
    u1 = parts[0]
    assert (u1.nets["11"], u1.nets["12"]) == (a1, a0)
    assert place_label(d, outline, parts, circle)[-1].text == f"MLX90393 I2C 0x{address:02X}"


def test_bad_addresses_and_option_codes_name_the_key():
    with pytest.raises(SpecError) as e:
        derive(parse_spec("[sensor]\ni2c_address = 0x20\n"))
    assert e.value.key == "sensor.i2c_address" and "0x0C" in str(e.value)
    with pytest.raises(SpecError) as e:
        derive(parse_spec('[sensor]\noption_code = "099"\n'))
    assert e.value.key == "sensor.option_code"
    assert derive(parse_spec('[sensor]\noption_code = "012"\ni2c_address = 0x13\n')).address_straps == (1, 1)


def test_too_small_board_is_a_spec_error():
    with pytest.raises(SpecError) as e:
        pcb.board(derive(parse_spec("[pcb]\nwidth_mm = 18\nheight_mm = 18\n")))
    assert e.value.key in {"pcb.width_mm", "pcb.height_mm"}


# -- the checks catch what they claim ---------------------------------------------------------------


def test_check_catches_a_clearance_violation(board):
    gnd = next(c for c in board.copper() if c.net == "GND" and c.owner == "U1.13")
    x = (gnd.a[0] + gnd.b[0]) / 2
    bad = Copper.seg(x, gnd.a[1] - 0.2, x, gnd.a[1] - 1.0, 0.25, "F.Cu", "SDA")
    assert "pcb-clearance" in _codes(pcb.findings(dataclasses.replace(board, tracks=(*board.tracks, bad))))


def test_check_catches_a_missing_track(board):
    sda = [t for t in board.tracks if t.net == "SDA" and t.kind == "seg" and "stub" not in t.owner]
    tracks = tuple(t for t in board.tracks if t is not sda[len(sda) // 2])
    assert "pcb-unconnected" in _codes(pcb.findings(dataclasses.replace(board, tracks=tracks)))


def test_check_catches_a_part_under_the_pad(board):
    parts = tuple(dataclasses.replace(p, y=pcb.ORIGIN[1] + 6.0) if p.ref == "J1" else p for p in board.parts)
    codes = _codes(pcb.findings(dataclasses.replace(board, parts=parts)))
    assert "pcb-pad-keepout" in codes


def test_check_catches_overlapping_courtyards(board):
    c1 = next(p for p in board.parts if p.ref == "C1")
    parts = tuple(dataclasses.replace(p, y=c1.y + 0.5) if p.ref == "C2" else p for p in board.parts)
    codes = _codes(pcb.findings(dataclasses.replace(board, parts=parts)))
    assert {"pcb-courtyard", "pcb-pad-overlap"} <= codes


def test_board_files_are_deterministic(board, design):
    again = pcb.files(pcb.board(design))
    assert again == pcb.files(board)
    text = again["magone.kicad_pcb"].decode()
    assert "tstamp" not in text and "(version 20211014)" in text


# -- KiCad itself -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def written(board, tmp_path_factory):
    root = tmp_path_factory.mktemp("pcb")
    for rel, data in pcb.files(board).items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
    return root


def test_kicad_loads_the_board_with_our_pads_and_nets(board, written):
    require_kicad()
    info = json.loads(run_tool("inspect", str(written / "magone.kicad_pcb")))
    assert info["clearance"] == 0.15  # the design rules of our .kicad_pro were read
    assert set(info["nets"]) == set(board.nets())
    ours = {p.ref: p for p in board.parts}
    assert {f["ref"] for f in info["footprints"]} == set(ours)
    for f in info["footprints"]:
        part = ours[f["ref"]]
        assert (f["x"], f["y"], f["bottom"]) == (part.x, part.y, part.bottom)
        copper = [c for c in part.copper() if not c.hole]
        kicad = [p for p in f["pads"] if p["number"] or p["net"]]
        if part.ref == "U1":
            assert len(f["pads"]) == 21 and len(kicad) == 17  # 16 lands + exposed pad, 4 paste apertures
        for c in copper:
            number = c.owner.split(".", 1)[1]
            cx, cy = (c.a[0] + c.b[0]) / 2, (c.a[1] + c.b[1]) / 2
            match = [p for p in kicad if p["number"] == number and abs(p["x"] - cx) < 1e-4 and abs(p["y"] - cy) < 1e-4]
            assert match, (part.ref, number)
            p = match[0]
            size = sorted((p["w"], p["h"]))
            assert size == pytest.approx(sorted((c.b[0] - c.a[0], c.b[1] - c.a[1])), abs=1e-4)
            assert p["net"] == c.net
    assert info["tracks"] == sum(1 for t in board.tracks if t.kind == "seg")
    assert info["vias"] == sum(1 for t in board.tracks if t.kind == "point")
    assert {(z["net"], z["layer"]) for z in info["zones"]} == {("GND", "F.Cu"), ("GND", "B.Cu")}


def _drc(path, tmp_path):
    return json.loads(run_tool("drc", str(path), str(tmp_path / "drc.rpt")))["counts"]


def test_kicad_drc_finds_nothing(written, tmp_path):
    require_kicad()
    counts = _drc(written / "magone.kicad_pcb", tmp_path)
    report = (tmp_path / "drc.rpt").read_text()
    assert counts["violations"] == 0, report
    assert counts["unconnected pads"] == 0, report


def test_kicad_drc_is_not_blind(written, tmp_path):
    """Control: the same board under a 0.4 mm clearance rule must show violations."""
    require_kicad()
    for f in written.iterdir():
        if f.is_file():
            (tmp_path / f.name).write_bytes(f.read_bytes())
    pro = json.loads((tmp_path / "magone.kicad_pro").read_text())
    pro["net_settings"]["classes"][0]["clearance"] = 0.4
    (tmp_path / "magone.kicad_pro").write_text(json.dumps(pro))
    assert _drc(tmp_path / "magone.kicad_pcb", tmp_path)["violations"] > 0


DRC_VARIANTS = [
    '[sensor]\ni2c_address = 0x0F\n[pcb]\npullups = false\ndensity = "most"\nwidth_mm = 34\nheight_mm = 31\n'
    "clearance_mm = 0.2\n",
    # narrow annular ring: KiCad's hole clearance binds, not the copper clearance (found by KiCad's DRC)
    "[pcb]\nclearance_mm = 0.1\ntrack_width_mm = 0.15\nvia_diameter_mm = 0.5\nvia_drill_mm = 0.25\nwidth_mm = 32\n",
    # tracks wider than the QFN lands neck down at the chip; the project's minimum width must allow it
    '[pcb]\ndensity = "least"\nclearance_mm = 0.24\ntrack_width_mm = 0.3\nmounting_hole_diameter_mm = 0\n'
    "via_diameter_mm = 0.5\nvia_drill_mm = 0.25\nheight_mm = 28\n",
]


@pytest.mark.parametrize("text", DRC_VARIANTS)
def test_variant_board_passes_kicad_drc(tmp_path, text):
    require_kicad()
    b = pcb.board(derive(parse_spec(text, "variant")))
    assert not _codes(pcb.findings(b))
    for rel, data in pcb.files(b).items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_bytes(data)
    counts = _drc(tmp_path / "variant.kicad_pcb", tmp_path)
    assert counts["violations"] == 0 and counts["unconnected pads"] == 0, (tmp_path / "drc.rpt").read_text()


def test_build_writes_library_board_and_gerbers(default_build):
    require_kicad()
    out = default_build.out_dir / "pcb"
    assert (out / "magfab.pretty" / "QFN-16-1EP_3x3mm_P0.5mm_EP1.7x1.7mm.kicad_mod").exists()
    assert (out / "magone.kicad_pcb").exists() and (out / "magone.kicad_pro").exists()
    gerbers = sorted(p.name for p in (out / "gerbers").iterdir())
    layers = ["B_Cu", "B_Mask", "B_Paste", "B_Silkscreen", "Edge_Cuts", "F_Cu", "F_Mask", "F_Paste", "F_Silkscreen"]
    assert gerbers == sorted([f"magone-{x}.gbr" for x in layers] + ["magone-NPTH.drl", "magone-PTH.drl"])
    top = (out / "gerbers" / "magone-F_Cu.gbr").read_text()
    assert "%TF.FileFunction,Copper,L1,Top*%" in top and top.rstrip().endswith("M02*")
    assert "2000-01-01" in top  # creation date pinned for reproducible builds
    npth = (out / "gerbers" / "magone-NPTH.drl").read_text()
    tools = {round(float(d), 3) for d in re.findall(r"^T\d+C([0-9.]+)", npth, re.M)}
    assert tools == {1.0, 1.5, 2.2}  # the pad's two dowel holes and the M2 holes
    manifest = json.loads((default_build.out_dir / "manifest.json").read_text())
    assert manifest["models"]["gerbers"].startswith("KiCad 6")


def test_wide_clearance_shrinks_the_exposed_pad_land_and_is_capped():
    """The lands sit 0.2 mm from the exposed pad: a wider rule shrinks the EP land to suit; past the
    gap between neighbouring lands no board can pass, and the spec is refused naming the limit."""
    b = pcb.board(derive(parse_spec("[pcb]\nclearance_mm = 0.22\n", "wide")))
    assert not _codes(pcb.findings(b))
    u1 = next(p for p in b.parts if p.ref == "U1")
    ep = u1.footprint.pads[16]
    assert ep.number == "17" and ep.w == pytest.approx(2.1 - 2 * 0.22, abs=0.01)
    with pytest.raises(SpecError) as err:
        pcb.board(derive(parse_spec("[pcb]\nclearance_mm = 0.25\n", "wider")))
    assert err.value.key == "pcb.clearance_mm" and "at most 0.247 mm" in str(err.value)


@pytest.mark.parametrize("name", ["m", "fingertip_v2-soft", "x" * 40, "lab-" + "very_long_design_name." * 2 + "x" * 16])
def test_long_names_wrap_and_stay_on_the_board(name):
    d = derive(parse_spec("", name))
    parts, outline, circle = place(d)
    label = place_label(d, outline, parts, circle)
    assert 2 <= len(label) <= 3
    text = "".join(t.text for t in label[:-1])
    assert text == name or (text.endswith("..") and name.startswith(text[:-2]))
    for t in label:
        assert t.size >= pcb.SILK_MIN_TEXT_MM and t.thickness >= 0.15
    b = dataclasses.replace(pcb.board(d), tracks=())
    assert "pcb-silk" not in _codes(pcb.findings(b))
    # the check measures: the same label moved onto the edge is caught
    moved = dataclasses.replace(b, label=(dataclasses.replace(label[0], y=outline[1]),))
    assert "pcb-silk" in _codes(pcb.findings(moved))


# Combinations that the greedy router (before targeted rip-up with negotiated congestion) left unrouted.
HARD_VARIANTS = [
    '[sensor]\ni2c_address = 0x0D\n[pcb]\ndensity = "least"\nmounting_hole_diameter_mm = 0\n'
    "via_diameter_mm = 0.8\nvia_drill_mm = 0.4\n",
    "[pcb]\nclearance_mm = 0.2\npullups = false\ntrack_width_mm = 0.3\n",
    "[pcb]\nclearance_mm = 0.24\npullups = false\ntrack_width_mm = 0.3\n",
    '[pcb]\ndensity = "most"\npullups = false\ntrack_width_mm = 0.2\n[pad]\ndiameter_mm = 18\n'
    "alignment_hole_spacing_mm = 15\n",
]


@pytest.mark.parametrize("text", HARD_VARIANTS)
def test_hard_variants_route_and_pass_our_checks(text):
    b = pcb.board(derive(parse_spec(text, "hard")))
    assert not b.unrouted and not _codes(pcb.findings(b)), pcb.findings(b)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_variants_route(seed):
    """Exhaustive: 30 seeded variants per seed (bench/route.py's generator) all route cleanly."""
    import importlib.util
    from pathlib import Path
    path = Path(__file__).parents[2] / "bench" / "route.py"
    spec = importlib.util.spec_from_file_location("bench_route", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rows = bench.run(bench.variants(30, seed))
    bad = [r for r in rows if "refused" not in r and not r["ok"]]
    assert not bad, bad


def test_via_drill_keeps_the_hole_clearance(board):
    """A via's pad may meet the copper rule while its drill breaks the hole rule (narrow ring)."""
    from magfab.board.route import LAYERS, clearance_violations
    rules = board.rules
    track = Copper.seg(0.0, 0.0, 5.0, 0.0, 0.2, "F.Cu", "A")
    # via pad 0.5 mm, drill 0.25 mm: 0.1 mm copper gap leaves 0.225 mm from the drill to the track
    via = Copper.point(2.0, 0.1 + 0.25 + 0.1 + 0.001, 0.25, LAYERS, "B", "via")
    assert not clearance_violations([track, via], 0.1, rules["hole_clearance"])
    found = clearance_violations([track, via], 0.1, rules["hole_clearance"], via_drill=0.25)
    assert found and found[0][3] == pytest.approx(0.125)
