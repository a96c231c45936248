"""The bench papers: silicone quantities from the mould, the checklist (Markdown and HTML) and the bill of
materials follow the spec, and spec or recipe text is escaped for the language it lands in."""

from __future__ import annotations

import csv
import io
import math

import pytest

from magfab.export import checklist as C
from magfab import derive, load_spec, parse_spec
from magfab.errors import Severity, SpecError
from magfab.export.templating import md


@pytest.fixture(scope="module")
def design():
    return derive(load_spec(None))


def _bom(design):
    return {row["item"]: row for row in csv.DictReader(io.StringIO(C.bom_csv(design)))}


def test_quantities_come_from_the_cast_solid(design):
    """One part's silicone is the elastomer solid's volume (the cavity less the pocket core), exactly."""
    from magfab.elastomer import elastomer_solid

    q = C.quantities(design)
    assert q.part_volume_mL == pytest.approx(elastomer_solid(design).val().Volume() / 1000.0, rel=1e-6)
    holes = [d for _, _, d in design.lid_holes[2:]]
    assert len(holes) == 3 * design.spec.mould.cavities  # a sprue and two vents per cavity
    assert q.holes_volume_mL == pytest.approx(sum(math.pi * d * d / 4 * design.lid_thickness_mm for d in holes) / 1000)
    grams = q.mould_holds_mL * q.density_g_cm3 * (1 + q.waste_pct / 100)
    assert q.batch_g == pytest.approx(max(grams, C.MIN_BATCH_G))
    assert q.part_a_g + q.part_b_g == pytest.approx(q.batch_g)
    assert q.part_a_g == pytest.approx(q.part_b_g)  # Ecoflex is 1A:1B by weight


def test_more_cavities_and_sensors_scale_the_pours():
    d = derive(parse_spec("[mould]\ncavities = 4\n[fabrication]\nsensors = 10\nwaste_pct = 10\n"))
    q = C.quantities(d)
    assert q.pours == 3 and q.cavities == 4
    assert q.batch_g == pytest.approx(max((4 * q.part_volume_mL + q.holes_volume_mL) * q.density_g_cm3 * 1.1,
                                          C.MIN_BATCH_G))
    assert q.total_g == pytest.approx(3 * q.batch_g)
    bom = _bom(d)
    assert bom["Hall sensor IC"]["quantity"] == "10" and bom["Capacitor"]["quantity"] == "20"
    assert float(bom["Silicone"]["quantity"]) == pytest.approx(round(q.total_g, 1))


def test_material_changes_the_ratio_the_times_and_the_papers():
    d = derive(parse_spec('[elastomer]\nmaterial = "sylgard-184"\n[mould]\ncavities = 8\n'))
    q = C.quantities(d)
    assert q.ratio == (10.0, 1.0) and q.part_a_g == pytest.approx(10 * q.part_b_g)
    assert q.cure_time_h == 48 and q.pot_life_min == 90
    text = C.checklist_md(d)
    assert "SYLGARD 184" in text and "of base and" in text and "curing agent" in text
    assert "Dow SYLGARD 184" in _bom(d)["Silicone"]["part"]


def test_overrides_win_over_the_recipe():
    d = derive(parse_spec("[fabrication]\ndensity_g_cm3 = 2.14\npot_life_min = 5\ncure_time_h = 1.5\nwaste_pct = 0\n"
                          "[mould]\ncavities = 8\n"))
    q = C.quantities(d)
    assert q.density_g_cm3 == 2.14 and q.cure_time_h == 1.5
    assert any(f.code == "pot-life" and f.severity is Severity.WARNING for f in C.findings(d))


def test_address_and_option_code_reach_the_bom_and_the_checklist():
    d = derive(parse_spec('[sensor]\noption_code = "012"\ni2c_address = 0x13\n[pcb]\npullups = false\n'))
    bom = _bom(d)
    assert bom["Hall sensor IC"]["part"] == "MLX90393SLW-ABA-012-RE"
    assert "Resistor" not in bom
    assert "0x13" in C.checklist_md(d) and "0x13" in C.checklist_html(d)


def test_markdown_and_html_escape_what_they_carry(design, monkeypatch):
    hostile = "<script>alert(1)</script> *bold* [link](x) a_b | c"
    assert "<" not in md(hostile) and "\\*bold\\*" in md(hostile) and "\\[link\\]" in md(hostile)
    monkeypatch.setattr(C, "sections", lambda d, a=None, p=None: [("Step " + hostile, [hostile])])
    html = C.checklist_html(design)
    assert "<script>" not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    text = C.checklist_md(design)
    assert "<script>" not in text and "&lt;script&gt;" in text


def test_checklist_covers_the_protocol(design):
    titles = [t for t, _ in C.sections(design)]
    for needle in ("Print", "Prepare", "Weigh", "Pour", "Magnet", "Solder", "Assemble", "Flash", "Calibrate",
                   "Acceptance"):
        assert any(needle in t for t in titles), needle
    html = C.checklist_html(design)
    assert html.count('type="checkbox"') == sum(len(s) for _, s in C.sections(design))
    q = C.quantities(design)
    assert f"{q.part_a_g:.1f} g" in C.checklist_md(design)


def test_a_ratio_that_cannot_be_read_is_a_clear_error():
    with pytest.raises(SpecError) as e:
        C.mix_ratio("by eye", "recipes/materials.toml:x.mix_ratio_by_weight")
    assert "1A:1B" in str(e.value)


def test_the_build_quotes_its_own_acceptance_bands_and_bom(default_build):
    """checklist.md's pass line carries acceptance.json's figures, and bom.csv is the BOM of the same design
    (written through checklist's re-export of magfab.export.bom)."""
    import json

    from magfab.export import bom

    out = default_build.out_dir
    acc = json.loads((out / "calibration" / "acceptance.json").read_text())
    (lo, hi), w, (d_lo, d_hi) = acc["rest_Bz_uT"], acc["weight_g"], acc["delta_Bz_uT"]
    assert 0 < lo < acc["rest"]["Bz_uT"]["nominal"] < hi and 0 < d_lo < d_hi
    line = next(s for s in (out / "checklist.md").read_text().splitlines() if "Pass:" in s)
    assert f"within {lo:.0f} to {hi:.0f} uT" in line and f"a {w:g} g weight raises Bz by {d_lo:.0f} to {d_hi:.0f} uT" in line
    assert C.bom_csv is bom.bom_csv
    assert (out / "bom.csv").read_text() == bom.bom_csv(default_build.design)


def test_the_scan_step_the_simulated_scan_and_the_range_share_one_depth(default_build, magone_design,
                                                                          magone_prediction):
    """The checklist tells the bench to scan exactly as deep as the simulated scan goes, and that is where the
    predicted normal range ends (MagOne: the stretch limit, before the spec's 3 mm scan depth)."""
    import numpy as np

    from magfab.models.scan import scan_plan, scan_track

    pred = magone_prediction
    plan = scan_plan(magone_design, pred)
    nominal = pred.curves["nominal"]
    end = float(np.interp(pred.normal.travel_mm, nominal.magnet_displacement_mm, nominal.indentation_mm))
    assert plan.depth_mm == pytest.approx(min(end, magone_design.spec.calibration.scan_z_mm))
    y, delta = scan_track(magone_design, pred)
    assert plan.depth_mm - plan.step_mm < delta.max() <= plan.depth_mm + 1e-9
    assert y.size == plan.points
    text = (default_build.out_dir / "checklist.md").read_text()
    assert f"{plan.depth_mm:.3g} mm of indentation" in text and f"({plan.points} points)" in text
    if plan.depth_mm < magone_design.spec.calibration.scan_z_mm:
        assert f"the predicted normal range ({pred.normal.range_limit})" in text


def test_the_glue_step_fills_the_channel_the_force_model_assumes_filled(design):
    """The FE bonds the magnet in a filled channel (an open one is ~34 % softer at 1 mm on MagOne,
    tests/models/test_mechanics_pocket.py): the magnet step says to fill it, with the design's own volume."""
    step = next(s for title, steps in C.sections(design) if title == "Magnet" for s in steps if "Fill" in s)
    volume = design.core_volume_mm3 - design.magnet_volume_mm3
    assert 20.0 < volume < 35.0 and f"about {volume:.0f} uL" in step and "up to the magnet" in step


def test_flash_commands_name_a_board_flash_sh_accepts(default_build):
    """The README's and the checklist's flash commands pass flash.sh a board it knows (it exits 2 on anything
    else, as `sh firmware/flash.sh /dev/ttyACM0` once did)."""
    import re
    from pathlib import Path

    script = (default_build.out_dir / "firmware" / "flash.sh").read_text()
    boards = set(re.search(r"usage: sh flash.sh ([\w|-]+)", script).group(1).split("|"))
    readme = (Path(__file__).parents[2] / "README.md").read_text()
    checklist = (default_build.out_dir / "checklist.md").read_text()
    used = re.findall(r"sh firmware/flash\.sh (\S+)", readme + checklist)
    assert used and set(used) <= boards, (used, boards)
