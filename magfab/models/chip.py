"""The chip's figures from its recipe and the spec's register fields: conversion time (the datasheet's table),
scale, full scale and noise. One light module the prediction, the calibration, the scan and the reference chip
read, and the firmware too, so importing the firmware renderer does not load the models' numerics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..units import GAUSS_PER_MT, UT_PER_GAUSS

if TYPE_CHECKING:
    from ..design import Design
    from ..recipes import Recipe

__all__ = ["ChipSetting", "chip_setting", "conversion_us", "noise"]

G_PER_UT = 1.0 / UT_PER_GAUSS


def conversion_us(chip: Recipe, osr: int, dig_filt: int, temperature: bool, axes: int = 3) -> float:
    """One measurement of ``axes`` magnetic axes (and T), us, from the datasheet's table of full (ZYXT)
    measurements in the recipe (``tconv_osr<o>_dig_filt<d>_ms``); fewer channels take off the Table 8 formula's
    per-channel time (TCONVM per axis, TCONVT for T at OSR2 = 0)."""
    full = chip[f"tconv_osr{osr}_dig_filt{dig_filt}_ms"].nominal * 1000.0
    axis = chip["tconvm_offset_us"].nominal + chip["tconvm_step_us"].nominal * 2**osr * (2 + 2**dig_filt)
    temp = chip["tconvm_offset_us"].nominal + chip["tconvt_step_us"].nominal
    return full - (3 - axes) * axis - (0.0 if temperature else temp)


@dataclass(frozen=True)
class ChipSetting:
    """The MLX90393 at the spec's GAIN_SEL / RES / OSR / DIG_FILT: scale, full scale, noise, timing."""

    gain_sel: int
    resolution: int
    osr: int
    dig_filt: int
    lsb_xy_uT: float
    lsb_z_uT: float
    full_scale_xy_G: float
    full_scale_z_G: float
    saturation_onset_G: float
    noise_xy_G: float  # chip's own RMS noise (upper bound, see recipe), without quantisation
    noise_z_G: float
    conversion_ms: float  # one T+X+Y+Z measurement

    @property
    def rate_Hz(self) -> float:
        return 1000.0 / self.conversion_ms


def chip_setting(design: Design) -> ChipSetting:
    """Scale, range, noise and conversion time from the chip recipe and the spec's register fields.

    Noise: the datasheet gives RMS noise only as curves against conversion time; the recipe holds the plot's
    axis end at the shortest conversion as an upper bound, and white noise averaged over a longer conversion
    falls as 1/sqrt(conversion time).
    """
    chip = design.chip
    s = design.spec.sensor
    scale = 2 ** s.resolution
    lsb_xy = chip[f"sensitivity_xy_gain{s.gain_sel}_uT_per_lsb"].nominal * scale
    lsb_z = chip[f"sensitivity_z_gain{s.gain_sel}_uT_per_lsb"].nominal * scale
    limit = chip[f"output_limit_res{s.resolution}_lsb"].nominal
    t_axis = chip["tconvm_offset_us"].nominal + chip["tconvm_step_us"].nominal * 2 ** s.osr * (2 + 2 ** s.dig_filt)
    tconv_us = conversion_us(chip, s.osr, s.dig_filt, bool(design.spec.firmware.temperature))  # the firmware's pace
    averaging = math.sqrt(chip["noise_reference_conversion_us"].nominal / t_axis)
    return ChipSetting(
        s.gain_sel, s.resolution, s.osr, s.dig_filt, lsb_xy, lsb_z,
        full_scale_xy_G=limit * lsb_xy * G_PER_UT, full_scale_z_G=limit * lsb_z * G_PER_UT,
        saturation_onset_G=chip["saturation_onset_mT"].nominal * GAUSS_PER_MT,
        noise_xy_G=chip["noise_xy_bound_uT"].nominal * G_PER_UT * averaging,
        noise_z_G=chip["noise_z_bound_uT"].nominal * G_PER_UT * averaging,
        conversion_ms=tconv_us / 1000.0,
    )


def noise(design: Design, chip: ChipSetting) -> dict[str, float]:
    """RMS field noise at the sensor, G: environment, chip, quantisation (LSB / sqrt 12), and the totals."""
    env = design.spec.predict.noise_G
    q_xy, q_z = chip.lsb_xy_uT * G_PER_UT / math.sqrt(12), chip.lsb_z_uT * G_PER_UT / math.sqrt(12)
    return {
        "environment_G": env, "chip_xy_G": chip.noise_xy_G, "chip_z_G": chip.noise_z_G,
        "quantisation_xy_G": q_xy, "quantisation_z_G": q_z,
        "total_xy_G": math.sqrt(env**2 + chip.noise_xy_G**2 + q_xy**2),
        "total_z_G": math.sqrt(env**2 + chip.noise_z_G**2 + q_z**2),
    }
