"""The ATmega328P board's serial and I2C clocks, from the spec's baud and I2C clock: what the image's record carries
(:func:`magfab.export.firmware.image_settings`), checked before any work so that ``magfab check`` and ``magfab build``
refuse a baud the 16 MHz UART cannot make with the same line (:func:`serial_links`). An RP2040 board's link is USB,
which has no baud: nothing to refuse."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..board.plan import two_buses
from ..errors import SpecError
from ..recipes import resolve
from ..spec_sections import readout_board_key

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["F_CPU_HZ", "BAUD_ERROR_LIMIT", "uart_settings", "twi_settings", "serial_links"]

F_CPU_HZ = 16_000_000
#: Largest UART rate error accepted (the receiver samples mid-bit; 2 to 2.5 % is the usual 8N1 budget).
BAUD_ERROR_LIMIT = 0.025


def serial_links(design: Design) -> None:
    """Refuse (:class:`~magfab.errors.SpecError`) a baud, I2C clock or second I2C bus the spec's readout board cannot
    make: an ATmega328P board's UART and TWI from 16 MHz (:func:`uart_settings`, :func:`twi_settings`), and its one
    TWI (``array.buses = 2`` needs an RP2040 board's two I2C controllers)."""
    key = readout_board_key(design.spec.board)
    if resolve.board(key).texts["mcu"] == "atmega328p":
        uart_settings(design.spec.firmware.baud)
        twi_settings(design.spec.firmware.i2c_hz)
        if two_buses(design):
            raise SpecError("array.buses", 2, f"needs a board with two I2C controllers: the {key} board's ATmega328P "
                            "has one; use buses = 1, or [board] mcu = \"rp2040\"")


def uart_settings(baud: int) -> tuple[int, float]:
    """UBRR with U2X for the spec's baud, and the rate error; SpecError past BAUD_ERROR_LIMIT."""
    ubrr = max(0, round(F_CPU_HZ / (8 * baud)) - 1)
    error = F_CPU_HZ / (8 * (ubrr + 1)) / baud - 1.0
    if ubrr > 4095 or abs(error) > BAUD_ERROR_LIMIT:
        good = [b for b in (57600, 76800, 115200, 250000, 500000, 1000000)
                if abs(F_CPU_HZ / (8 * round(F_CPU_HZ / (8 * b))) / b - 1) <= BAUD_ERROR_LIMIT]
        raise SpecError("firmware.baud", baud,
                        f"is {error * 100:+.1f} % off on a 16 MHz ATmega328P with U2X (UBRR {ubrr}); the UART "
                        f"allows {BAUD_ERROR_LIMIT * 100:g} %", "use one of " + ", ".join(map(str, good)))
    return ubrr, error


def twi_settings(hz: int) -> tuple[int, int, int]:
    """(TWBR, prescaler bits, actual Hz): the fastest TWI clock not above the spec's."""
    for bits, div in enumerate((1, 4, 16, 64)):
        twbr = max(0, math.ceil((F_CPU_HZ / hz - 16) / (2 * div)))
        if twbr <= 255:
            return twbr, bits, round(F_CPU_HZ / (16 + 2 * twbr * div))
    raise SpecError("firmware.i2c_hz", hz, "is below what the ATmega328P's TWI can divide 16 MHz down to (~490 Hz)")
