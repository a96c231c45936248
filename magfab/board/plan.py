"""The board's address plan: which chip reads which taxel, at which I2C address, strapped how.

One source for the board (the table on its drawing layer, the marks beside the chips) and for the papers that
name the chips (BOM, checklist, report): :func:`address_plan`.
"""

from __future__ import annotations

from ..design import Design
from .layout import GROUND, ORIGIN, SUPPLY

__all__ = ["address_plan", "table_lines", "ORDER_CODE"]

ORDER_CODE = "MLX90393SLW-ABA-{}"  # the chip's order code (QFN-16) for an option code, as the BOM orders it


def address_plan(design: Design) -> list[dict]:
    """One row per chip, in taxel order (one row for a single taxel):

    ``taxel`` (index), ``designator`` ("U1".., taxel + 1), ``address`` (7-bit int) and ``address_hex`` ("0x0C"),
    ``option_code`` ("011"..) and ``order_code`` ("MLX90393SLW-ABA-011"), ``a1`` / ``a0`` (strap levels 0 or 1) and
    ``a1_net`` / ``a0_net`` ("GND" or "+3V3"), ``capacitors`` (its two decoupling capacitors on the bottom,
    ("C1", "C2")..), ``polarity`` (+1 north up, -1 flipped), ``x_mm`` / ``y_mm`` (the chip's centre in the design's
    frame: from the pad's centre, y up) and ``kicad_x_mm`` / ``kicad_y_mm`` (in the board file, y down)."""
    if design.array is None:
        rows = [(0, design.i2c_address, design.spec.sensor.option_code, design.address_straps, 1, 0.0, 0.0)]
    else:
        rows = [(t.index, t.i2c_address, t.option_code, t.address_straps, t.polarity, t.x_mm, t.y_mm)
                for t in design.taxels]
    ox, oy = ORIGIN
    out = []
    for k, address, code, (a1, a0), polarity, x, y in rows:
        out.append({"taxel": k, "designator": f"U{k + 1}", "address": address, "address_hex": f"0x{address:02X}",
                    "option_code": code, "order_code": ORDER_CODE.format(code), "a1": int(a1), "a0": int(a0),
                    "a1_net": SUPPLY if a1 else GROUND, "a0_net": SUPPLY if a0 else GROUND,
                    "capacitors": (f"C{2 * k + 1}", f"C{2 * k + 2}"), "polarity": polarity, "x_mm": x, "y_mm": y,
                    "kicad_x_mm": round(ox + x, 6), "kicad_y_mm": round(oy - y, 6)})
    return out


def table_lines(design: Design) -> tuple[str, ...]:
    """The address table drawn beside the board: a heading, then "T0  U1  0x0C  MLX90393SLW-ABA-011  A1=GND  A0=GND"
    per chip."""
    return ("address plan: taxel, chip, I2C address, order code, A1 A0 straps",
            *(f"T{r['taxel']}  {r['designator']}  {r['address_hex']}  {r['order_code']}  "
              f"A1={'3V3' if r['a1'] else 'GND'}  A0={'3V3' if r['a0'] else 'GND'}" for r in address_plan(design)))
