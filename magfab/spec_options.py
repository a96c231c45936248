"""The spec's choices of model (``predict.field_model``, ``predict.mechanics_model``, ``predict.material_law``,
``calibration.method``): plain enums, imported by :mod:`magfab.spec` (which re-exports them) and by the models that
take the same choices."""

from __future__ import annotations

from enum import Enum

__all__ = ["Mcu", "BoardName", "FieldModel", "MechanicsModel", "CLOSED_FORMS", "MaterialLaw", "MaterialLawChoice",
           "CalibrationMethod"]


class FieldModel(str, Enum):
    """Magnet-field model: 'auto' picks the cheapest whose error fits predict.tolerance_pct."""

    AUTO = "auto"
    EXACT = "exact"
    SURROGATE = "surrogate"
    DIPOLE = "dipole"
    ON_AXIS = "on_axis"


class MechanicsModel(str, Enum):
    """Elastomer model: 'auto' uses the finite-element model on the coarsest mesh whose estimated
    discretisation error fits predict.tolerance_pct."""

    AUTO = "auto"
    FE = "fe"
    HERTZ_COLUMN = "hertz_column"
    COLUMN = "column"


class MaterialLaw(str, Enum):
    """Hyperelastic law of the elastomer FE: 'neo-hookean' or 'yeoh' (the silicone's fit in recipes/materials.toml)."""

    NEO_HOOKEAN = "neo-hookean"
    YEOH = "yeoh"


#: The mechanics models that are closed forms: neo-Hookean by construction, so ``predict.material_law = "auto"``
#: gives them that law and "yeoh" is refused with them.
CLOSED_FORMS = (MechanicsModel.COLUMN, MechanicsModel.HERTZ_COLUMN)


class MaterialLawChoice(str, Enum):
    """The spec's ``predict.material_law``: a :class:`MaterialLaw`, or 'auto': the silicone's Yeoh law where the
    recipes fit one and the FE (or its surrogate) models the elastomer, neo-Hookean otherwise (a silicone without a
    fit, a closed-form mechanics model)."""

    AUTO = "auto"
    NEO_HOOKEAN = "neo-hookean"
    YEOH = "yeoh"


class CalibrationMethod(str, Enum):
    """Calibration fit: 'poly' (global least squares), 'mls' (moving least squares, host only) or 'auto'."""

    AUTO = "auto"
    POLY = "poly"
    MLS = "mls"


class Mcu(str, Enum):
    """The readout board's microcontroller: 'atmega328p' (Arduino Uno / Nano, 5 V) or 'rp2040' (3.3 V, native USB)."""

    ATMEGA328P = "atmega328p"
    RP2040 = "rp2040"


class BoardName(str, Enum):
    """The readout board (recipes/boards.toml): its pins, connector and flash, and the image it runs."""

    UNO = "uno"
    NANO = "nano"
    PICO = "pico"
    QTPY_RP2040 = "qtpy-rp2040"
    XIAO_RP2040 = "xiao-rp2040"
