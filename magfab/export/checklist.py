"""What a person holds at the bench: the fabrication checklist (Markdown and printable HTML with tick boxes), with
the spec's and the recipes' numbers filled in; the silicone quantities are :mod:`magfab.models.silicone`'s, the bill
of materials is in :mod:`magfab.export.bom`.

Everything here is a pure function of the Design (and the chip's I2C address, the prediction's acceptance
figures); the templates are in ``templates/checklist/``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..board.placement import board_size_mm
from ..board.plan import two_buses
from ..design import PRY_LIP_MM
from ..formats import acceptance_json
from ..models.scan import scan_plan
from ..models.silicone import (
    DEGAS_MIN,
    MIN_BATCH_G,
    MIX_MIN,
    POUR_MIN_PER_CAVITY,
    Quantities,
    quantities,
    silicone_recipe,
)
from ..recipes import Recipe, catalogue
from . import checklist_rp2040 as rp2040_words
from . import firmware, rp2040
from .bom import bom_rows, indenter_disc_mm
from .checklist_array import ADDRESS_HEADER, acceptance_steps, address_rows, calibrate_text, chips_text, magnets_text
from .checklist_array import CALIBRATE_COMMANDS as ARRAY_CALIBRATE_COMMANDS
from .checklist_weights import weights_steps
from .templating import render

if TYPE_CHECKING:
    from ..design import Design
    from ..models.scan import ScanPlan

__all__ = ["Step", "Table", "Section", "sections", "checklist_md", "checklist_html", "FLASH_COMMANDS",
           "sensor_id", "sensor_commands", "calibrate_commands", "acceptance_commands"]

# ---------------------------------------------------------------------------------------------------
# Rendering: sections of imperative steps; a step may end in a ```sh block of commands (run from the build
# folder) and a section may open with a table. Numbers come from the spec, the design or a recipe quantity
# (each with its source in magfab/recipes); provenance stays in the recipes' *_source fields.

#: The bench commands, run from the build folder (the README lists the same). One command per line.
FLASH_COMMANDS = (
    "sh firmware/flash.sh uno /dev/ttyACM0       # a Nano: nano (new bootloader) or nano-old",
    "pip install ./readout",
    "magfab-readout upload",
    "magfab-readout info",
    "magfab-readout stream --zero 200            # Ctrl-C ends it",
)


def sensor_id(design: Design) -> str:
    """The sensor ID the bench commands carry, the first sensor of the design's: its name and ``-01`` (an ID has at
    most 32 characters, docs/sensors.md section 1)."""
    return f"{design.spec.name[:29]}-01"


def sensor_commands(design: Design) -> tuple[str, ...]:
    """The sensor's record started beside the spec, from the build folder: up to the folder ``magfab build`` made it
    in (``build/<name>``, the pipeline's default output folder) and back, as the README runs it."""
    out = f"build/{design.spec.name}"
    return ("cd ../..", f"magfab sensor add {sensor_id(design)} --build {out}", f"cd {out}")


def calibrate_commands(sensor: str) -> tuple[str, ...]:
    """A single taxel's calibration: the recording, the fit into the sensor's record, and onto its board."""
    return ("magfab-readout record scan.csv              # during the scan; Ctrl-C ends it",
            f"magfab calibrate scan.csv --reference reference.csv --sensor {sensor}",
            f"magfab-readout upload --sensor {sensor}",
            "magfab-readout info")


def acceptance_commands(sensor: str, weight_g: float, flags: str) -> tuple[str, ...]:
    """The acceptance test, kept in the sensor's record, and the record's history."""
    return (f"magfab-readout check --weight-g {weight_g:g}{flags} --sensor {sensor}",
            f"magfab sensor show {sensor} --plot {sensor}.png")


@dataclass(frozen=True)
class Step:
    """One tick box: the instruction, then (optional) the commands to type, shown as a ``sh`` block."""

    text: str
    commands: tuple[str, ...] = ()


@dataclass(frozen=True)
class Table:
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class Section:
    title: str
    steps: tuple[Step, ...]
    table: Table | None = None  # shown before the steps


def _section(title: str, steps: Sequence[str | Step], table: Table | None = None) -> Section:
    return Section(title, tuple(s if isinstance(s, Step) else Step(s) for s in steps), table)


def _t(recipe: Recipe, key: str, fallback: str = "") -> str:
    return recipe.texts.get(key, fallback)


def _lc(text: str) -> str:
    """``text`` with its first letter in lower case, to follow a colon."""
    return text[:1].lower() + text[1:]


def _q(recipe: Recipe, key: str) -> float | None:
    return recipe[key].nominal if key in recipe.quantities else None


def _parts_section(design: Design, acceptance: Mapping[str, Any] | None,
                   weighing: Mapping[str, Any] | None = None) -> Section:
    rows = tuple((str(r["item"]), str(r["part"]), f"{r['quantity']:g} {r['unit']}")
                 for r in bom_rows(design, acceptance, weighing))
    return _section("Parts", ["Check you have every part in the table before you start (bom.csv lists the same "
                              "parts with a description and a source for each)."],
                    Table(("item", "part", "quantity"), rows))


def _array_sections(design: Design) -> list[Section]:
    """An array's address plan and orientation, before anything is made (none for a single taxel)."""
    if design.array is None:
        return []

    arr = design.array
    return [_section(f"The array: {len(design.taxels)} taxels, address plan", [
        f"Each taxel is the fingertip of this checklist over its own MLX90393, {arr.pitch_mm:g} mm apart "
        f"({'separate fingertips on one pad' if arr.skin.value == 'separate' else 'one skin holding every magnet'}, "
        f"magnets {arr.polarity.value}). The table is the board's silkscreen, design.json's array and "
        "calibration/array.json: the firmware reads the chips in taxel order.",
        f"Order the chips by the code in the table ({chips_text(design)}): the code sets the chip's I2C base "
        "address and the board's A1/A0 straps the last two bits, so a chip from the wrong reel answers at the wrong "
        "address and the firmware reports that taxel's chip as missing.",
    ], Table(ADDRESS_HEADER, address_rows(design)))]


def _print_section(design: Design) -> Section:
    printer = design.printer
    n = design.spec.fabrication.sensors
    layer = _q(printer, "layer_height_mm")
    wash, post, post_t = (_q(printer, "wash_time_min"), _q(printer, "post_cure_time_min"),
                          _q(printer, "post_cure_temperature_C"))
    dry = _q(printer, "dry_time_min")
    steps = [
        f"Print mould_cup.stl and mould_lid.stl once, and pad.stl {n} time(s), on the {printer.name}, in the poses the "
        f"files are saved in (lid cores up){f', {layer * 1000:g} um layers' if layer else ''}. The thinnest wall is "
        f"{design.wall_mm:g} mm, above the printer's {printer['min_wall_mm'].nominal:g} mm minimum.",
    ]
    if wash is not None:
        steps.append(f"Wash the prints in IPA for {wash:g} min.")
    if _t(printer, "post_process"):
        steps.append(_t(printer, "post_process"))
    if post is not None:
        steps.append((f"Let them dry for at least {dry:g} min, then p" if dry is not None else "P")
                     + f"ost-cure them for {post:g} min" + (f" at {post_t:g} C" if post_t is not None else "") + ".")
    holes = ", ".join(f"{d:g} mm" for _, _, d in design.alignment_holes)
    steps.append(f"Check that a dowel pin goes through each of the pad's alignment holes ({holes}); ream a hole the "
                 "printer closed up.")
    return _section("Print the mould and the pad", steps)


def _prepare_section(design: Design, q: Quantities) -> Section:
    printer = design.printer
    rec = silicone_recipe(design)
    release = design.release_agent
    coats, coat_dry = _q(printer, "barrier_coats"), _q(printer, "barrier_dry_min")
    seal = _t(printer, "barrier_coat")
    if coats is not None and coat_dry is not None:
        seal += f" Use {coats:g} coats, each dried at least {coat_dry:g} min (longer in humid air)."
    if _t(printer, "inhibits_platinum") == "yes":
        seal = "Seal the mould (resin prints can stop platinum silicone curing): " + _lc(seal)
    steps = [seal,
             f"Cast a test patch of {q.material} on an offcut printed and finished like the mould; if it is still "
             f"tacky after {q.cure_time_h:g} h, the surface inhibits the cure: seal it (again) and test once more."]
    rel = f"Release agent, {release.name}: {_lc(_t(release, 'application', 'a light, even coat on cup and lid.'))}"
    rel_dry = _q(release, "dry_time_min")
    steps.append(rel + (f" Let it dry {rel_dry:g} min before you pour." if rel_dry is not None else ""))
    steps.append(_t(rec, "inhibition", "Keep sulfur, latex and tin-cure silicone away from the silicone."))
    return _section("Prepare the mould", steps)


def _mix_section(design: Design, q: Quantities) -> Section:
    rec = silicone_recipe(design)
    n = design.spec.fabrication.sensors
    a_name, b_name = ("part A", "part B") if q.ratio[0] == q.ratio[1] else ("base", "curing agent")
    cup, inhg, extra = (_q(rec, k) for k in ("degas_cup_ratio", "degas_vacuum_inHg", "degas_extra_min"))
    degas = "Degas: " + (f"stand the cup (at least {cup:g} times the mix's volume: it rises) in the vacuum chamber, "
                         f"pull {inhg:g} inHg and hold it until the foam rises, breaks and falls, then {extra:g} min "
                         "more. " if None not in (cup, inhg, extra) else "") + _t(rec, "degas")
    return _section("Weigh, mix and degas", [
        f"Per pour ({q.pours} pour(s) for {n} sensor(s), {q.cavities} cavit{'y' if q.cavities == 1 else 'ies'} each): "
        f"weigh {q.part_a_g:.1f} g of {a_name} and {q.part_b_g:.1f} g of {b_name} of {q.material} "
        f"({q.ratio[0]:g}:{q.ratio[1]:g} by weight; {q.batch_g:.1f} g in all).",
        f"Why that much: one part is {q.part_volume_mL:.3f} mL, the lid's fill and vent holes {q.holes_volume_mL:.3f} "
        f"mL, so the mould holds {q.mould_holds_mL:.3f} mL = {q.mould_holds_mL * q.density_g_cm3:.2f} g at "
        f"{q.density_g_cm3:g} g/cm3, plus {q.waste_pct:g} % for the cup, the stirrer and the overflow"
        + (f" (raised to the {MIN_BATCH_G:g} g smallest batch a 0.1 g scale weighs to 1 %)"
           if q.batch_g <= MIN_BATCH_G else "")
        + ".",
        f"Pot life {q.pot_life_min:g} min: you have about {q.bench_time_min:g} min of work (mix {MIX_MIN:g}, degas "
        f"{DEGAS_MIN:g}, pour {POUR_MIN_PER_CAVITY:g} per cavity). Start the clock when the {b_name} meets the "
        f"{a_name}.",
        f"Mix for {MIX_MIN:g} min, scraping the sides and the bottom of the cup.",
        degas,
    ])


def _pour_section(design: Design, q: Quantities) -> Section:
    cure_at = f" at {q.cure_temperature_C:g} C" if q.cure_temperature_C is not None else ""
    return _section("Pour, cure and demould", [
        "Pour slowly in a thin stream into one side of each cavity, filling it to the brim.",
        "Lower the lid onto its registration pins; the excess rises through the fill hole and the vents.",
        f"Cure for {q.cure_time_h:g} h{cure_at} before opening.",
        f"Lever the lid off at its {PRY_LIP_MM:g} mm overhangs; the part comes out of the cup on its core. Peel it off "
        "the core.",
        "Trim the sprue and vent stubs flush with the base.",
    ])


def _magnet_section(design: Design) -> Section:
    spec = design.spec
    assembly = catalogue("assembly")
    grade = design.magnet_grade
    t_max = grade.max_operating_temp_C.nominal if grade.max_operating_temp_C is not None else None
    if design.array is not None:
        array = [f"Insert {len(design.taxels)} magnets, one per pocket, as below. " + magnets_text(design)]
    else:
        array = []
    return _section("Insert the magnet" + ("s" if array else ""), [
        *array,
        f"Magnet: NdFeB {spec.magnet.grade}, {spec.magnet.diameter_mm:g} mm diameter x {spec.magnet.height_mm:g} mm, "
        "axially magnetised" + (f", {grade.coating} coated" if grade.coating else "") + ".",
        "Polarity: " + _lc(_t(assembly["polarity-check"], "method", "mark each magnet's north face.")),
        _t(assembly["magnet-handling"], "heat", "Keep magnets away from hot steps.")
        + (f" {spec.magnet.grade} is rated {t_max:g} C." if t_max is not None else ""),
        f"Push the magnet, dotted (north) face first, up the insertion channel from the part's base (the silicone "
        f"stretches) until it stops against the pocket's roof, {design.cover_mm:g} mm below the tip. North then faces "
        "the fingertip, away from the chip, the same in every sensor: the chip reads a positive Bz at rest, and the "
        "acceptance test checks the sign.",
    ])


def _solder_section(design: Design) -> Section:
    spec = design.spec
    assembly = catalogue("assembly")
    stencil, reflow = assembly["stencil"], assembly["reflow"]
    coverage = catalogue("land")["tolerances"]["ep_paste_coverage"].nominal
    wire = catalogue("bench")["solder-wire"]
    two = two_buses(design)
    return _section("Solder the board", [
        f"Order the board from pcb/gerbers ({' x '.join(f'{v:g}' for v in board_size_mm(design))} mm, 2 layers, "
        f"{spec.pcb.thickness_mm:g} mm) with a {stencil['thickness_mm'].nominal:g} mm stencil for the top side (the "
        f"F_Paste layer). {_t(stencil, 'perimeter_aperture')}",
        f"{_t(stencil, 'paste')} The chip's exposed pad gets its paste in four apertures ({coverage * 100:.0f} % "
        "coverage) so the chip does not float.",
        f"Print the paste, place {_chips(design)} (pin 1 at the silk arrow) and reflow. {_t(reflow, 'soak')} Peak at "
        f"{reflow['peak_C'].nominal:g} C (never above the package's "
        f"{reflow['package_classification_peak_C'].nominal:g} C), {reflow['time_above_liquidus_s'].nominal:g} s above "
        "liquidus.",
        f"Without a reflow oven, use hot air: {_lc(_t(reflow, 'hot_air_rework'))}",
        "Inspect the chip's sides for bridges. Then solder "
        + ("C1, C2 (100 nF) on the bottom, under the chip" if design.array is None else
           f"C1-C{2 * len(design.taxels)} (100 nF) on the bottom, two under each chip")
        + ((", R1-R4 (pull-ups) behind J1 and J2" if two else ", R1, R2 (pull-ups) behind J1")
           if spec.pcb.pullups else "")
        + (", and J1 and J2 (Qwiic; J2 the second I2C bus)" if two else ", and J1 (Qwiic)")
        + f" on the bottom edge by hand, with {wire.name.split(',')[0].lower()}.",
        f"The board answers at I2C address 0x{design.i2c_address:02X} (A1/A0 strapped on the board)." if design.array
        is None else f"The chips answer at {', '.join(f'0x{t.i2c_address:02X}' for t in design.taxels)} (the address "
        "plan: A1/A0 strapped on the board per chip).",
    ])


def _chips(design: Design) -> str:
    if design.array is None:
        return "U1"

    return f"U1-U{len(design.taxels)} ({chips_text(design)})"


def _assemble_section(design: Design) -> Section:
    glue = design.adhesive
    ca = catalogue("adhesives")["loctite-401"]
    fillet = ca["fillet_mm"].nominal
    bead_ul = 0.5 * fillet * fillet * 2.0 * math.pi * design.pad_radius_mm
    pins = " and ".join(f"{d:g} mm" for _, _, d in design.alignment_holes)
    handling = _q(glue, "cure_time_handling_min")
    full = _q(glue, "cure_time_full_h")
    return _section("Assemble", [
        f"Push the dowel pins ({pins}) into the board's two alignment holes and lower the pad over them and the chip: "
        "the square recess drops over the package, and the holes of different sizes let it fit one way round.",
        f"Fix the pad: hold it flat on the board and run a {fillet:g} mm bead of {ca.name} around its rim where it "
        f"meets the board (about {bead_ul:.0f} uL); keep the glue on the rim, not under the pad, which would lift it. "
        f"Hold it still for {ca['fixture_time_s'].nominal:g} s; the bond reaches full strength in "
        f"{ca['cure_time_full_h'].nominal:g} h.",
        f"Fill the magnet's insertion channel and the funnel with {glue.name} up to the magnet, without bubbles (about "
        f"{design.core_volume_mm3 - design.magnet_volume_mm3:.0f} uL: the channel, funnel and pocket clearance less "
        "the magnet). The predicted force assumes a filled channel (report, the note under the stack-up drawing): "
        f"an open one makes the tip markedly softer. {_t(glue, 'mix')}",
        f"Before that glue sets, spread a thin, even layer of {glue.name} on the elastomer's flat base and press it "
        "onto the pad, inside its lip."
        + (f" Leave it {handling:g} min before handling" if handling is not None else "")
        + (f" and {full:g} h before loading the tip." if full is not None else "."),
    ])


def _wiring_table() -> Table:
    qwiic = catalogue("parts")["jst-sh-4"]
    bench = catalogue("bench")
    ls, uno = bench["level-shifter"], bench["arduino"]
    j1 = {_t(qwiic, f"qwiic_pin_{k}"): f"{_t(qwiic, f'qwiic_pin_{k}')} (pin {k})" for k in range(1, 5)}
    return Table(("breakout J1 (Qwiic)", "level shifter, low side", "level shifter, high side", "Arduino Uno / Nano"), (
        (j1["GND"], _t(ls, "gnd_pin"), _t(ls, "gnd_pin"), _t(uno, "gnd_pin")),
        (j1["3V3"], _t(ls, "lv_pin"), "", _t(uno, "v3_pin")),
        (j1["SDA"], _t(ls, "sda_low_pin"), _t(ls, "sda_high_pin"), f"{_t(uno, 'sda_pin')} (SDA)"),
        (j1["SCL"], _t(ls, "scl_low_pin"), _t(ls, "scl_high_pin"), f"{_t(uno, 'scl_pin')} (SCL)"),
        ("", "", _t(ls, "hv_pin"), _t(uno, "v5_pin")),
    ))


def _wiring_section(design: Design) -> Section:
    if rp2040.is_rp2040(design.spec):
        return _section("Wire the board", rp2040_words.wiring_text(design),
                        Table(rp2040_words.wiring_header(design), rp2040_words.wiring_rows(design)))
    bench = catalogue("bench")
    ls, uno, jumper = bench["level-shifter"], bench["arduino"], bench["qwiic-jumper"]
    vdd = _t(design.chip, "function_VDD", "supply")
    return _section("Wire the board", [
        f"Wire the breakout to the {uno.name} through the {ls.name}, as in the table: the {jumper.name.split(',')[0]} "
        f"into J1, its pins into the shifter's low side, jumper wires from the high side to the Arduino.",
        f"The breakout is a 3.3 V board (the MLX90393's VDD takes {vdd.removeprefix('supply, ')}): its 3V3 and the "
        f"shifter's {_t(ls, 'lv_pin')} take the Arduino's {_t(uno, 'v3_pin')} pin, the shifter's {_t(ls, 'hv_pin')} "
        f"its {_t(uno, 'v5_pin')} pin. Do not connect SDA and SCL straight to the Arduino: at 5 V the ATmega328P's I2C "
        f"inputs need {uno['vih_fraction'].nominal:g} x 5 V = {uno['vih_fraction'].nominal * 5:.2g} V to read a high, "
        f"more than the 3.3 V bus gives.",
    ], _wiring_table())


def _flash_section(design: Design) -> Section:
    flash = Step(rp2040_words.flash_text(design), rp2040_words.flash_commands(design)) if rp2040.is_rp2040(
        design.spec) else Step(
        "Plug the Arduino into this computer and run these from the build folder (the folder holding this "
        f"checklist). They flash firmware/{firmware.HEX_NAME} with avrdude (a Uno as shown; a Nano: nano, or nano-old "
        "for the old bootloader; the last argument is the Arduino's serial port, a COM port on Windows with "
        "firmware\\flash.bat), install the reader with this build's calibration (provisional: fitted to the scan "
        "magfab simulated for the design), write that calibration into the board's EEPROM (the bootloader leaves the "
        "EEPROM empty, and until then the board sends only text error lines naming the missing calibration), check "
        "that the board reports the same calibration hash, and stream "
        f"calibrated forces at {design.spec.firmware.baud} baud, zeroed on the first 200 samples: keep the tip "
        f"untouched while it starts.", FLASH_COMMANDS)
    if design.array is not None:
        return _section("Flash and read", [flash])
    sensor = sensor_id(design)
    return _section("Flash and read", [Step(
        f"Give the sensor an ID and write it on the board's label: {sensor} here, {sensor[:-2]}02 for the next sensor "
        f"of this design, and so on (yours in place of {sensor} in the commands below). Start its record in sensors/ "
        "beside the spec, outside every build folder: it keeps what the sensor was made from and every measurement "
        "made on it, and a rebuild, which replaces the build folder, never touches it. The lines below go to the "
        "folder you built in (two up from this one, for a build in its default place), add the record, and come "
        "back; the later commands find sensors/ from here.",
        sensor_commands(design)), flash])


def _calibrate_section(design: Design, plan: ScanPlan | None) -> Section:
    cal = design.spec.calibration
    bench = catalogue("bench")
    ref, stage = bench["reference-sensor"], bench["stage"]
    if plan is None:  # no prediction to cap it: the spec's extent

        plan = scan_plan(design)
    disc = indenter_disc_mm(design, plan.y_half_mm)
    scan = ("From the build folder: start the reference log and the recording (the first line below), run the scan, "
            "and end both when it is done. The recording's host_time_s column is this computer's clock too, which "
            "is how calibrate pairs each sample with the reference's force. Then fit the calibration to the "
            f"reference (order {cal.order}, {cal.method.value}, {cal.folds}-fold held-out error, tolerance "
            f"{cal.tolerance_mN:g} mN)")
    if design.array is not None:
        run = Step(calibrate_text(design, scan), ARRAY_CALIBRATE_COMMANDS)
    else:
        run = Step(scan + ", which goes into the sensor's record with the scan and the reference log (the build folder "
                   "keeps its provisional calibration), and upload it with the sensor's ID into the board's EEPROM (no "
                   "compiler, no reflash): the board then names the sensor and the calibration's date.",
                   calibrate_commands(sensor_id(design)))
    return _section("Calibrate", [
        f"Build the rig: the {ref.name} (resolution {cal.reference_resolution_mN:g} mN, the figure the simulated scan "
        f"assumed) on a {_lc(stage.name)} graduated in "
        f"{plan.step_mm * stage['graduation_fraction'].nominal * 1000:g} um or finer, a flat rigid disc at least "
        f"{disc:.3g} mm across on its tool side, the fingertip under it.",
        "Log the reference sensor on this computer as reference.csv, with the columns time_s (seconds since the Unix "
        "epoch on this computer's clock, as Python's time.time() gives), Fx_N, Fy_N and Fz_N (the sensor's frame: +z "
        "presses the tip towards the chip).",
        f"The track to scan: {2.0 * plan.y_half_mm:.3g} mm in y centred on the axis (set by {plan.y_end}) and "
        f"{plan.depth_mm:.3g} mm of indentation (set by {plan.depth_end}; the simulated scan and the predicted range "
        f"stop there too), in {plan.step_mm * 1000:g} um steps ({plan.points} points).",
        run,
    ])


def _acceptance_section(acceptance: Mapping[str, Any] | None, design: Design) -> Section:
    doc = acceptance or {}
    rest, weight, delta = doc.get("rest_Bz_uT"), doc.get("weight_g"), doc.get("delta_Bz_uT")
    if design.array is not None:
        return _section("Acceptance test", acceptance_steps(design, float(weight or 50)))
    if not (rest and weight and delta):
        return _section("Acceptance test", [
            "This build has no acceptance bands (no calibration/acceptance.json: the prediction gave no weight that "
            "fits the range), so there is no check to run; compare the streamed forces with a known weight by hand."])
    w = float(weight)
    flags = acceptance_json.drift_flags(doc)
    then = " then to turn the sensor over and to warm it (below)," if flags else ""
    return _section("Acceptance test", [
        Step(f"From the build folder, with nothing touching the tip, run the check: it reads the field at rest, then "
             f"asks you to put the {w:g} g weight on the tip,{then} waiting for Enter at each step. Its result goes "
             "into the sensor's record; the record's history follows, as a table and as a chart.",
             acceptance_commands(sensor_id(design), w, flags)),
        f"Pass: Bz at rest within {rest[0]:.0f} to {rest[1]:.0f} uT (positive: magnet the right way up), and a {w:g} g "
        f"weight raises Bz by {delta[0]:.0f} to {delta[1]:.0f} uT.",
        "A fail names the step and the measured and predicted values: a weak or strong field points at the magnet "
        "grade or the stack-up, a negative one at an upside-down magnet, a small rise at a stiff batch of silicone.",
        *_drift_steps(doc),
    ])


def _drift_steps(acceptance: Mapping[str, Any]) -> list[str]:
    """The check's turn-over and warm-up steps (magfab.models.acceptance_steps), when acceptance.json has them."""
    rot, warm = acceptance.get("rotation"), acceptance.get("warmup")
    if not rot and not warm:
        return []
    out = ["Drift (after the weight is off): the check's last steps, each when it asks."]
    if rot:
        force = "" if rot.get("predicted_normal_rest_mN") is None else (
            f"; the force it reads changes by about {rot['predicted_normal_rest_mN']:.0f} mN from the Earth's field at "
            f"most and {rot['self_weight_mN']:.0f} mN from the tip's own weight")
        out.append(f"Turned over: turn the whole sensor (board and fingertip) upside down, nothing touching the tip. "
                   f"Pass: the field changes by at most {rot['band_uT']:.0f} uT (the Earth's field turned over, "
                   f"{rot['earth_change_uT']:.0f} uT, and the fingertip's own weight reversed, "
                   f"{rot['self_weight_change_uT']:.0f} uT){force}. More means the magnet moved: loose in its pocket "
                   "(glue it in), or steel or magnetised parts near the sensor turned with it.")
    if warm:
        per_C = warm["per_C_mN"]
        out.append(f"Warm-up: warm the sensor by at least {warm['min_change_C']:g} C, nothing touching the tip (hold "
                   "the board, not the fingertip, in your hand, or power it up from cold). Pass: the rest force moves "
                   f"by at most {per_C['with']:.1f} mN per C with the recipe's temperature coefficients "
                   f"({per_C['fitted']:.1f} mN/C when the calibration fitted them; {per_C['without']:.1f} mN/C "
                   "uncorrected; the drift budget's worst-case calibration, which the check rescales to this one's "
                   "force per field). More means the board runs a calibration without its temperature correction "
                   "(upload it again) or a magnet of another material.")
    return out


def sections(design: Design, acceptance: Mapping[str, Any] | None = None,
             plan: ScanPlan | None = None, weighing: Mapping[str, Any] | None = None) -> list[Section]:
    """The checklist as :class:`Section` s of :class:`Step` s: plain text with the spec's, the design's and the
    recipes' numbers filled in; the Markdown and HTML templates only lay it out (and escape it). ``plan``: the
    calibration scan's extent (:func:`magfab.models.scan.scan_plan`; omitted, the spec's); ``weighing``: the weight
    plan (calibration/weigh_plan.json), whose section follows the scan's."""
    q = quantities(design)
    weights = weights_steps(design, weighing, sensor_id(design))
    return [_parts_section(design, acceptance, weighing), *_array_sections(design), _print_section(design),
            _prepare_section(design, q), _mix_section(design, q), _pour_section(design, q), _magnet_section(design),
            _solder_section(design), _assemble_section(design), _wiring_section(design), _flash_section(design),
            _calibrate_section(design, plan),
            *([_section("Calibrate with weights (no force sensor)", weights)] if weights else []),
            _acceptance_section(acceptance, design)]


def checklist_md(design: Design, acceptance: Mapping[str, Any] | None = None,
                 plan: ScanPlan | None = None, weighing: Mapping[str, Any] | None = None) -> str:
    return render("checklist/checklist.md.j2", spec=design.spec, q=quantities(design),
                  sections=sections(design, acceptance, plan, weighing))


def checklist_html(design: Design, acceptance: Mapping[str, Any] | None = None,
                   plan: ScanPlan | None = None, weighing: Mapping[str, Any] | None = None) -> str:
    return render("checklist/checklist.html.j2", spec=design.spec, q=quantities(design),
                  sections=sections(design, acceptance, plan, weighing))
