"""The spec's section base and its optional sections ([environment], [reference], [board]): :mod:`magfab.spec`
imports them into :class:`~magfab.spec.Spec`."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

from .recipes import catalogue, resolve
from .spec_options import BoardName, Mcu

__all__ = ["Section", "Environment", "Reference", "Board", "boards_of", "readout_board_key"]


class Section(BaseModel):
    """A spec section: frozen, strict, every key known."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)

    @field_validator("*", mode="before")
    @classmethod
    def _integral_float(cls, value: Any, info: ValidationInfo) -> Any:
        """An integer key accepts a float with no fractional part (``12.0`` is 12: TOML writes both, and a
        user converting units gets floats); anything else (2.5, 1e300) still fails as "must be an integer"."""
        field = cls.model_fields.get(info.field_name or "")
        if field is not None and field.annotation is int and isinstance(value, float) and value.is_integer() \
                and abs(value) <= 2.0**53:
            return int(value)
        return value


class Environment(Section):
    """Where the sensor is used, for the drift prediction (magfab.models.drift): the temperature span, how far the
    sensor turns in the Earth's field and a stray magnetic source nearby. Omit the section for a lab bench (these
    defaults)."""

    temperature_min_C: float = Field(20.0, ge=-40.0, le=125.0, description="Coldest the sensor gets in use, C.")
    temperature_max_C: float = Field(30.0, ge=-40.0, le=125.0, description="Warmest the sensor gets in use, C.")
    calibration_temperature_C: float = Field(
        25.0, ge=-40.0, le=125.0, description="Temperature the sensor is calibrated at (within the span), C.")
    temperature_lag_C: float = Field(
        1.0, ge=0.0, le=50.0, description="Largest difference between the magnet's and the chip's temperature while "
        "the temperature changes (the compensation reads the chip's), C.")
    earth_field_G: float | None = Field(
        None, gt=0.0, le=1.0, description="Local total intensity of the Earth's field (NOAA NCEI's calculator), "
        "gauss; omit: the strongest on Earth, 0.65 G.")
    rotation_deg: float = Field(
        180.0, ge=0.0, le=180.0,
        description="Largest change of the sensor's orientation in use, deg (180: turned over).")
    stray_moment_Am2: float = Field(
        0.0, ge=0.0, le=1.0e4, description="Dipole moment of a stray source nearby (a motor, a magnetised steel part), "
        "A m^2; 0: none.")
    stray_distance_mm: float = Field(
        100.0, ge=10.0, le=1.0e5, description="Distance from the stray source to the chip, mm (a dipole estimate: "
        "the source much smaller than this).")

    @model_validator(mode="after")
    def _span(self) -> Environment:
        if self.temperature_max_C <= self.temperature_min_C:
            raise ValueError(f"temperature_max_C {self.temperature_max_C:g} C must be above temperature_min_C "
                             f"{self.temperature_min_C:g} C")
        if not self.temperature_min_C <= self.calibration_temperature_C <= self.temperature_max_C:
            raise ValueError(f"calibration_temperature_C {self.calibration_temperature_C:g} C must lie within the "
                             f"span {self.temperature_min_C:g}..{self.temperature_max_C:g} C")
        return self


class Reference(Section):
    """A reference MLX90393 on the board that no magnet moves: its reading subtracted in the firmware rejects a
    stray field that is the same at both chips (the Earth's as the sensor turns, a far motor's). Omit the section
    for none."""

    distance_mm: float | None = Field(
        None, gt=0.0, le=200.0, description="From the taxels (the hull's edge) to the reference chip along +y, mm; "
        "omit: the nearest point where no magnet's press or slide moves the field there by more than the chip's "
        "noise (computed; MagOne: 42.5 mm), the board made taller to hold it.")


class Board(Section):
    """The readout board the sensor's cable goes to (recipes/boards.toml): the image it runs, its pins and the wiring.
    Omit the section for an Arduino Uno."""

    mcu: Mcu | None = Field(None, strict=False, description="'atmega328p' (Arduino Uno or Nano, 5 V, with a level "
                            "shifter) or 'rp2040' (3.3 V, native USB); omit: the board's.")
    board: BoardName | None = Field(None, strict=False, description="'uno' or 'nano' (atmega328p); 'pico', "
                                    "'qtpy-rp2040' or 'xiao-rp2040' (rp2040); omit: 'uno', or 'qtpy-rp2040' for an "
                                    "rp2040 (its STEMMA QT socket takes the Qwiic cable).")

    @model_validator(mode="after")
    def _same_mcu(self) -> Board:
        mcu = resolve.board(self.key).texts["mcu"]
        if self.mcu is not None and mcu != self.mcu.value:
            raise ValueError(f"board {self.key!r} is an {mcu} board, not an {self.mcu.value} one; the "
                             f"{self.mcu.value} boards: {', '.join(boards_of(self.mcu.value))}")
        return self

    @property
    def key(self) -> str:
        """The board's key in recipes/boards.toml (without ``board``: the Uno, or the QT Py for an rp2040)."""
        if self.board is not None:
            return self.board.value
        return "qtpy-rp2040" if self.mcu is Mcu.RP2040 else "uno"


def readout_board_key(board: Board | None) -> str:
    """The key in recipes/boards.toml of a spec's ``[board]`` (the Uno without the section)."""
    return "uno" if board is None else board.key


def boards_of(mcu: str) -> list[str]:
    """The keys of recipes/boards.toml whose microcontroller is ``mcu``."""
    return [k for k, r in catalogue("boards").items() if r.texts["mcu"] == mcu]
