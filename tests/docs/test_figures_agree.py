"""One source for every figure: the sample rate, the scan's depth and points, the board's size and the materials
read the same on every page that gives them (README, the spec template `magfab init` writes, the report, the
checklist, the firmware README), because each comes from the number the build itself uses."""

from __future__ import annotations

import json
import re
from pathlib import Path

from magfab.recipes import catalogue
from magfab.spec import default_spec_text

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _text(path: Path) -> str:
    """A page's words: an HTML page without its tags, images and styles, one space between words."""
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".html":
        text = re.sub(r"<(style|script|svg)\b.*?</\1>", " ", text, flags=re.S)
        text = re.sub(r"<[^>]+>", " ", re.sub(r"data:[^\"']+", "", text))
    return re.sub(r"\s+", " ", text.replace("&nbsp;", " "))


def test_the_rate_is_the_firmware_pace_everywhere(default_build):
    """The chip's conversion time (models/chip.py, the datasheet table) paces the firmware; every page gives it."""
    out = default_build.out_dir
    chip = json.loads((out / "predictions.json").read_text())["chip"]
    ms, hz = chip["conversion_ms"], chip["rate_Hz"]
    assert (ms, round(hz)) == (1.84, 543)  # MagOne: OSR 0, DIG_FILT 2
    rate = f"{hz:.0f} Hz"
    pages = {"README.md": README, "magone.toml": default_spec_text(), "report.html": _text(out / "report.html"),
             "firmware/README.md": _text(out / "firmware" / "README.md")}
    for page, text in pages.items():
        assert rate in text, f"{page} does not give the rate as {rate}"
        others = {int(x) for x in re.findall(r"\b(\d{3}) Hz\b", text)} - {round(hz)}
        assert not others, f"{page} gives another sample rate: {others} Hz"
    assert f"{ms:.2f} ms" in README and f"{ms:.2f} ms" in pages["magone.toml"]
    assert f"{ms * 1000:.0f} us" in pages["firmware/README.md"] and f"{ms:.3f} ms" in pages["report.html"]


def test_the_scan_depth_and_points_are_the_scan_plans(default_build):
    """The checklist's scan step, the simulated scan and the predicted range share one depth (models/scan.py)."""
    from magfab.models.scan import scan_plan

    out = default_build.out_dir
    plan = scan_plan(default_build.design, default_build.prediction)
    checklist = _text(out / "checklist.md")
    depths = {f"{plan.depth_mm:.3g} mm of indentation"}
    assert any(d in checklist for d in depths) and f"{plan.points} points" in checklist
    rows = [line for line in (out / "calibration" / "scan_simulated.csv").read_text().splitlines()
            if line and not line.startswith(("#", "time_s"))]
    assert len(rows) == plan.points


def test_the_board_size_is_the_specs(default_build):
    pcb = default_build.spec.pcb
    size = f"{pcb.width_mm:g} x {pcb.height_mm:g} mm"
    for page in ("checklist.md", "report.html"):
        assert size in _text(default_build.out_dir / page), f"{page} does not give the board as {size}"


def test_the_readme_lists_every_recipe_it_offers():
    """The spec's errors offer every catalogue key; the README's recipe list names them all."""
    recipes = README[README.index("Recipes: "):]
    recipes = recipes[:recipes.index("\n\n")]
    for kind in ("materials", "magnets", "chips"):
        for key in catalogue(kind):
            assert key in recipes, f"the README's recipe list lacks {kind} {key!r}"
    assert "Wang et al., *Sensors* 2016, 16(9):1356" in README  # outside references: test_references.py
