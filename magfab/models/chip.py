"""The chip's conversion time from its recipe (the datasheet's table): one light module the prediction and the
firmware both read, so importing the firmware renderer does not load the models' numerics.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..recipes import Recipe

__all__ = ["conversion_us"]


def conversion_us(chip: Recipe, osr: int, dig_filt: int, temperature: bool, axes: int = 3) -> float:
    """One measurement of ``axes`` magnetic axes (and T), us, from the datasheet's table of full (ZYXT)
    measurements in the recipe (``tconv_osr<o>_dig_filt<d>_ms``); fewer channels take off the Table 8 formula's
    per-channel time (TCONVM per axis, TCONVT for T at OSR2 = 0)."""
    full = chip[f"tconv_osr{osr}_dig_filt{dig_filt}_ms"].nominal * 1000.0
    axis = chip["tconvm_offset_us"].nominal + chip["tconvm_step_us"].nominal * 2**osr * (2 + 2**dig_filt)
    temp = chip["tconvm_offset_us"].nominal + chip["tconvt_step_us"].nominal
    return full - (3 - axes) * axis - (0.0 if temperature else temp)
