"""The checklist's pages for an array: the address plan and the magnets' orientation, and the words of the
single taxel's steps that change when one board carries several chips and magnets."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["address_rows", "ADDRESS_HEADER", "north", "chips_text", "magnets_text"]

ADDRESS_HEADER = ("taxel", "x, y (mm)", "chip", "order code", "I2C address", "A1, A0", "magnet north")


def north(polarity: int) -> str:
    """Which way the magnet's north face looks: up (towards the tip), or down (towards the chip)."""
    return "up (to the tip)" if polarity > 0 else "down (to the chip)"


def address_rows(design: "Design") -> tuple[tuple[str, ...], ...]:
    """One row per taxel: where it stands (board frame, from the board's centre), its chip, the order code that sets
    the chip's I2C base, its address, the A1/A0 straps the board wires (0 GND, 1 3.3 V), the magnet's north."""
    return tuple((str(t.index), f"{t.x_mm:g}, {t.y_mm:g}", f"U{t.index + 1}", f"MLX90393SLW-ABA-{t.option_code}",
                  f"0x{t.i2c_address:02X}", f"{t.address_straps[0]}, {t.address_straps[1]}", north(t.polarity))
                 for t in design.taxels)


def chips_text(design: "Design") -> str:
    """The chips to place, by designator and order code (they look alike: the code is on the reel, not the part)."""
    by_code = {}
    for t in design.taxels:
        by_code.setdefault(t.option_code, []).append(f"U{t.index + 1}")
    return "; ".join(f"{', '.join(us)} from the -{code} reel" for code, us in sorted(by_code.items()))


def magnets_text(design: "Design") -> str:
    """Which way each magnet goes in, for the magnet step."""
    downs = [str(t.index) for t in design.taxels if t.polarity < 0]
    if not downs:
        return "Every taxel's magnet goes in the same way: north up, towards the tip."
    return (f"The magnets alternate: taxel(s) {', '.join(downs)} take theirs south face (undotted) first, north down "
            "towards the chip; the others north face first. The address plan's last column says which for each; a "
            "wrong one reads a negative field at rest for a north-up taxel (the acceptance test names it).")
