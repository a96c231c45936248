"""The board's address plan: which chip reads which taxel, at which I2C address, strapped how.

One source for the board (the table on its drawing layer, the marks beside the chips) and for the papers that
name the chips (BOM, checklist, report): :func:`address_plan`.
"""

from __future__ import annotations

from ..design import Design
from .layout import GROUND, ORIGIN, SUPPLY

__all__ = ["address_plan", "table_lines", "taxel_bus", "bus_mask", "two_buses", "ORDER_CODE", "BUS_NETS"]

ORDER_CODE = "MLX90393SLW-ABA-{}"  # the chip's order code (QFN-16) for an option code, as the BOM orders it
#: Each I2C bus's (SDA, SCL) nets and its connector: the first on J1, a second (``array.buses = 2``) on J2.
BUS_NETS = (("SDA", "SCL", "J1"), ("SDA_B", "SCL_B", "J2"))


def two_buses(design: Design) -> bool:
    """Whether the board splits its chips over two I2C buses (``array.buses = 2``: J2 and a second cable)."""
    return design.spec.array is not None and design.spec.array.buses == 2


def taxel_bus(design: Design, k: int) -> int:
    """The I2C bus taxel ``k``'s chip is on: 0, or 1 for an odd taxel of an array split over two buses
    (``array.buses = 2``). Alternate taxels, because the firmware reads the taxels in order and a read on the other
    bus runs beside the one before it (docs/bundle.md section 4)."""
    return int(two_buses(design) and k % 2 == 1)


def bus_mask(design: Design) -> int:
    """The array record's buses mask: bit k set for taxel k on the second bus (0 for one bus, or a single taxel)."""
    return sum(1 << t.index for t in design.taxels if taxel_bus(design, t.index)) if design.array is not None else 0


def address_plan(design: Design) -> list[dict]:
    """One row per chip, in taxel order (one row for a single taxel):

    ``taxel`` (index), ``designator`` ("U1".., taxel + 1), ``address`` (7-bit int) and ``address_hex`` ("0x0C"),
    ``option_code`` ("011"..) and ``order_code`` ("MLX90393SLW-ABA-011"), ``a1`` / ``a0`` (strap levels 0 or 1) and
    ``a1_net`` / ``a0_net`` ("GND" or "+3V3"), ``bus`` (0, or 1 on the second I2C bus: :func:`taxel_bus`),
    ``capacitors`` (its two decoupling capacitors on the bottom, ("C1", "C2")..), ``polarity`` (+1 north up, -1
    flipped), ``x_mm`` / ``y_mm`` (the chip's centre in the design's frame: from the pad's centre, y up) and
    ``kicad_x_mm`` / ``kicad_y_mm`` (in the board file, y down)."""
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
                    "bus": taxel_bus(design, k), "capacitors": (f"C{2 * k + 1}", f"C{2 * k + 2}"),
                    "polarity": polarity, "x_mm": x, "y_mm": y,
                    "kicad_x_mm": round(ox + x, 6), "kicad_y_mm": round(oy - y, 6)})
    return out


def table_lines(design: Design) -> tuple[str, ...]:
    """The address table drawn beside the board: a heading, then "T0  U1  0x0C  MLX90393SLW-ABA-011  A1=GND  A0=GND"
    per chip; on a board of two buses each line ends with its bus's connector ("J1", "J2")."""
    two = two_buses(design)
    return ("address plan: taxel, chip, I2C address, order code, A1 A0 straps" + (", bus" if two else ""),
            *(f"T{r['taxel']}  {r['designator']}  {r['address_hex']}  {r['order_code']}  "
              f"A1={'3V3' if r['a1'] else 'GND'}  A0={'3V3' if r['a0'] else 'GND'}"
              + (f"  {BUS_NETS[r['bus']][2]}" if two else "") for r in address_plan(design)))
