"""The bench papers: silicone quantities from the mould, the checklist (Markdown and HTML) and the bill of
materials follow the spec, and spec or recipe text is escaped for the language it lands in."""

from __future__ import annotations

import csv
import io
import math

import pytest

from magfab import derive, load_spec, parse_spec
from magfab.check import fabrication_findings
from magfab.errors import Severity, SpecError
from magfab.export import bom
from magfab.export import checklist as C
from magfab.export.templating import md
from magfab.models import silicone as S


@pytest.fixture(scope="module")
def design():
    return derive(load_spec(None))


def _bom(design):
    return {row["item"]: row for row in csv.DictReader(io.StringIO(bom.bom_csv(design)))}


def test_quantities_come_from_the_cast_solid(design):
    """One part's silicone is the elastomer solid's volume (the cavity less the pocket core), exactly."""
    from magfab.elastomer import elastomer_solid

    q = S.quantities(design)
    assert q.part_volume_mL == pytest.approx(elastomer_solid(design).val().Volume() / 1000.0, rel=1e-6)
    holes = [d for _, _, d in design.lid_holes[2:]]
    assert len(holes) == 3 * design.spec.mould.cavities  # a sprue and two vents per cavity
    assert q.holes_volume_mL == pytest.approx(sum(math.pi * d * d / 4 * design.lid_thickness_mm for d in holes) / 1000)
    grams = q.mould_holds_mL * q.density_g_cm3 * (1 + q.waste_pct / 100)
    assert q.batch_g == pytest.approx(max(grams, S.MIN_BATCH_G))
    assert q.part_a_g + q.part_b_g == pytest.approx(q.batch_g)
    assert q.part_a_g == pytest.approx(q.part_b_g)  # Ecoflex is 1A:1B by weight


def test_more_cavities_and_sensors_scale_the_pours():
    d = derive(parse_spec("[mould]\ncavities = 4\n[fabrication]\nsensors = 10\nwaste_pct = 10\n"))
    q = S.quantities(d)
    assert q.pours == 3 and q.cavities == 4
    assert q.batch_g == pytest.approx(max((4 * q.part_volume_mL + q.holes_volume_mL) * q.density_g_cm3 * 1.1,
                                          S.MIN_BATCH_G))
    assert q.total_g == pytest.approx(3 * q.batch_g)
    bom = _bom(d)
    assert bom["Hall sensor IC"]["quantity"] == "10" and bom["Capacitor"]["quantity"] == "20"
    assert float(bom["Silicone"]["quantity"]) == pytest.approx(round(q.total_g, 1))


def test_material_changes_the_ratio_the_times_and_the_papers():
    d = derive(parse_spec('[elastomer]\nmaterial = "sylgard-184"\n[mould]\ncavities = 8\n'))
    q = S.quantities(d)
    assert q.ratio == (10.0, 1.0) and q.part_a_g == pytest.approx(10 * q.part_b_g)
    assert q.cure_time_h == 48 and q.pot_life_min == 90
    text = C.checklist_md(d)
    assert "SYLGARD 184" in text and "of base and" in text and "curing agent" in text
    assert "Dow SYLGARD 184" in _bom(d)["Silicone"]["part"]


def test_overrides_win_over_the_recipe():
    d = derive(parse_spec("[fabrication]\ndensity_g_cm3 = 2.14\npot_life_min = 5\ncure_time_h = 1.5\nwaste_pct = 0\n"
                          "[mould]\ncavities = 8\n"))
    q = S.quantities(d)
    assert q.density_g_cm3 == 2.14 and q.cure_time_h == 1.5
    assert any(f.code == "pot-life" and f.severity is Severity.WARNING for f in fabrication_findings(d))


def test_address_and_option_code_reach_the_bom_and_the_checklist():
    d = derive(parse_spec('[sensor]\noption_code = "012"\ni2c_address = 0x13\n[pcb]\npullups = false\n'))
    bom = _bom(d)
    assert bom["Hall sensor IC"]["part"] == "MLX90393SLW-ABA-012-RE"
    assert "Resistor" not in bom
    assert "0x13" in C.checklist_md(d) and "0x13" in C.checklist_html(d)


def test_markdown_and_html_escape_what_they_carry(design, monkeypatch):
    hostile = "<script>alert(1)</script> *bold* [link](x) a_b | c"
    assert "<" not in md(hostile) and "\\*bold\\*" in md(hostile) and "\\[link\\]" in md(hostile)
    table = C.Table(("h " + hostile,), ((hostile,),))
    monkeypatch.setattr(C, "sections",
                        lambda d, a=None, p=None, w=None: [C.Section("Step " + hostile, (C.Step(hostile),), table)])
    html = C.checklist_html(design)
    assert "<script>" not in html and html.count("&lt;script&gt;alert(1)&lt;/script&gt;") == 4
    text = C.checklist_md(design)
    assert "<script>" not in text and text.count("&lt;script&gt;") == 4 and "\\| c" in text


def test_checklist_covers_the_protocol(design):
    titles = [s.title for s in C.sections(design)]
    order = ("Parts", "Print", "Prepare", "Weigh", "Pour", "magnet", "Solder", "Assemble", "Wire", "Flash",
             "Calibrate", "Acceptance")
    at = [next(i for i, t in enumerate(titles) if needle in t) for needle in order]
    assert at == sorted(at) and len(titles) == len(order)
    html = C.checklist_html(design)
    assert html.count('type="checkbox"') == sum(len(s.steps) for s in C.sections(design))
    q = S.quantities(design)
    assert f"{q.part_a_g:.1f} g" in C.checklist_md(design)


def test_a_ratio_that_cannot_be_read_is_a_clear_error():
    with pytest.raises(SpecError) as e:
        S.mix_ratio("by eye", "recipes/materials.toml:x.mix_ratio_by_weight")
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
    assert f"within {lo:.0f} to {hi:.0f} uT" in line and \
        f"a {w:g} g weight raises Bz by {d_lo:.0f} to {d_hi:.0f} uT" in line
    plan = json.loads((out / "calibration" / "weigh_plan.json").read_text())
    assert (out / "bom.csv").read_text() == bom.bom_csv(default_build.design, acc, plan)


def test_the_weights_section_follows_the_scan_and_names_the_plans_load(default_build):
    """With the build's weight plan the checklist gains "Calibrate with weights" between the scan's calibration and
    the acceptance test, naming the coins the stiffest skin's plan needs and the cap's bound; the BOM lists the jig,
    the coins and a balance; an array's build has neither."""
    import json

    out = default_build.out_dir
    plan = json.loads((out / "calibration" / "weigh_plan.json").read_text())
    titles = [s.title for s in C.sections(default_build.design, None, None, plan)]
    at = titles.index("Calibrate with weights (no force sensor)")
    assert titles[at - 1] == "Calibrate" and titles[at + 1] == "Acceptance test"
    text = (out / "checklist.md").read_text()
    most = plan["coins_most"]  # the stiffest skin's plan's: the two-stage bench may plan for it
    assert most >= max(step["coins"] for step in plan["steps"])
    assert f"Have {most} coins ready" in text and f"at most {plan['cap_mass_bound_g']:.1f} g" in text
    rows = {r["item"]: r for r in bom.bom_rows(default_build.design, None, plan)}
    assert rows["Coins"]["quantity"] == most and "weigh_cap.stl" in rows["Printed weight jig"]["part"]
    assert "Balance" in rows and "Coins" not in {r["item"] for r in bom.bom_rows(default_build.design)}


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
        assert f"{magone_design.spec.calibration.scan_z_mm:.3g} mm of indentation" not in text
        assert f"the predicted normal range ({pred.normal.range_limit})" in text


def test_the_glue_step_fills_the_channel_the_force_model_assumes_filled(design):
    """The FE bonds the magnet in a filled channel (an open one is ~34 % softer at 1 mm on MagOne,
    tests/models/test_mechanics_pocket.py): the magnet step says to fill it, with the design's own volume."""
    step = next(s.text for sec in C.sections(design) for s in sec.steps if s.text.startswith("Fill"))
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



# ---------------------------------------------------------------------------------------------------
# The checklist as bench instructions: steps say what to do, every number is the recipe's, the
# commands are sh blocks, the wiring and the parts are tables.

MATERIALS = ("ecoflex-00-10", "ecoflex-00-30", "ecoflex-00-50", "dragon-skin-10", "dragon-skin-20", "dragon-skin-30",
             "sylgard-184")
#: Research-note phrasing that belongs in a recipe's source field, never in a step.
BANNED = ("not retrieved", "not found", "stored source", "stored corpus", "build guide", "the issue", "brief",
          "secondary", "as quoted", "as reproduced", "via", "blog", "http", ".com", "faq", "tb", "bulletin",
          "fab academy", "wiki", "as ecoflex", "as dragon", "jig", "e.g.", "datasheet (", "(see ", "this note",
          "30-60", "the full 60")
ACCEPTANCE = {"rest_Bz_uT": [16000.0, 21000.0], "weight_g": 73.0, "delta_Bz_uT": [1200.0, 6400.0]}


def _steps(sections):
    return [s.text for sec in sections for s in sec.steps]


def _blocks(markdown: str) -> list[list[str]]:
    import re

    return [b.splitlines() for b in re.findall(r"^```sh\n(.*?)^```$", markdown, re.M | re.S)]


@pytest.fixture(scope="module",
                params=[*[(m, p) for m in MATERIALS for p in ("sla", "fdm")][::3], ("ecoflex-00-30", "fdm")],
                ids=lambda mp: "-".join(mp))
def variant(request):
    material, printer = request.param
    return derive(parse_spec(f'[elastomer]\nmaterial = "{material}"\n[mould]\nprinter = "{printer}"\n'))


def test_steps_carry_no_research_notes(variant):
    import re

    for text in _steps(C.sections(variant, ACCEPTANCE)):
        found = [b for b in BANNED if re.search(r"(?<![a-z])" + re.escape(b) + r"(?![a-z])", text.lower())]
        assert not found, (found, text)


def test_every_material_has_its_own_sourced_degas_and_inhibition_text():
    import re

    from magfab.recipes import catalogue

    degas = set()
    for key in MATERIALS:
        rec = catalogue("materials")[key]
        assert rec.texts["degas_source"] and rec.texts["inhibition_source"]
        assert not re.search(r"\d\s*(min|h\b|inhg|times|x\b|%|cps)", rec.texts["degas"].lower()), key  # quantities
        degas.add(rec.texts["degas"])
    assert len(degas) >= len(MATERIALS) - 2  # the Dragon Skin grades may share a sentence, nothing else


def test_process_numbers_are_the_recipe_values(variant):
    """Post-cure, degas, pot life and cure: one value each, the recipe's, where the step states it."""
    import re

    from magfab.recipes import catalogue

    rec = catalogue("materials")[variant.spec.elastomer.material]
    printer = variant.printer
    steps = _steps(C.sections(variant, ACCEPTANCE))
    q = S.quantities(variant)
    assert q.pot_life_min == rec["pot_life_min"].nominal and q.cure_time_h == rec["cure_time_h"].nominal
    degas = next(s for s in steps if s.startswith("Degas:"))
    assert f"pull {rec['degas_vacuum_inHg'].nominal:g} inHg" in degas
    assert f"at least {rec['degas_cup_ratio'].nominal:g} times" in degas
    assert f"then {rec['degas_extra_min'].nominal:g} min more" in degas
    assert f"Pot life {q.pot_life_min:g} min" in " ".join(steps)
    assert f"Cure for {q.cure_time_h:g} h" in " ".join(steps)
    post = [s for s in steps if "post-cure" in s.lower() and re.search(r"\d+ min", s)]
    if "post_cure_time_min" in printer.quantities:
        quantity = printer["post_cure_time_min"]
        assert quantity.low == quantity.high  # one value, one source
        assert len(post) == 1 and f"post-cure them for {quantity.nominal:g} min" in post[0]
        assert re.findall(r"(\d+) min", post[0])[-1] == f"{quantity.nominal:g}"
    else:
        assert not post


def test_the_pad_is_fixed_to_the_board_before_the_elastomer_is_glued_onto_it(design):
    from magfab.recipes import catalogue

    ca = catalogue("adhesives")["loctite-401"]
    assemble = next(s for s in C.sections(design) if s.title == "Assemble")
    texts = [s.text for s in assemble.steps]
    pins = next(i for i, s in enumerate(texts) if "dowel pins" in s)
    fix = next(i for i, s in enumerate(texts) if s.startswith("Fix the pad"))
    glue = next(i for i, s in enumerate(texts) if "elastomer's flat base" in s)
    assert pins < fix < glue
    assert ca.name in texts[fix] and f"{ca['fixture_time_s'].nominal:g} s" in texts[fix]
    assert f"{ca['cure_time_full_h'].nominal:g} h" in texts[fix] and " uL" in texts[fix]
    assert "loctite-401" in list(catalogue("adhesives")) and ca["fixture_time_s"].source.startswith("LOCTITE 401")


def test_the_magnet_goes_in_after_demoulding_north_face_first(design):
    titles = [s.title for s in C.sections(design)]
    magnet = next(s for s in C.sections(design) if "magnet" in s.title)
    assert titles.index("Pour, cure and demould") < titles.index(magnet.title)
    assert any("dotted (north) face first" in s.text for s in magnet.steps)


def test_the_wiring_table_runs_through_the_level_shifter(design):
    from magfab.recipes import catalogue

    wire = next(s for s in C.sections(design) if s.title == "Wire the board")
    rows = {r[0].split(" ")[0]: r for r in wire.table.rows}
    ls = catalogue("bench")["level-shifter"]
    assert rows["SDA"][3].startswith("A4") and rows["SCL"][3].startswith("A5")
    assert rows["SDA"][1:3] == (ls.texts["sda_low_pin"], ls.texts["sda_high_pin"])
    assert rows["3V3"][1:] == ("LV", "", "3.3V") and rows["GND"][3] == "GND"
    assert rows[""][2:] == ("HV", "5V")
    qwiic = catalogue("parts")["jst-sh-4"]
    assert [r[0] for r in wire.table.rows[:4]] == [f"{qwiic.texts[f'qwiic_pin_{k}']} (pin {k})" for k in range(1, 5)]
    text = C.checklist_md(design, ACCEPTANCE)
    assert "| SDA (pin 3) | L1 | H1 | A4 (SDA) |" in text and "| GND (pin 1) | GND | GND | GND |" in text
    assert "<td>A5 (SCL)</td>" in C.checklist_html(design, ACCEPTANCE)
    assert ls.name in " ".join(s.text for s in wire.steps)


def test_the_board_connector_matches_the_wiring_table(default_build):
    """J1's nets on the generated board are the Qwiic pin order the table wires from."""
    import re

    from magfab.recipes import catalogue

    board = next((default_build.out_dir / "pcb").glob("*.kicad_pcb")).read_text()
    start = board.rfind("(footprint", 0, board.index('(fp_text reference "J1"'))
    end = board.find("(footprint", start + 1)
    j1 = board[start:end if end > 0 else None]
    nets = dict(re.findall(r'\(pad "(\d)" smd \w+.*?\(net \d+ "([^"]+)"\)', j1, re.S))
    qwiic = catalogue("parts")["jst-sh-4"]
    assert {k: v.lstrip("+") for k, v in nets.items()} == {str(k): qwiic.texts[f"qwiic_pin_{k}"] for k in range(1, 5)}


def test_bench_commands_are_sh_blocks_with_the_acceptance_weight(design):
    import re

    text = C.checklist_md(design, ACCEPTANCE)
    blocks = _blocks(text)
    sensor = C.sensor_id(design)
    expected = [C.sensor_commands(design), C.FLASH_COMMANDS, C.calibrate_commands(sensor),
                C.acceptance_commands(sensor, 73, "")]
    assert blocks == [list(b) for b in expected]
    assert blocks[0][1] == f"magfab sensor add {sensor} --build build/{design.spec.name}"
    assert blocks[-1] == [f"magfab-readout check --weight-g 73 --sensor {sensor}",
                          f"magfab sensor show {sensor} --plot {sensor}.png"]
    html = C.checklist_html(design, ACCEPTANCE)
    for line in (line for b in expected for line in b):
        assert line in html
    assert html.count('<pre class="sh">') == 4
    for step in _steps(C.sections(design, ACCEPTANCE)):  # prose never holds a command to type
        assert not re.search(r"magfab-readout \w|pip install|(?<![\w-])sh firmware/|magfab (calibrate|sensor)",
                             step), step
    without = C.checklist_md(design, None)
    assert len(_blocks(without)) == 3 and "--weight-g" not in without


def test_the_built_checklist_commands_match_the_readme(default_build):
    """The build's own checklist quotes acceptance.json's weight, and its commands are the README's."""
    import json
    from pathlib import Path

    out = default_build.out_dir
    weight = json.loads((out / "calibration" / "acceptance.json").read_text())["weight_g"]
    blocks = _blocks((out / "checklist.md").read_text())
    assert blocks[-1][0] == f"magfab-readout check --weight-g {weight:g} --rotation --warmup --sensor magone-01"
    readme = (Path(__file__).parents[2] / "README.md").read_text()
    # The README builds the spec "finger" in build/finger and names its sensor finger-01; the checklist's cd lines
    # go to the folder the build was made in and back (the README's commands start there).
    commands = [c.split("#")[0].strip().replace("magone", "finger") for b in blocks for c in b]
    missing = [c for c in commands if not c.startswith("cd ") and c not in readme]
    assert not missing, f"README lacks {missing}"


def test_the_bom_holds_what_the_bench_needs(design):
    from magfab.export import bom
    from magfab.recipes import catalogue

    rows = {r["item"]: r for r in csv.DictReader(io.StringIO(bom.bom_csv(design, ACCEPTANCE)))}
    for item in ("Level shifter", "Solder paste", "Stencil", "Cable", "Reference force sensor", "Indenter", "Stage",
                 "Pad adhesive", "Microcontroller", "Test weight"):
        assert item in rows, item
    assert all(r["source"].strip() for r in rows.values())
    assert list(rows["Hall sensor IC"]) == list(bom.FIELDS)
    assert rows["Test weight"]["part"].startswith("73 g") and "Test weight" not in _bom(design)
    ref = catalogue("bench")["reference-sensor"]
    assert ref["resolution_mN"].nominal == design.spec.calibration.reference_resolution_mN
    disc = float(rows["Indenter"]["part"].split("at least ")[1].split(" mm")[0])
    assert disc >= 2 * design.elastomer_radius_mm + design.spec.calibration.scan_y_mm
    parts = next(s for s in C.sections(design, ACCEPTANCE) if s.title == "Parts")
    assert [r[0] for r in parts.table.rows] == list(rows)


def test_the_acceptance_section_describes_the_drift_steps_with_their_bands(default_build):
    """Turning over and warming (check --rotation --warmup) are described with acceptance.json's bands, as options
    to the check's one command: the bench walk cannot turn or warm its simulated board, so no new command block."""
    import json

    out = default_build.out_dir
    acc = json.loads((out / "calibration" / "acceptance.json").read_text())
    text = (out / "checklist.md").read_text()
    rot, warm = acc["rotation"], acc["warmup"]
    assert "then to turn the sensor over and to warm it" in text
    turned = next(s for s in text.splitlines() if "Turned over:" in s)
    assert f"at most {rot['band_uT']:.0f} uT" in turned and f"{rot['earth_change_uT']:.0f} uT" in turned
    warmed = next(s for s in text.splitlines() if "Warm-up:" in s)
    assert f"at least {warm['min_change_C']:g} C" in warmed and f"{warm['per_C_mN']['with']:.1f} mN per C" in warmed
    check = f"magfab-readout check --weight-g {acc['weight_g']:g} --rotation --warmup --sensor magone-01"
    assert _blocks(text)[-1][0] == check
