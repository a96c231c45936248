"""The bill of materials (bom.csv): one row per item, quantities for ``fabrication.sensors``, each with the
source its choice or figure comes from (a recipe in ``magfab/recipes`` or the build's own files)."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ..board.placement import board_size_mm
from ..board.plan import two_buses
from ..models.silicone import quantities
from ..recipes import catalogue
from ..reference_chip import reference_chip
from . import rp2040
from .checklist_weights import jig_rows

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["FIELDS", "bom_rows", "bom_csv"]

FIELDS = ("item", "part", "description", "quantity", "unit", "source")

#: Solder paste per board: a 0.125 mm stencil over the chip's lands prints a few mm3; a syringe is the
#: smallest unit sold, so the BOM asks for one syringe whatever the count.
_PASTE_UNIT = "syringe"


def indenter_disc_mm(design: Design, y_half_mm: float) -> float:
    """The least diameter of the flat indenter: it covers the tip over a scan reaching ``y_half_mm`` off the
    axis, with the recipe's margin."""
    return 2.0 * (design.elastomer_radius_mm + y_half_mm + catalogue("bench")["indenter"]["margin_mm"].nominal)


def _row(item: str, part: str, description: str, quantity: float, unit: str, source: str) -> dict[str, object]:
    return {"item": item, "part": part, "description": description, "quantity": quantity, "unit": unit,
            "source": source}


def _chip_rows(design: Design) -> list[dict[str, object]]:
    """The Hall chips, one row per option code: the order number's suffix sets the I2C base address, so an array
    of more than four chips orders two or more codes (the address plan of design.json)."""
    n = design.spec.fabrication.sensors
    source = "Melexis MLX90393 datasheet, ordering information; recipes/chips.toml"
    ref = reference_chip(design)
    extra = [] if ref is None else [_row(
        "Hall sensor IC", f"MLX90393SLW-ABA-{ref.option_code}-RE", f"Melexis MLX90393, QFN-16 3x3 mm, option code "
        f"{ref.option_code}: {ref.designator}, the reference chip (0x{ref.i2c_address:02X}, reads stray fields, no "
        "magnet)",
        n, "pcs", source)]
    if design.array is None:
        code = design.spec.sensor.option_code
        return [_row("Hall sensor IC", f"MLX90393SLW-ABA-{code}-RE", f"Melexis MLX90393, QFN-16 3x3 mm, option code "
                     f"{code} (I2C base for address 0x{design.i2c_address:02X})", n, "pcs", source), *extra]
    rows = []
    for code in design.array.option_codes:
        chips = [t for t in design.taxels if t.option_code == code]
        where = ", ".join(f"U{t.index + 1} (taxel {t.index}, 0x{t.i2c_address:02X})" for t in chips)
        rows.append(_row("Hall sensor IC", f"MLX90393SLW-ABA-{code}-RE", f"Melexis MLX90393, QFN-16 3x3 mm, option "
                         f"code {code}: {where}", len(chips) * n, "pcs", source))
    return rows + extra


def _sensor_rows(design: Design) -> list[dict[str, object]]:
    """The parts of the sensor itself: chip, magnet, silicone, glues, board and its parts, prints."""
    spec = design.spec
    n = spec.fabrication.sensors
    q = quantities(design)
    parts, assembly = catalogue("parts"), catalogue("assembly")
    pcb = spec.pcb
    glue, release, ca = design.adhesive, design.release_agent, catalogue("adhesives")["loctite-401"]
    stencil = assembly["stencil"]
    coating = design.magnet_grade.coating
    taxels = len(design.taxels)
    chips = taxels + (design.spec.reference is not None)
    width, height = board_size_mm(design)
    rows = [
        *_chip_rows(design),
        _row("Magnet", f"NdFeB {spec.magnet.grade} disc {spec.magnet.diameter_mm:g} x {spec.magnet.height_mm:g} mm",
             "axially magnetised" + (f", {coating} coated" if coating else "")
             + (f"; {taxels} per sensor" if taxels > 1 else ""), taxels * n, "pcs",
             "spec magnet; recipes/magnets.toml (remanence), recipes/assembly.toml (coating)"),
        _row("Silicone", q.material, f"mix {q.ratio[0]:g}:{q.ratio[1]:g} by weight; {q.total_g:.1f} g in {q.pours} "
             f"pour(s) including {q.waste_pct:g} % waste", round(q.total_g, 1), "g",
             "recipes/materials.toml (manufacturer's technical bulletin); quantity from the mould's volume"),
        _row("Adhesive", glue.name, "seals the magnet in its channel and glues the elastomer to the pad", 1, "tube",
             "recipes/adhesives.toml " + glue.key),
        _row("Pad adhesive", ca.name, "fixes the printed pad to the board", 1, "bottle",
             "recipes/adhesives.toml loctite-401 (LOCTITE 401 technical data sheet)"),
        _row("Release agent", release.name, "on the mould before every pour", 1, "can",
             "recipes/adhesives.toml " + release.key),
        _row("Sealer", "clear acrylic spray", "barrier coat in the mould's cavities against cure inhibition", 1, "can",
             "recipes/printers.toml barrier_coat (Smooth-On FAQ 129)"),
        _row("PCB", f"{spec.name} breakout {width:g} x {height:g} mm",
             f"2 layers, {pcb.thickness_mm:g} mm FR-4, from pcb/gerbers", n, "pcs", "pcb/gerbers (this build)"),
        _row("Stencil", f"top-side solder-paste stencil, {stencil['thickness_mm'].nominal:g} mm stainless",
             "laser-cut from pcb/gerbers F_Paste, for the chip", 1, "pcs",
             "recipes/assembly.toml stencil (Silicon Labs QFN stencil notes)"),
        _row("Solder paste", "no-clean SAC305, Type 3 or finer", "printed through the stencil for the chip", 1,
             _PASTE_UNIT, "recipes/assembly.toml stencil.paste (Silicon Labs QFN stencil note 9)"),
        _row("Solder wire", catalogue("bench")["solder-wire"].name, "the bottom-side parts, by hand", 1, "reel",
             "recipes/bench.toml solder-wire"),
        _row("Capacitor", "100 nF 0603 X7R", "C1, C2: VDD and VDDIO decoupling" if chips == 1 else
             f"VDD and VDDIO decoupling, two per chip (C1-C{2 * chips})", 2 * chips * n, "pcs",
             "pcb/ (this build): one on each supply pin"),
    ]
    buses = two_buses(design)
    if pcb.pullups:
        ohm = parts["jst-sh-4"]["pullup_ohm"].nominal
        rows.append(_row("Resistor", f"{ohm / 1000:g} kOhm 0603 1 %",
                         "R1-R4: I2C pull-ups, two a bus" if buses else "R1, R2: I2C pull-ups", (4 if buses else 2) * n,
                         "pcs", "recipes/parts.toml jst-sh-4 pullup_ohm (SparkFun Qwiic boards)"))
    rows += [
        _row("Connector", "JST SM04B-SRSS-TB", "J1, J2: Qwiic (SH 1.0 mm, 4 pins), one a bus" if buses else
             "J1: Qwiic (SH 1.0 mm, 4 pins)", (2 if buses else 1) * n, "pcs",
             "recipes/parts.toml jst-sh-4 (JST SH catalogue)"),
        _row("Dowel pins", "; ".join(f"{d:g} mm x {pcb.thickness_mm + design.pad_thickness_mm:g} mm"
                                     for _, _, d in design.alignment_holes),
             "align the pad on the board (one hole of each size)", n, "sets",
             "design.json alignment holes (this build)"),
    ]
    if pcb.mounting_hole_diameter_mm > 0:
        rows.append(_row("Screws", "M2 x 6 mm", "mount the board (H3, H4)", 2 * n, "pcs",
                         "recipes/parts.toml npth (ISO 273 clearance for M2)"))
    rows += [
        _row("Printed mould", "mould_cup.stl + mould_lid.stl",
             f"{design.printer.name}; {design.cavities} cavit{'y' if design.cavities == 1 else 'ies'}", 1, "set",
             "this build; recipes/printers.toml"),
        _row("Printed pad", "pad.stl", design.printer.name, n, "pcs", "this build; recipes/printers.toml"),
    ]
    return rows


def _reader_rows(design: Design) -> list[dict[str, object]]:
    """The readout board and what wires it to the breakout: an Arduino through a level shifter (the ATmega328P's
    I2C inputs need 0.7 x 5 V), or a 3.3 V RP2040 board straight, by a Qwiic cable into its STEMMA QT socket or a
    Qwiic-to-pins cable where it has none."""
    n = design.spec.fabrication.sensors
    bench = catalogue("bench")
    board = rp2040.readout_board(design.spec)
    if board.texts["mcu"] == "rp2040":
        key = rp2040.board_key(design.spec)
        socket = board.texts["connector"] == "stemma-qt"
        cable = bench["qwiic-cable" if socket else "qwiic-jumper"]
        second = [_row("Cable", bench["qwiic-jumper"].name, f"from J2 (the second I2C bus) to the board's pins "
                       f"({board.texts['sda_b_pin']}, {board.texts['scl_b_pin']}; its 3.3 V and GND wires taped off)",
                       n, "pcs", "recipes/bench.toml qwiic-jumper (SparkFun Qwiic connect system)")
                  ] if two_buses(design) else []
        return [
            _row("Microcontroller", board.name, f"runs firmware/{rp2040.image_name(key)}", n, "pcs",
                 f"recipes/boards.toml {key}"),
            _row("Cable", cable.name, "from J1 to the board's STEMMA QT socket" if socket else
                 f"from J1 to the board's pins ({board.texts['sda_pin']}, {board.texts['scl_pin']}, 3.3 V, GND)", n,
                 "pcs", f"recipes/bench.toml {'qwiic-cable' if socket else 'qwiic-jumper'} (SparkFun Qwiic connect "
                 "system)"),
            *second,
        ]
    return [
        _row("Microcontroller", bench["arduino"].name, "runs firmware/magfab-atmega328p.hex", n, "pcs",
             "recipes/bench.toml arduino (Arduino Wire reference, Uno Rev3 specifications)"),
        _row("Level shifter", bench["level-shifter"].name, "I2C between the 3.3 V breakout and the 5 V Arduino", n,
             "pcs", "recipes/bench.toml level-shifter (Pololu 2595; NXP AN10441 circuit)"),
        _row("Cable", bench["qwiic-jumper"].name, "from J1 to the level shifter's low side", n, "pcs",
             "recipes/bench.toml qwiic-jumper (SparkFun Qwiic connect system)"),
        _row("Jumper wires", "male-female 0.1 in jumper wires", "level shifter's high side to the Arduino", 4 * n,
             "pcs", "the wiring table in checklist.md"),
    ]


def _bench_rows(design: Design, acceptance: Mapping[str, Any] | None) -> list[dict[str, object]]:
    """What reads, wires and calibrates the sensor: the readout board and its wiring, the calibration rig
    and the acceptance test's weight (when the build has acceptance bands)."""
    bench = catalogue("bench")
    cal = design.spec.calibration
    disc = indenter_disc_mm(design, cal.scan_y_mm / 2.0)
    rows = [
        *_reader_rows(design),
        _row("Reference force sensor", bench["reference-sensor"].name,
             f"the calibration's reference, resolution {cal.reference_resolution_mN:g} mN", 1, "pcs",
             "recipes/bench.toml reference-sensor (ATI Nano17 calibration table)"),
        _row("Indenter", f"flat rigid disc, at least {math.ceil(disc):g} mm across",
             "on the reference sensor's tool side; covers the tip over the whole scan", 1, "pcs",
             "recipes/bench.toml indenter (the FE's flat indenter)"),
        _row("Stage", bench["stage"].name,
             f"moves the indenter in {cal.scan_step_mm * 1000:g} um steps; graduations "
             f"{cal.scan_step_mm * bench['stage']['graduation_fraction'].nominal * 1000:g} um or finer", 1, "pcs",
             "recipes/bench.toml stage (spec calibration.scan_step_mm)"),
    ]
    weight = acceptance.get("weight_g") if acceptance else None
    if weight:
        rows.append(_row("Test weight", f"{float(weight):g} g calibration weight",
                         "the acceptance test's known weight", 1, "pcs",
                         "calibration/acceptance.json weight_g (this build)"))
    return rows


def bom_rows(design: Design, acceptance: Mapping[str, object] | None = None,
             weighing: Mapping[str, Any] | None = None) -> list[dict[str, object]]:
    """The bill of materials: one row per item (:data:`FIELDS`), quantities for ``fabrication.sensors``;
    ``acceptance`` (acceptance.json's content) adds the acceptance test's weight, ``weighing`` (the weight plan,
    calibration/weigh_plan.json) the weight jig, its coins and a balance."""
    return _sensor_rows(design) + _bench_rows(design, acceptance) + jig_rows(weighing, _row)


def bom_csv(design: Design, acceptance: Mapping[str, object] | None = None,
            weighing: Mapping[str, Any] | None = None) -> str:
    out = io.StringIO()
    w = csv.DictWriter(out, fieldnames=list(FIELDS), lineterminator="\n")
    w.writeheader()
    for row in bom_rows(design, acceptance, weighing):
        w.writerow(row)
    return out.getvalue()
