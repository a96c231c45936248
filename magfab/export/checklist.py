"""What a person holds at the bench: silicone quantities, the fabrication checklist (Markdown and printable
HTML with tick boxes), with the spec's and the recipes' numbers filled in; the bill of materials is in
:mod:`magfab.export.bom` (re-exported here).

Everything here is a pure function of the Design (and the chip's I2C address, the prediction's acceptance
figures); the templates are in ``templates/checklist/``.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Mapping

from ..errors import Finding, Severity, SpecError
from ..recipes import Recipe, catalogue
from .bom import bom_csv, bom_rows  # re-exported: pipeline.py writes bom.csv through this module

if TYPE_CHECKING:
    from ..models.scan import ScanPlan
    from ..design import Design

__all__ = ["Quantities", "quantities", "mix_ratio", "sections", "checklist_md", "checklist_html", "bom_rows", "bom_csv",
           "findings"]

#: Minutes at the bench per pour, before the silicone is in the mould: weigh and mix (3), degas (5), pour
#: and close the lid (2 per cavity). Our estimate of a careful first-timer; checked against the pot life.
MIX_MIN, DEGAS_MIN, POUR_MIN_PER_CAVITY = 3.0, 5.0, 2.0
#: Lowest total mass weighed per batch: a 0.1 g kitchen scale then errs by at most 1 % per part.
MIN_BATCH_G = 10.0


def mix_ratio(text: str, where: str) -> tuple[float, float]:
    """(A, B) parts by weight from a recipe's ratio text: "1A:1B", "10:1 (base : curing agent)", "100A:42B"."""
    m = re.match(r"\s*(\d+(?:\.\d+)?)\s*A?\s*:\s*(\d+(?:\.\d+)?)", text)
    if not m:
        raise SpecError(where, text, "must start with a ratio like 1A:1B or 10:1")
    return float(m.group(1)), float(m.group(2))


@dataclass(frozen=True)
class Quantities:
    """Silicone per pour and in all, g; times, min."""

    material: str
    sensors: int
    cavities: int
    pours: int
    part_volume_mL: float  # one cast part (the cavity minus the pocket core)
    holes_volume_mL: float  # the lid's fill and vent holes, filled to the top, per pour
    mould_holds_mL: float  # per pour
    density_g_cm3: float
    waste_pct: float
    batch_g: float  # mixed per pour
    part_a_g: float
    part_b_g: float
    ratio: tuple[float, float]
    total_g: float  # over all pours
    pot_life_min: float
    bench_time_min: float  # weigh, mix, degas and pour one batch
    cure_time_h: float
    cure_temperature_C: float | None

    def as_dict(self) -> dict[str, object]:
        return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in asdict(self).items()}


def _silicone(design: "Design") -> Recipe:
    return catalogue("materials")[design.spec.elastomer.material]


def _override(value: float | None, recipe: Recipe, key: str, spec_key: str) -> float:
    if value is not None:
        return float(value)
    if key not in recipe.quantities:
        raise SpecError(spec_key, "(recipe)", f"is needed: recipes/materials.toml gives no {key} for "
                        f"{recipe.key!r}, so set it in the spec")
    return recipe[key].nominal


def quantities(design: "Design") -> Quantities:
    """How much silicone to weigh per pour and in all (cavities, the lid's holes, the waste allowance)."""
    spec = design.spec
    fab = spec.fabrication
    rec = _silicone(design)
    density = _override(fab.density_g_cm3, rec, "density_g_cm3", "fabrication.density_g_cm3")
    pot = _override(fab.pot_life_min, rec, "pot_life_min", "fabrication.pot_life_min")
    cure = _override(fab.cure_time_h, rec, "cure_time_h", "fabrication.cure_time_h")
    ratio = mix_ratio(rec.texts.get("mix_ratio_by_weight", ""), f"recipes/materials.toml:{rec.key}.mix_ratio_by_weight")
    cavities = spec.mould.cavities
    holes = [d for x, y, d in design.lid_holes[len(design.pin_positions_x_mm):]]  # sprues and vents
    holes_mm3 = sum(math.pi * d * d / 4 * design.lid_thickness_mm for d in holes)
    part_mm3 = design.elastomer_volume_mm3
    holds_mm3 = cavities * part_mm3 + holes_mm3
    batch = max(holds_mm3 / 1000.0 * density * (1 + fab.waste_pct / 100.0), MIN_BATCH_G)
    a, b = ratio
    pours = math.ceil(fab.sensors / cavities)
    temp = rec["cure_temperature_C"].nominal if "cure_temperature_C" in rec.quantities else None
    return Quantities(
        material=rec.name, sensors=fab.sensors, cavities=cavities, pours=pours, part_volume_mL=part_mm3 / 1000.0,
        holes_volume_mL=holes_mm3 / 1000.0, mould_holds_mL=holds_mm3 / 1000.0, density_g_cm3=density,
        waste_pct=fab.waste_pct, batch_g=batch, part_a_g=batch * a / (a + b), part_b_g=batch * b / (a + b),
        ratio=ratio, total_g=batch * pours, pot_life_min=pot,
        bench_time_min=MIX_MIN + DEGAS_MIN + POUR_MIN_PER_CAVITY * cavities, cure_time_h=cure, cure_temperature_C=temp,
    )


def findings(design: "Design") -> list[Finding]:
    q = quantities(design)
    out = [Finding(Severity.INFO, "silicone",
                   f"weigh {q.part_a_g:.1f} g part A and {q.part_b_g:.1f} g part B of {q.material} per pour "
                   f"({q.pours} pour(s), {q.total_g:.1f} g in all): the mould holds {q.mould_holds_mL:.2f} mL, plus "
                   f"{q.waste_pct:g} % waste", "fabrication.waste_pct")]
    if q.bench_time_min > 0.8 * q.pot_life_min:
        out.append(Finding(Severity.WARNING, "pot-life",
                           f"weighing, mixing, degassing and pouring {q.cavities} cavities takes about "
                           f"{q.bench_time_min:g} min, more than 80 % of the {q.pot_life_min:g} min pot life: pour "
                           "fewer cavities per batch or choose a slower silicone", "mould.cavities"))
    return out


# ---------------------------------------------------------------------------------------------------
# Rendering


def _t(recipe: Recipe, key: str, fallback: str = "") -> str:
    return recipe.texts.get(key, fallback)


def _q(recipe: Recipe, key: str) -> float | None:
    return recipe[key].nominal if key in recipe.quantities else None


Section = tuple[str, list[str]]


def _print_section(design: "Design") -> Section:
    printer = design.printer
    n = design.spec.fabrication.sensors
    layer = _q(printer, "layer_height_mm")
    wash, post, post_t = _q(printer, "wash_time_min"), _q(printer, "post_cure_time_min"), _q(printer, "post_cure_temperature_C")
    prints = [
        f"Print mould_cup.stl and mould_lid.stl once, and pad.stl {n} time(s), on the {printer.name}, in the poses the "
        f"files are saved in (lid cores point up){f', {layer * 1000:g} um layers' if layer else ''}. The walls are at "
        f"least {design.wall_mm:g} mm; the printer's minimum is {printer['min_wall_mm'].nominal:g} mm.",
    ]
    if wash is not None and post is not None:
        prints.append(f"Wash the prints in IPA for at least {wash:g} min, dry them, then post-cure for {post:g} min"
                      + (f" at {post_t:g} C" if post_t is not None else "") + ". " + _t(printer, "post_process"))
    elif _t(printer, "post_process"):
        prints.append(_t(printer, "post_process"))
    prints.append(f"Check the pad's alignment holes ({', '.join(f'{d:g} mm' for _, _, d in design.alignment_holes)}) "
                  "take their dowel pins; ream them if the printer closed them up.")
    return "Print the mould and the pad", prints


def _prepare_section(design: "Design", q: Quantities) -> Section:
    printer = design.printer
    rec = _silicone(design)
    release = catalogue("adhesives")[design.spec.fabrication.release_agent]
    inhibit = _t(printer, "inhibits_platinum")
    prep = []
    if inhibit and not inhibit.lower().startswith("no"):
        prep.append(f"Cure inhibition: {inhibit.split(' - ')[0]}. {_t(printer, 'barrier_coat')} Cast a test patch of "
                    f"{q.material} in an offcut first; if it stays tacky after {q.cure_time_h:g} h, seal the mould.")
    else:
        prep.append(f"Cure inhibition: {inhibit or 'no data for this printer'}. {_t(printer, 'barrier_coat')}")
    prep.append(f"Release agent ({release.name}): {_t(release, 'application', 'a light, even coat on cup and lid')}")
    prep.append(f"Inhibitors to keep away from the silicone: {_t(rec, 'inhibition', 'see the silicone datasheet')}")
    return "Prepare the mould", prep


def _mix_section(design: "Design", q: Quantities) -> Section:
    rec = _silicone(design)
    n = design.spec.fabrication.sensors
    a_name, b_name = ("part A", "part B") if q.ratio[0] == q.ratio[1] else ("base", "curing agent")
    mix = [
        f"Per pour ({q.pours} pour(s) for {n} sensor(s), {q.cavities} cavit{'y' if q.cavities == 1 else 'ies'} each): "
        f"weigh {q.part_a_g:.1f} g of {a_name} and {q.part_b_g:.1f} g of {b_name} of {q.material} "
        f"({q.ratio[0]:g}:{q.ratio[1]:g} by weight; {q.batch_g:.1f} g in all).",
        f"Why that much: one part is {q.part_volume_mL:.3f} mL, the lid's fill and vent holes {q.holes_volume_mL:.3f} mL, "
        f"so the mould holds {q.mould_holds_mL:.3f} mL = {q.mould_holds_mL * q.density_g_cm3:.2f} g at "
        f"{q.density_g_cm3:g} g/cm3, plus {q.waste_pct:g} % for the cup, the stirrer and the overflow"
        + (f" (raised to the {MIN_BATCH_G:g} g smallest batch a 0.1 g scale weighs to 1 %)" if q.batch_g <= MIN_BATCH_G else "")
        + ".",
        f"Pot life {q.pot_life_min:g} min: you have about {q.bench_time_min:g} min of work (mix {MIX_MIN:g}, degas "
        f"{DEGAS_MIN:g}, pour {POUR_MIN_PER_CAVITY:g} per cavity). Start the clock when B meets A.",
        "Mix for 3 min, scraping the sides and the bottom of the cup.",
        f"Degas: {_t(rec, 'degas', 'vacuum-degas until the foam collapses')}",
    ]
    return "Weigh, mix and degas", mix


def _pour_section(q: Quantities) -> Section:
    cure_at = f" at {q.cure_temperature_C:g} C" if q.cure_temperature_C is not None else ""
    return "Pour, cure and demould", [
        "Pour slowly in a thin stream into one side of each cavity, filling it to the brim.",
        "Lower the lid onto its registration pins; the excess rises through the fill hole and the vents.",
        f"Cure for {q.cure_time_h:g} h{cure_at} before opening.",
        "Lever the lid off at the 3 mm overhangs; the part comes out of the cup on its core. Peel it off the core.",
        "Trim the sprue and vent stubs flush with the base.",
    ]


def _magnet_section(design: "Design") -> Section:
    spec = design.spec
    assembly = catalogue("assembly")
    glue = catalogue("adhesives")[spec.fabrication.adhesive]
    polarity = assembly["polarity-check"]
    mag = assembly.get(f"magnet-{spec.magnet.grade.lower()}")
    return "Magnet", [
        f"Magnet: NdFeB {spec.magnet.grade}, {spec.magnet.diameter_mm:g} mm diameter x {spec.magnet.height_mm:g} mm, "
        "axially magnetised" + (f"; {_t(mag, 'coating', '')}" if mag is not None and _t(mag, 'coating') else "") + ".",
        f"Polarity: {_t(polarity, 'method', 'mark the north pole with a compass')}",
        f"Heat: {_t(assembly['magnet-handling'], 'heat', 'keep the magnet below its maximum operating temperature')}",
        "Orientation, the same for every sensor: north pole up, away from the chip (towards the fingertip). The chip "
        "then reads a positive Bz at rest; the acceptance test checks the sign.",
        f"Push the magnet up the insertion channel (it stretches) until it stops against the pocket's roof, "
        f"{design.cover_mm:g} mm below the tip.",
        f"Fill the insertion channel and the funnel with {glue.name} up to the magnet, without bubbles (about "
        f"{design.core_volume_mm3 - design.magnet_volume_mm3:.0f} uL: the channel, funnel and pocket clearance less "
        "the magnet); the predicted force assumes the magnet glued in a filled channel (report, the note under the "
        "stack-up drawing): an open channel makes the tip markedly softer. Glue: "
        f"{_t(glue, 'mix', '')} Handling cure "
        + (f"{glue['cure_time_handling_min'].nominal:g} min" if 'cure_time_handling_min' in glue.quantities else "per the datasheet")
        + (f", full cure {glue['cure_time_full_h'].nominal:g} h." if 'cure_time_full_h' in glue.quantities else "."),
    ]


def _solder_section(design: "Design") -> Section:
    spec = design.spec
    assembly = catalogue("assembly")
    stencil, reflow = assembly["stencil"], assembly["reflow"]
    return "Solder the board", [
        f"Order the board from pcb/gerbers ({spec.pcb.width_mm:g} x {spec.pcb.height_mm:g} mm, 2 layers, "
        f"{spec.pcb.thickness_mm:g} mm) with a {stencil['thickness_mm'].nominal:g} mm stencil. "
        + _t(stencil, "perimeter_aperture"),
        f"Paste: {_t(stencil, 'paste', 'no-clean').rstrip('.')}. The exposed pad's paste is split in four apertures "
        "(65 % coverage) so the chip does not float.",
        f"Place U1 (pin 1 at the silk arrow), then reflow: peak {reflow['peak_C'].nominal:g} C "
        f"(never above the package's {reflow['package_classification_peak_C'].nominal:g} C), "
        f"{reflow['time_above_liquidus_s'].nominal:g} s above liquidus. {_t(reflow, 'soak')}",
        f"Hot air instead of an oven: {_t(reflow, 'hot_air_rework')}",
        "Place C1, C2 (100 nF) on the bottom, under the chip" + (", R1, R2 (pull-ups) behind J1" if spec.pcb.pullups else "")
        + ", and J1 (Qwiic) on the bottom edge. Inspect the QFN's sides for bridges.",
        f"The board answers at I2C address 0x{design.i2c_address:02X} (A1/A0 strapped on the board).",
    ]


def _assemble_section(design: "Design") -> Section:
    glue = catalogue("adhesives")[design.spec.fabrication.adhesive]
    return "Assemble", [
        f"Glue the elastomer's flat base to the pad, inside its lip, with a thin even layer of {glue.name}.",
        "Put the dowel pins in the board's two alignment holes and lower the pad over the chip: the square recess "
        "drops over the package and the holes of different sizes let it fit one way round.",
    ]


def _flash_section(design: "Design") -> Section:
    from . import firmware

    spec = design.spec
    return "Flash and read", [
        f"Wire the board to an Arduino Uno or Nano through an I2C level shifter (the board is 3.3 V).",
        f"Flash: sh firmware/flash.sh uno PORT (a Nano: nano, or nano-old for the old bootloader; Windows: "
        f"firmware\\flash.bat uno PORT) writes firmware/{firmware.HEX_NAME}.",
        "Install the reader: pip install ./readout; then magfab-readout upload (the image keeps its calibration in "
        "EEPROM, which the Arduino bootloader does not write: until this runs the board sends only error frames "
        "'no valid calibration'), magfab-readout info (the calibration hash must match) and "
        f"magfab-readout stream --zero 200 (binary frames at {spec.firmware.baud} baud).",
    ]


def _calibrate_section(design: "Design", plan: "ScanPlan | None") -> Section:
    spec = design.spec
    cal = spec.calibration
    if plan is None:  # no prediction to cap it: the spec's extent
        from ..models.scan import scan_plan

        plan = scan_plan(design)
    return "Calibrate", [
        f"Scan against a reference force sensor (resolution {cal.reference_resolution_mN:g} mN): the y-z track, "
        f"{2.0 * plan.y_half_mm:.3g} mm in y centred on the axis (set by {plan.y_end}) and {plan.depth_mm:.3g} mm of "
        f"indentation (set by {plan.depth_end}; the simulated scan and the predicted range stop there too), in "
        f"{plan.step_mm * 1000:g} um steps ({plan.points} points).",
        "Record with magfab-readout record scan.csv and add the reference's Fx_N, Fy_N, Fz_N columns (docs/bundle.md).",
        f"magfab calibrate scan.csv --spec {spec.name}.toml: order {cal.order} ({cal.method.value}), {cal.folds}-fold "
        f"held-out error, tolerance {cal.tolerance_mN:g} mN; then pip install ./readout again and magfab-readout "
        "upload: the new calibration goes into the EEPROM over serial, no compiler and no reflash.",
    ]


def _acceptance_section(acceptance: Mapping[str, object] | None) -> Section:
    accept = ["With nothing touching the tip: magfab-readout check (it reads the field at rest, then asks for a "
              "known weight on the tip)."]
    if acceptance:
        rest = acceptance.get("rest_Bz_uT")
        weight = acceptance.get("weight_g")
        delta = acceptance.get("delta_Bz_uT")
        if rest and weight and delta:
            accept.append(f"Pass: Bz at rest within {rest[0]:.0f} to {rest[1]:.0f} uT (positive: magnet the right way "
                          f"up), and a {weight:g} g weight raises Bz by {delta[0]:.0f} to {delta[1]:.0f} uT.")
    accept.append("A fail names the step and the measured and predicted values: a weak or strong field points at the "
                  "magnet grade or the stack-up, a negative one at an upside-down magnet, a small rise at a stiff "
                  "batch of silicone.")
    return "Acceptance test", accept


def sections(design: "Design", acceptance: Mapping[str, object] | None = None,
             plan: "ScanPlan | None" = None) -> list[Section]:
    """The checklist as (section title, steps): plain text with the spec's and the recipes' numbers filled
    in; the Markdown and HTML templates only lay it out (and escape it). ``plan``: the calibration scan's extent
    (:func:`magfab.models.scan.scan_plan`; omitted, the spec's)."""
    q = quantities(design)
    return [_print_section(design), _prepare_section(design, q), _mix_section(design, q), _pour_section(q),
            _magnet_section(design), _solder_section(design), _assemble_section(design), _flash_section(design),
            _calibrate_section(design, plan), _acceptance_section(acceptance)]


def checklist_md(design: "Design", acceptance: Mapping[str, object] | None = None,
                 plan: "ScanPlan | None" = None) -> str:
    from .templating import render

    return render("checklist/checklist.md.j2", spec=design.spec, q=quantities(design),
                  sections=sections(design, acceptance, plan))


def checklist_html(design: "Design", acceptance: Mapping[str, object] | None = None,
                 plan: "ScanPlan | None" = None) -> str:
    from .templating import render

    return render("checklist/checklist.html.j2", spec=design.spec, q=quantities(design),
                  sections=sections(design, acceptance, plan))
