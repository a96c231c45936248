"""The bill of materials (bom.csv): one row per item, quantities for ``fabrication.sensors``."""

from __future__ import annotations

import csv
import io
from typing import TYPE_CHECKING

from ..recipes import catalogue

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["bom_rows", "bom_csv"]


def bom_rows(design: "Design") -> list[dict[str, object]]:
    """The bill of materials: one row per item, quantities for ``fabrication.sensors``."""
    spec = design.spec
    n = spec.fabrication.sensors
    from .checklist import quantities  # checklist re-exports this module, so import it at call time

    q = quantities(design)
    parts = catalogue("parts")
    pcb = spec.pcb
    rows = [
        {"item": "Hall sensor IC", "part": f"MLX90393SLW-ABA-{spec.sensor.option_code}-RE",
         "description": f"Melexis MLX90393, QFN-16 3x3 mm, option code {spec.sensor.option_code} (I2C base for address "
                        f"0x{design.i2c_address:02X})", "quantity": n, "unit": "pcs"},
        {"item": "Magnet", "part": f"NdFeB {spec.magnet.grade} disc {spec.magnet.diameter_mm:g} x {spec.magnet.height_mm:g} mm",
         "description": "axially magnetised, Ni-Cu-Ni coated", "quantity": n, "unit": "pcs"},
        {"item": "Silicone", "part": q.material,
         "description": f"mix {q.ratio[0]:g}:{q.ratio[1]:g} by weight; {q.total_g:.1f} g in {q.pours} pour(s) "
                        f"including {q.waste_pct:g} % waste", "quantity": round(q.total_g, 1), "unit": "g"},
        {"item": "Adhesive", "part": catalogue("adhesives")[spec.fabrication.adhesive].name,
         "description": "seals the magnet in its pocket and glues the elastomer to the pad", "quantity": 1, "unit": "tube"},
        {"item": "Release agent", "part": catalogue("adhesives")[spec.fabrication.release_agent].name,
         "description": "on the mould before every pour", "quantity": 1, "unit": "can"},
        {"item": "PCB", "part": f"{spec.name} breakout {pcb.width_mm:g} x {pcb.height_mm:g} mm",
         "description": f"2 layers, {pcb.thickness_mm:g} mm FR-4, from pcb/gerbers", "quantity": n, "unit": "pcs"},
        {"item": "Capacitor", "part": "100 nF 0603 X7R", "description": "C1, C2: VDD and VDDIO decoupling",
         "quantity": 2 * n, "unit": "pcs"},
    ]
    if pcb.pullups:
        ohm = parts["jst-sh-4"]["pullup_ohm"].nominal
        rows.append({"item": "Resistor", "part": f"{ohm / 1000:g} kOhm 0603 1 %", "description": "R1, R2: I2C pull-ups",
                     "quantity": 2 * n, "unit": "pcs"})
    rows += [
        {"item": "Connector", "part": "JST SM04B-SRSS-TB", "description": "J1: Qwiic (SH 1.0 mm, 4 pins)",
         "quantity": n, "unit": "pcs"},
        {"item": "Cable", "part": "Qwiic cable (JST SH 4-pin, 1.0 mm)", "description": "to the microcontroller board",
         "quantity": n, "unit": "pcs"},
        {"item": "Dowel pins", "part": "; ".join(f"{d:g} mm x {pcb.thickness_mm + design.pad_thickness_mm:g} mm"
                                                 for _, _, d in design.alignment_holes),
         "description": "align the pad on the board (one hole of each size)", "quantity": n, "unit": "sets"},
    ]
    if pcb.mounting_hole_diameter_mm > 0:
        rows.append({"item": "Screws", "part": f"M2 x 6 mm", "description": "mount the board (H3, H4)",
                     "quantity": 2 * n, "unit": "pcs"})
    rows += [
        {"item": "Printed mould", "part": "mould_cup.stl + mould_lid.stl",
         "description": f"{design.printer.name}; {spec.mould.cavities} cavit{'y' if spec.mould.cavities == 1 else 'ies'}",
         "quantity": 1, "unit": "set"},
        {"item": "Printed pad", "part": "pad.stl", "description": design.printer.name, "quantity": n, "unit": "pcs"},
        {"item": "Microcontroller", "part": "Arduino Uno or Nano (ATmega328P, 16 MHz)",
         "description": "runs firmware/magfab-atmega328p.hex; needs an I2C level shifter to the 3.3 V board",
         "quantity": n, "unit": "pcs"},
    ]
    return rows


def bom_csv(design: "Design") -> str:
    out = io.StringIO()
    w = csv.DictWriter(out, fieldnames=["item", "part", "description", "quantity", "unit"], lineterminator="\n")
    w.writeheader()
    for row in bom_rows(design):
        w.writerow(row)
    return out.getvalue()
