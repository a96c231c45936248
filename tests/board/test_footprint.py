"""Land patterns: the IPC-7351B equations, KiCad's own library as the reference, golden footprint files.

Regenerate the golden files after an intended change with

    MAGFAB_REGEN_GOLDEN=1 python -m pytest tests/board/test_footprint.py -k golden
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from types import MappingProxyType

import pytest
from conftest import require_kicad, require_kicad_library

from magfab.board.footprint import Band, chip_footprint, connector_footprint, ipc_land, qfn_footprint
from magfab.export.kicad import run_tool
from magfab.recipes import Quantity, Recipe, catalogue
from magfab.spec import Density

GOLDEN = Path(__file__).with_name("golden")
QFN_LIB = "Package_DFN_QFN.pretty"


def _generic_qfn16() -> Recipe:
    """A generic QFN-16 3x3 mm 0.5 mm-pitch part: the ST TSV521 outline KiCad's library footprint
    QFN-16-1EP_3x3mm_P0.5mm_EP1.7x1.7mm was generated from (kicad-footprint-generator size definition
    qfn-1x.yaml)."""
    src = "ST TSV521 datasheet QFN16 3x3 outline, as in kicad-footprint-generator qfn-1x.yaml"
    q = {
        "body_mm": Quantity(3.0, 2.9, 3.1, src), "height_mm": Quantity(0.9, 0.8, 1.0, src),
        "pitch_mm": Quantity(0.5, 0.5, 0.5, src), "terminal_length_mm": Quantity(0.4, 0.3, 0.5, src),
        "terminal_width_mm": Quantity(0.25, 0.18, 0.3, src), "exposed_pad_mm": Quantity(1.7, 1.7, 1.7, src),
    }
    texts = {"name": "generic QFN-16 3x3", **{f"pin_{i}": f"P{i}" for i in range(1, 17)}}
    return Recipe("generic-qfn16", MappingProxyType(q), MappingProxyType(texts))


def test_ipc_equations_by_hand():
    # Z = 2.9 + 2*0.3 + sqrt(0.2^2 + 0.1^2 + 0.05^2) = 3.729 -> 3.75
    # S_max,rms = 2.5 - (0.6 - sqrt(0.12))/2 = 2.3732;  G = 2.3732 - sqrt(0.12 + 0.0125) = 2.0092 -> 2.00
    # X = 0.18 - 0.08 + sqrt(0.12^2 + 0.0125) = 0.2640 -> 0.25
    land = catalogue("land")
    got = ipc_land(Band(2.9, 3.0, 3.1), Band(0.3, 0.4, 0.5), Band(0.18, 0.25, 0.3), land["qfn-nominal"],
                   land["tolerances"])
    assert (got.z_max, got.g_min, got.x_max) == (3.75, 2.0, 0.25)
    s_rms = math.sqrt(0.2**2 + 2 * 0.2**2)
    raw_g = 2.5 - (0.6 - s_rms) / 2 - math.sqrt(s_rms**2 + 0.1**2 + 0.05**2)
    assert abs(raw_g - 2.0092) < 1e-3


def test_density_levels_order_the_lands():
    chip = catalogue("chips")["mlx90393"]
    pads = {d: qfn_footprint(chip, d).pads[0] for d in Density}
    outer = {d: -p.x + p.w / 2 for d, p in pads.items()}
    assert outer[Density.LEAST] < outer[Density.NOMINAL] < outer[Density.MOST]
    courts = {d: qfn_footprint(chip, d).courtyard[2] for d in Density}
    assert courts[Density.LEAST] < courts[Density.NOMINAL] < courts[Density.MOST]


def test_qfn_lands_clear_the_exposed_pad_and_each_other():
    fp = qfn_footprint(catalogue("chips")["mlx90393"])
    copper = fp.copper_pads()
    assert len(copper) == 17
    ep = copper[-1]
    for p in copper[:-1]:
        x0, y0, x1, y1 = p.box()
        gap_x = max(ep.box()[0] - x1, x0 - ep.box()[2])
        gap_y = max(ep.box()[1] - y1, y0 - ep.box()[3])
        assert max(gap_x, gap_y) >= 0.2 - 1e-9  # min_ep_to_pad_clearance
    pitch_gap = 0.5 - copper[0].h
    assert pitch_gap >= 0.2  # solder-mask web between lands


def _kicad_pads(lib: str, name: str) -> list[dict]:
    require_kicad()
    return json.loads(run_tool("footprint", lib, name))["pads"]


def _compare(ours, theirs: list[dict], tol: float = 0.05) -> float:
    """Largest position/size difference between matching copper pads (matched by number and position)."""
    mine = sorted((p for p in ours.pads if p.copper), key=lambda p: (p.number, p.x, p.y))
    theirs = sorted((p for p in theirs if any(layer.endswith("Cu") for layer in p["layers"])),
                    key=lambda p: (p["number"], p["x"], p["y"]))
    assert [p.number for p in mine] == [p["number"] for p in theirs]
    worst = 0.0
    for a, b in zip(mine, theirs):
        worst = max(worst, abs(a.x - b["x"]), abs(a.y - b["y"]), abs(a.w - b["w"]), abs(a.h - b["h"]))
    assert worst <= tol, worst
    return worst


def test_generic_qfn16_reproduces_kicads_library_footprint():
    lib = os.path.dirname(require_kicad_library(f"{QFN_LIB}/QFN-16-1EP_3x3mm_P0.5mm_EP1.7x1.7mm.kicad_mod"))
    theirs = _kicad_pads(lib, "QFN-16-1EP_3x3mm_P0.5mm_EP1.7x1.7mm")
    ours = qfn_footprint(_generic_qfn16())
    assert _compare(ours, theirs) <= 0.05
    paste_theirs = sorted((p["x"], p["y"], p["w"]) for p in theirs if p["layers"] == ["F.Paste"])
    paste_ours = sorted((p.x, p.y, p.w) for p in ours.pads if p.layers == ("F.Paste",))
    assert len(paste_ours) == len(paste_theirs) == 4
    for a, b in zip(paste_ours, paste_theirs):
        assert a == pytest.approx(b, abs=0.01)


def test_0603_and_qwiic_connector_match_kicads_library():
    cap = os.path.dirname(require_kicad_library("Capacitor_SMD.pretty/C_0603_1608Metric.kicad_mod"))
    _compare(chip_footprint(catalogue("parts")["chip-0603"]), _kicad_pads(cap, "C_0603_1608Metric"))
    name = "JST_SH_SM04B-SRSS-TB_1x04-1MP_P1.00mm_Horizontal"
    jst = os.path.dirname(require_kicad_library(f"Connector_JST.pretty/{name}.kicad_mod"))
    _compare(connector_footprint(catalogue("parts")["jst-sh-4"]), _kicad_pads(jst, name))


def test_our_library_footprint_loads_in_kicad(tmp_path):
    fp = qfn_footprint(catalogue("chips")["mlx90393"])
    lib = tmp_path / "magfab.pretty"
    lib.mkdir()
    (lib / f"{fp.name}.kicad_mod").write_text(fp.library_text())
    pads = _kicad_pads(str(lib), fp.name)
    _compare(fp, pads, tol=1e-6)
    assert sum(1 for p in pads if p["layers"] == ["F.Paste"]) == 4


FOOTPRINTS = {
    "mlx90393_qfn16.kicad_mod": lambda: qfn_footprint(catalogue("chips")["mlx90393"]),
    "chip_0603.kicad_mod": lambda: chip_footprint(catalogue("parts")["chip-0603"]),
    "jst_sh_4.kicad_mod": lambda: connector_footprint(catalogue("parts")["jst-sh-4"]),
}


@pytest.mark.parametrize("name", sorted(FOOTPRINTS))
def test_golden_footprints(name):
    text = FOOTPRINTS[name]().library_text()
    path = GOLDEN / name
    if os.environ.get("MAGFAB_REGEN_GOLDEN") == "1":
        path.write_text(text)
    assert path.exists(), f"no golden file {path}; run with MAGFAB_REGEN_GOLDEN=1"
    assert text == path.read_text(), f"{name} differs from its golden file (regenerate if intended)"


def test_footprint_text_is_deterministic():
    a = qfn_footprint(catalogue("chips")["mlx90393"]).library_text()
    b = qfn_footprint(catalogue("chips")["mlx90393"]).library_text()
    assert a == b and "tstamp" not in a
