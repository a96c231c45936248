"""The checklist's pages for an array: the address plan and the magnets' orientation, and the words of the
single taxel's steps that change when one board carries several chips and magnets."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..units import G0

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["address_rows", "ADDRESS_HEADER", "north", "chips_text", "magnets_text", "CALIBRATE_COMMANDS",
           "calibrate_text", "acceptance_steps"]

#: An array's calibration commands: one taxel's scan per recording, --taxel naming it (the readout README's bench
#: block has the same lines). One command per line.
CALIBRATE_COMMANDS = (
    "magfab-readout record scan.csv              # during taxel 0's scan; Ctrl-C ends it",
    "magfab calibrate scan.csv --reference reference.csv --taxel 0",
    "pip install ./readout",
    "magfab-readout upload",
)

ADDRESS_HEADER = ("taxel", "x, y (mm)", "chip", "order code", "I2C address", "A1, A0", "magnet north")


def north(polarity: int) -> str:
    """Which way the magnet's north face looks: up (towards the tip), or down (towards the chip)."""
    return "up (to the tip)" if polarity > 0 else "down (to the chip)"


def address_rows(design: Design) -> tuple[tuple[str, ...], ...]:
    """One row per taxel: where it stands (board frame, from the board's centre), its chip, the order code that sets
    the chip's I2C base, its address, the A1/A0 straps the board wires (0 GND, 1 3.3 V), the magnet's north."""
    return tuple((str(t.index), f"{t.x_mm:g}, {t.y_mm:g}", f"U{t.index + 1}", f"MLX90393SLW-ABA-{t.option_code}",
                  f"0x{t.i2c_address:02X}", f"{t.address_straps[0]}, {t.address_straps[1]}", north(t.polarity))
                 for t in design.taxels)


def chips_text(design: Design) -> str:
    """The chips to place, by designator and order code (they look alike: the code is on the reel, not the part)."""
    by_code: dict[str, list[str]] = {}
    for t in design.taxels:
        by_code.setdefault(t.option_code, []).append(f"U{t.index + 1}")
    return "; ".join(f"{', '.join(us)} from the -{code} reel" for code, us in sorted(by_code.items()))


def magnets_text(design: Design) -> str:
    """Which way each magnet goes in, for the magnet step."""
    downs = [str(t.index) for t in design.taxels if t.polarity < 0]
    if not downs:
        return "Every taxel's magnet goes in the same way: north up, towards the tip."
    return (f"The magnets alternate: taxel(s) {', '.join(downs)} take theirs south face (undotted) first, north down "
            "towards the chip; the others north face first. The address plan's last column says which for each; a "
            "wrong one reads a negative field at rest for a north-up taxel (the acceptance test names it).")


def calibrate_text(design: Design, scan: str) -> str:
    """The calibration step's words for an array (its commands: :data:`CALIBRATE_COMMANDS`), after the words ``scan``
    it shares with a single taxel's: one taxel scanned per recording, its calibration fitted into this build folder."""
    n = len(design.taxels)
    return scan + (
        ", which updates this build folder, reinstall the reader with the new calibration, and upload the array's "
        "record again, which names it (no compiler, no reflash). Scan one taxel at a time, taxel 0 first, its tip "
        "under the disc: the recording holds every chip's field and --taxel names the taxel scanned (the others keep "
        f"their calibrations). Then the same for taxels 1 to {n - 1}, one recording each, with --taxel the taxel "
        "scanned.")


def acceptance_steps(design: Design, weight_g: float) -> list[str]:
    """The acceptance section's words for an array: magfab-readout check reads a single taxel only."""
    return [f"magfab-readout check does not read an array yet. With the board streaming, zeroed at rest (the last "
            f"command of the section Flash and read), put the {weight_g:g} g weight on each of the "
            f"{len(design.taxels)} tips in turn: that taxel's Fz reads about {weight_g * G0 / 1000.0:.2f} N and the "
            "others stay near zero (the host removes each magnet's field from its neighbours')."]
