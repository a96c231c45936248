"""The checklist's words for an RP2040 readout board ([board] mcu = "rp2040"): the wiring, straight at 3.3 V with no
level shifter, and flashing by copying the build's .uf2 onto the board's RPI-RP2 drive. The pins and the socket are
recipes/boards.toml's."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..board.plan import two_buses
from ..recipes import Recipe, catalogue
from . import rp2040

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["flash_commands", "flash_text", "wiring_header", "wiring_rows", "wiring_text"]


def _board(design: Design) -> tuple[str, Recipe]:
    return rp2040.board_key(design.spec), rp2040.readout_board(design.spec)


def flash_commands(design: Design) -> tuple[str, ...]:
    """The bench commands from the build folder: the .uf2 onto the drive, the reader, what the board runs, forces.
    One command per line."""
    key, _ = _board(design)
    return (
        f"cp firmware/{rp2040.image_name(key)} /media/$USER/RPI-RP2/     # macOS: /Volumes/RPI-RP2/",
        "pip install ./readout",
        "magfab-readout info",
        "magfab-readout stream --zero 200            # Ctrl-C ends it",
    )


def flash_text(design: Design) -> str:
    """The step before :func:`flash_commands`."""
    key, board = _board(design)
    return (f"Hold the {rp2040.short_name(board)}'s BOOTSEL button while you plug it into this computer: it shows up "
            f"as a USB drive named RPI-RP2. Then run these from the build folder (the folder holding this checklist). "
            f"They copy firmware/{rp2040.image_name(key)} onto that drive (on Windows, drag it onto the drive; the "
            "board restarts into it when the copy ends), install the reader with this build's calibration "
            "(provisional: fitted to the scan magfab simulated for the design), check that the board reports the same "
            "calibration hash (the .uf2 carries the calibration too, so there is nothing to upload), and stream "
            "calibrated forces over USB, zeroed on the first 200 samples: keep the tip untouched while it starts.")


def wiring_header(design: Design) -> tuple[str, ...]:
    return ("breakout J1, J2 (Qwiic)" if two_buses(design) else "breakout J1 (Qwiic)",
            rp2040.short_name(_board(design)[1]))


def wiring_rows(design: Design) -> tuple[tuple[str, str], ...]:
    """J1's four pins and the board's pin each goes to; with a second bus, J2's SDA and SCL to the board's second
    controller's pins (its ground and supply are J1's: those two wires stay off)."""
    board = _board(design)[1]
    qwiic = catalogue("parts")["jst-sh-4"]
    pin = {qwiic.texts[f"qwiic_pin_{k}"]: f"{qwiic.texts[f'qwiic_pin_{k}']} (pin {k})" for k in range(1, 5)}
    rows = ((pin["GND"], board.texts["gnd_pin"]), (pin["3V3"], board.texts["v3_pin"]),
            (pin["SDA"], board.texts["sda_pin"]), (pin["SCL"], board.texts["scl_pin"]))
    if not two_buses(design):
        return rows
    return (*((f"J1 {a}", b) for a, b in rows), (f"J2 {pin['SDA']}", board.texts["sda_b_pin"]),
            (f"J2 {pin['SCL']}", board.texts["scl_b_pin"]), (f"J2 {pin['GND']}, {pin['3V3']}", "none (taped off)"))


def wiring_text(design: Design) -> list[str]:
    """The wiring steps: a Qwiic cable into the board's STEMMA QT socket, or a Qwiic-to-pins cable to its header;
    both sides are 3.3 V, so no level shifter."""
    board = _board(design)[1]
    bench = catalogue("bench")
    name = rp2040.short_name(board)
    two = two_buses(design)
    if board.texts["connector"] == "stemma-qt":
        first = (f"Plug the {bench['qwiic-cable'].name.split(',')[0]} into J1 and into the {name}'s STEMMA QT socket "
                 "(it takes the cable one way round)." + ("" if two else " That is all the wiring: the table shows "
                                                          "what each wire joins."))
    else:
        first = (f"The {name} has no Qwiic socket: plug the {bench['qwiic-jumper'].name.split(',')[0]} into J1 and "
                 "its four pins onto the board's header pins as in the table (solder a header onto the board first).")
    bus = (("The breakout's pull-ups (R1, R2 for J1's bus, R3, R4 for J2's) hold the buses." if two else
            "The breakout's pull-ups (R1, R2) hold the bus.") if design.spec.pcb.pullups else
           "This breakout has no pull-ups (pcb.pullups = false): fit 2.2 kOhm from SDA and from SCL to 3.3 V"
           + (" on each bus" if two else "") + ", or the bus will not reach its clock.")
    steps = [first]
    if two:
        steps.append(f"J2 is the second I2C bus (the odd taxels' chips, read beside the even ones' on the {name}'s "
                     "other I2C controller): plug the second Qwiic-to-pins cable (the BOM's breadboard jumper) into "
                     f"J2 and take its SDA (blue) wire to {board.texts['sda_b_pin']} and its SCL (yellow) to "
                     f"{board.texts['scl_b_pin']} (a header soldered on, or the board on a breadboard); tape off its "
                     "red and black wires (J1 carries the supply and ground).")
    return [*steps, f"The breakout and the {name} are both 3.3 V boards, so SDA and SCL run straight between them: "
                    f"no level shifter. {bus}"]
