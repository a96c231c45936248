"""Every printable STL slices in the real PrusaSlicer command line, as the printer kind asks: the mould and the pad on
the spec's printer; the weight jig on a filament printer, whatever the spec's (its cap is wider than a small resin
printer's display, and it needs no resin's detail)."""

from __future__ import annotations

import subprocess

import pytest
from conftest import require_tool

from magfab import build, parse_spec

PRINTED = ("mould_cup", "mould_lid", "pad")
JIG = ("weigh_cap", "weigh_stand_0", "weigh_stand_20", "weigh_stand_40")


def _slice(slicer: str, stl, technology: str, tmp_path):
    if technology == "sla":
        args = [slicer, "--printer-technology", "SLA", "--export-sla", "--output", str(tmp_path / f"{stl.stem}.sl1")]
    else:
        args = [slicer, "--printer-technology", "FFF", "--export-gcode", "--output",
                str(tmp_path / f"{stl.stem}.gcode")]
    proc = subprocess.run([*args, str(stl)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    out = tmp_path / (stl.stem + (".sl1" if technology == "sla" else ".gcode"))
    assert out.stat().st_size > 1000
    return out


@pytest.mark.parametrize("stem", PRINTED)
def test_default_sla_parts_slice(default_build, stem, tmp_path):
    slicer = require_tool("prusa-slicer")
    _slice(slicer, default_build.out_dir / f"{stem}.stl", "sla", tmp_path)


@pytest.mark.parametrize("stem", JIG)
def test_the_default_builds_jig_slices_for_a_filament_printer(default_build, stem, tmp_path):
    slicer = require_tool("prusa-slicer")
    text = _slice(slicer, default_build.out_dir / f"{stem}.stl", "fdm", tmp_path).read_text(errors="replace")
    assert "G1" in text and ";LAYER_CHANGE" in text


@pytest.mark.parametrize("stem", PRINTED + JIG)
def test_fdm_parts_slice_to_gcode(stem, tmp_path_factory, tmp_path):
    slicer = require_tool("prusa-slicer")
    out = tmp_path_factory.getbasetemp() / "fdm-build"
    if not out.exists():
        build(parse_spec('name = "fdm"\n[mould]\nprinter = "fdm"\ncavities = 2'), out)
    gcode = _slice(slicer, out / f"{stem}.stl", "fdm", tmp_path)
    text = gcode.read_text(errors="replace")
    assert "G1" in text and ";LAYER_CHANGE" in text
