"""The readout firmware: C sources rendered from the spec and the calibration.

:func:`render` -- ``(design, calibration) -> {relative path: bytes}``: the portable C core
(``magfab_readout/src``: MLX90393 protocol, conversion, calibration, frames, the loop), the Arduino sketch
and ``platformio.ini``, the bare-metal ATmega328P main and its Makefile, the cycle benchmark, the host
simulator with its harness, the avrdude flash scripts, and the EEPROM image (:data:`EEP_NAME`) holding the
calibration record the image reads at start-up and ``magfab-readout upload`` rewrites. Deterministic: the same
inputs give the same bytes.
Compiling them (avr-gcc, gcc, simavr) is :mod:`magfab.export.toolchain`'s job; this module holds the target's
constants both share.

The calibration is checked by :func:`magfab.formats.calibration_json.validate` (the one validator of the file);
on top, :class:`FirmwareError` refuses what the EEPROM record cannot hold (float32 range, order above
``MAX_ORDER`` of readout/src/magfab_readout/eeprom.py, a record over the EEPROM's 960 bytes before the sensor
identity).

Every chip number comes from the recipe (``magfab/recipes/chips.toml``); the few the recipe does not carry are
the named constants below, each with its source or marked as an assumption. The serial formats are those of
``docs/bundle.md``; :func:`calibration_sha256` is the hash the firmware's info line reports.
"""

from __future__ import annotations

import binascii
import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from importlib.resources import files
from typing import TYPE_CHECKING, Any

from ..board.plan import bus_mask
from ..check.links import F_CPU_HZ, twi_settings
from ..check.links import uart_settings as _uart
from ..errors import InputError
from ..formats import calibration_json
from ..formats.calibration_json import calibration_sha256
from ..models.chip import conversion_us  # the chip's pace, shared with the prediction
from ..models.reference import REFERENCE_SHIFT
from ..readout.src.magfab_readout import eeprom
from ..readout.src.magfab_readout.float32_bound import direction_band, float32_error_N
from ..recipes import resolve
from ..reference_chip import reference_chip
from . import rp2040
from .templating import render as render_template
from .templating import templates_dir

if TYPE_CHECKING:
    from ..design import Design

__all__ = [
    "AVR_CFLAGS",
    "EEP_NAME",
    "HEX_NAME",
    "HOST_CFLAGS",
    "ChipConfig",
    "FirmwareError",
    "calibration_sha256",
    "chip_config",
    "eeprom_record",
    "generic_sources",
    "image_settings",
    "info_line",
    "raw_words",
    "image_path",
    "ready_image",
    "render",
    "shipped_image",
    "twi_settings",
]

# ---- the target -------------------------------------------------------------------------------------------

MCU = "atmega328p"
HEX_NAME = "magfab-atmega328p.hex"
#: The EEPROM image beside it (Intel HEX from address 0): the calibration record the image reads.
EEP_NAME = "magfab-atmega328p.eep"
#: Flash left for the application under the 2 KB bootloader of older Nanos (Optiboot on the Uno takes 512 B).
FLASH_LIMIT_BYTES = 32 * 1024 - 2048
#: Static RAM allowed, leaving 512 of the 2048 bytes for the stack (float routines, frame buffers).
RAM_LIMIT_BYTES = 2048 - 512
#: Without a valid record the image does not touch the chip (it knows neither its address nor its settings) and
#: sends one error frame per this interval.
NO_RECORD_US = 20_000

#: Package data beside this module: the generic image (:func:`shipped_image`) and ``toolchain.json``, the avr-gcc
#: and avr-libc versions that made it (``python -m magfab.export.toolchain`` rebuilds both).
GENERIC_DIR = "generic_image"
GENERIC_TOOLCHAIN = "toolchain.json"
#: Beside them, what the image delivered on the project's simulated bus timed like a real one, across MagOne's
#: calibrated region (:func:`measured_rate`; ``python bench/firmware.py --record-rate`` measures and writes it).
GENERIC_RATE = "rate.json"
CORE_SOURCES = ("mlx90393.c", "mf_sample.c", "mf_nv.c", "mf_calib.c", "mf_frame.c", "mf_app.c", "mf_array.c",
                "mf_reference.c")
CORE_DIR = "magfab_readout/src"
AVR_CFLAGS = ("-mmcu=" + MCU, f"-DF_CPU={F_CPU_HZ}UL", "-Os", "-std=gnu99", "-Wall", "-Wextra",
              "-ffunction-sections", "-fdata-sections", "-flto")
AVR_LDFLAGS = ("-Wl,--gc-sections", "-lm")
HOST_CFLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wshadow", "-Wstrict-prototypes",
               "-Wdouble-promotion", "-O1")
HOST_PROGRAM = "host/magfab_host"

# ---- chip facts the recipe does not carry -----------------------------------------------------------------

#: HALLCONF the firmware programs: the setting the datasheet's sensitivity table (recipe) is given for.
HALLCONF = 0xC
#: Temperature channel, TCMP off: T = 25 C + (raw - T25) / TRES, both from recipes/chips.toml (datasheet Table 7).
#: The register code is written for this chip, so these are its figures by name, not by a spec key.
TEMPERATURE_RAW_25C = int(resolve.chip("mlx90393")["temperature_raw_25C"].nominal)
TEMPERATURE_LSB_PER_C = resolve.chip("mlx90393")["temperature_lsb_per_C"].nominal
#: How long after a conversion is due (the datasheet's table) the firmware reads it, as a fraction of the conversion.
#: Assumption: covers the read's own start-up and the timer's granularity; the reads then follow on a fixed grid one
#: conversion apart, so the margin does not accumulate and every conversion is read once. A chip slower than the
#: table is caught by the ERROR-bit retry below (the grid then re-anchors on the retry); one faster than the table
#: loses conversions in proportion.
READ_MARGIN = 0.05
#: Wait after RT before the next command. Assumption: the recipe has no start-up time; public drivers wait 1 to
#: 10 ms. Only recovery pays it.
RESET_WAIT_US = 5000
#: A read the chip rejects while it is still in its measuring mode (burst, or a single measurement not done) is
#: tried again after this fraction of the conversion: a slow oscillator, not a fault, until a single taxel's fails
#: twice (an array chip's is tried until a conversion's time has passed: mf_app_read_measurement).
RETRY_FRACTION = 0.25
START_TRIES = 3
#: While the chip does not answer: one error frame and one recovery attempt per interval.
LOST_RETRY_US = 100_000
#: I2C timeout per bus step: this many byte times at the bus clock, and never under the minimum.
I2C_TIMEOUT_BYTES = 10
I2C_TIMEOUT_MIN_US = 1000
#: Power-on register words of the simulated chip: HALLCONF 0xC, GAIN_SEL 7 (the datasheet default) plus a
#: reserved bit in reg 0, and COMM_MODE = I2C only in reg 1, so the tests catch a driver that overwrites bits
#: it does not own. Simulator only.
SIM_REGISTER_DEFAULTS = (0x047C, 0x6000, 0x0000)

class FirmwareError(InputError):
    """A calibration or spec value the firmware cannot carry (float32 range, the record's order, the EEPROM or
    image size): names the key path, the value and what is allowed. Exit 2."""

    def __init__(self, key: str, value: object, allowed: str) -> None:
        shown = repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        super().__init__(f"calibration.{key} = {shown}: {allowed}")


# ---- chip configuration -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ChipConfig:
    """What the firmware programs into the MLX90393 and what follows from it. Times in microseconds."""

    gain_sel: int
    resolution: int
    osr: int
    dig_filt: int
    zyxt: int  # channel bits: z 8, y 4, x 2, t 1
    burst: bool
    temperature: bool
    registers: tuple[tuple[int, int, int], ...]  # (address, mask, value) for registers 0, 1, 2
    lsb_xy_uT: float
    lsb_z_uT: float
    raw_signed: bool  # RES 0/1: two's complement words
    raw_zero: int  # word at zero field (RES 2: 32768, RES 3: 16384, else 0)
    raw_limit: int  # |counts| at the output limit: the saturation flag
    tconv_us: int  # one measurement of the zyxt channels: the datasheet's table (recipe), rounded up
    read_margin_us: int  # READ_MARGIN of it: how long after a conversion is due it is read

    @property
    def sample_rate_Hz(self) -> float:
        """Frames per second in burst mode: one per conversion (the reads are paced by the chip's table).
        Single mode adds the margin and the bus time to each sample."""
        return 1e6 / self.tconv_us


def _value(option: object) -> str:
    """An option's text, whether the spec holds the Enum or (a copy made without validation) the string."""
    return str(getattr(option, "value", option))


def chip_config(design: Design) -> ChipConfig:
    """The register words, scale and timing for the spec's sensor and firmware sections."""
    chip, s, fw = design.chip, design.spec.sensor, design.spec.firmware
    temperature = bool(fw.temperature)
    zyxt = 0x0E | (0x01 if temperature else 0)
    res = s.resolution
    registers = (
        (0x00, 0x01FF, HALLCONF | s.gain_sel << 4),  # Z_SERIES = 0, BIST = 0
        (0x01, 0x1FFF, zyxt << 6),  # BURST_DATA_RATE 0, BURST_SEL, TCMP_EN 0, EXT_TRG 0, WOC_DIFF 0
        (0x02, 0x1FFF, s.osr | s.dig_filt << 2 | res << 5 | res << 7 | res << 9),  # OSR2 = 0
    )
    tconv = math.ceil(round(conversion_us(chip, s.osr, s.dig_filt, temperature), 6))
    zero = int(chip[f"output_zero_res{res}_lsb"].nominal) if res >= 2 else 0
    return ChipConfig(
        gain_sel=s.gain_sel, resolution=res, osr=s.osr, dig_filt=s.dig_filt, zyxt=zyxt,
        burst=_value(fw.acquisition) == "burst", temperature=temperature, registers=registers,
        lsb_xy_uT=chip[f"sensitivity_xy_gain{s.gain_sel}_uT_per_lsb"].nominal * 2**res,
        lsb_z_uT=chip[f"sensitivity_z_gain{s.gain_sel}_uT_per_lsb"].nominal * 2**res,
        raw_signed=res < 2, raw_zero=zero, raw_limit=int(chip[f"output_limit_res{res}_lsb"].nominal),
        tconv_us=tconv, read_margin_us=math.ceil(tconv * READ_MARGIN),
    )


def raw_words(chip: ChipConfig, b_uT: tuple[float, float, float], t_C: float = 25.0) -> tuple[int, int, int, int]:
    """(T, X, Y, Z) words the chip would send for a field in microtesla (rounded, clipped at the output limit)."""
    words: list[int] = []
    for value, lsb in zip(b_uT, (chip.lsb_xy_uT, chip.lsb_xy_uT, chip.lsb_z_uT)):
        c = max(-chip.raw_limit, min(chip.raw_limit, round(value / lsb)))
        words.append(c & 0xFFFF if chip.raw_signed else chip.raw_zero + c)
    t = min(0xFFFF, max(0, round(TEMPERATURE_RAW_25C + (t_C - 25.0) * TEMPERATURE_LSB_PER_C)))
    x, y, z = words
    return (t if chip.temperature else 0, x, y, z)


def _serial(design: Design) -> tuple[int, float]:
    """:func:`_uart` of the spec's baud on an ATmega328P board; (0, 0.0) on an RP2040 board (USB: no baud)."""
    return (0, 0.0) if rp2040.is_rp2040(design.spec) else _uart(design.spec.firmware.baud)


# ---- calibration: the EEPROM record --------------------------------------------------------------------------


def _eeprom_module():
    """The readout package's ``eeprom`` module (the build's record and ``magfab-readout upload`` both pack with it)."""
    return eeprom


def _calibration_context(cal: Mapping[str, Any]) -> dict[str, Any]:
    """Validate a calibration.json dict (:func:`magfab.formats.calibration_json.validate`) and lay it out as the
    firmware evaluates it (the package's ``eeprom.layout``); what it cannot carry is a :class:`FirmwareError`."""
    return _layout(calibration_json.validate(dict(cal) if isinstance(cal, Mapping) else cal))


def _layout(checked: calibration_json.Checked) -> dict[str, Any]:
    ee = _eeprom_module()
    try:
        return ee.layout(checked)
    except ee.EepromError as exc:
        raise FirmwareError(exc.key, exc.value, exc.allowed) from None


def image_settings(design: Design) -> dict[str, Any]:
    """What the generic image reads from the record besides the calibration (the package's ``eeprom.SETTINGS``,
    docs/bundle.md section 4): every number the build-specific sources carried in mf_config.h, computed here from
    the spec and the chip's recipe. Plain JSON values: build.json carries them for ``magfab-readout upload``.
    An array's also carry ``taxel_addresses``: every chip's 7-bit address in taxel order (``i2c_address`` is
    taxel 0's), and one split over two I2C buses ``taxel_buses`` (bit k: taxel k on the second); a build with a
    reference chip ``reference`` (its 7-bit address) and ``reference_shift`` (its average's,
    :data:`magfab.models.reference.REFERENCE_SHIFT`).
    :class:`~magfab.errors.SpecError` for a baud or I2C clock the board cannot make."""
    ee = _eeprom_module()
    chip, fw = chip_config(design), design.spec.firmware
    ubrr = _serial(design)[0]
    twbr, twps, i2c_actual = twi_settings(fw.i2c_hz)
    flags = ((ee.FLAG_BURST if chip.burst else 0) | (ee.FLAG_TEMPERATURE if chip.temperature else 0)
             | (ee.FLAG_TEXT if _value(fw.output) == "text" else 0) | (ee.FLAG_RAW_SIGNED if chip.raw_signed else 0))
    regs = {reg: (mask, value) for reg, mask, value in chip.registers}
    array: dict[str, object] = {} if design.array is None else {
        "taxel_addresses": [t.i2c_address for t in design.taxels]}
    mask = bus_mask(design)
    if mask:  # taxels on a second bus (array.buses = 2): the record's mask
        array["taxel_buses"] = mask
    ref = reference_chip(design)
    if ref is not None:  # the record's reference block (version 5)
        array = {"reference": ref.i2c_address, "reference_shift": REFERENCE_SHIFT}
    return {
        **array,
        "name": design.spec.name, "gain_sel": chip.gain_sel, "resolution": chip.resolution, "osr": chip.osr,
        "dig_filt": chip.dig_filt, "i2c_address": design.i2c_address, "twbr": twbr, "twps_bits": twps,
        "flags": flags, "zyxt": chip.zyxt, "ubrr": ubrr, "baud": int(fw.baud), "i2c_hz": int(fw.i2c_hz),
        "i2c_timeout_us": max(I2C_TIMEOUT_MIN_US, math.ceil(I2C_TIMEOUT_BYTES * 9 * 1e6 / i2c_actual)),
        **{f"reg{k}_{part}": regs[k][n] for k in range(3) for n, part in enumerate(("mask", "value"))},
        "tconv_us": chip.tconv_us, "read_margin_us": chip.read_margin_us,
        "retry_us": math.ceil(chip.tconv_us * RETRY_FRACTION), "exit_wait_us": chip.tconv_us + chip.read_margin_us,
        "raw_zero": chip.raw_zero, "raw_limit": chip.raw_limit, "t_raw_25c": TEMPERATURE_RAW_25C,
        "lsb_xy_uT": chip.lsb_xy_uT, "lsb_z_uT": chip.lsb_z_uT, "t_c_per_lsb": 1.0 / TEMPERATURE_LSB_PER_C,
    }


def eeprom_record(design: Design, calibration: Mapping[str, Any]) -> bytes:
    """The EEPROM record of this calibration for this build's settings (docs/bundle.md section 4): what the .eep
    holds and ``magfab-readout upload`` writes. :class:`FirmwareError` when it does not fit the EEPROM's first
    960 bytes (``eeprom.RECORD_MAX``: the last 64 hold the sensor identity).

    An array's (version 3) holds the settings and every chip's address, no calibration (the host computes the
    forces); ``calibration`` (the build's, the readout package's calibration.json) only gives the info line's
    hash."""
    ee = _eeprom_module()
    settings = image_settings(design)
    try:
        if design.array is not None:
            return ee.pack_array(settings["taxel_addresses"], calibration_sha256(calibration)[:16], settings)
        return ee.pack(_calibration_context(calibration), calibration_sha256(calibration)[:16], settings)
    except ee.EepromError as exc:
        raise FirmwareError(exc.key, exc.value, exc.allowed) from None


# ---- rendering --------------------------------------------------------------------------------------------


def _bench_points(chip: ChipConfig, cal: dict[str, Any]) -> list[dict[str, Any]]:
    """Raw words for the cycle benchmark: the hull's centre (the quick inner-box accept), near a vertex (inside,
    the full hull test), on the axis (no direction split), outside the box."""
    hull = cal["hull"]
    bz = sum(p[0] for p in hull) / len(hull)
    br = sum(p[1] for p in hull) / len(hull)
    vz, vr = max(hull, key=lambda p: (p[0] - bz) ** 2 / (1e-9 + (cal["bz_hi"] - cal["bz_lo"]) ** 2)
                 + (p[1] - br) ** 2 / (1e-9 + (cal["br_hi"] - cal["br_lo"]) ** 2))
    edge = (bz + 0.97 * (vz - bz), br + 0.97 * (vr - br))
    far = (cal["bz_hi"] + (cal["bz_hi"] - cal["bz_lo"]) + 1.0, cal["br_hi"] * 2.0 + 1.0)
    out = []
    for name, (z, r) in (("centre", (bz, br)), ("edge", edge), ("axis", (bz, 0.0)), ("outside", far)):
        t, x, y, zz = raw_words(chip, (r / math.sqrt(2.0), r / math.sqrt(2.0), z), 31.0)
        out.append({"name": name, "t": t, "x": x, "y": y, "z": zz})
    return out


def info_line(name: str, sha16: str, chip: ChipConfig, taxels: int = 0) -> str:
    """The firmware's answer to 'i' (docs/bundle.md section 3), checksum and newline included (CRC-16/CCITT-FALSE
    as the frames'): the reference the tests hold the image's line to. An array's (``taxels`` chips) ends with
    ``,<taxels>``."""
    body = f"I,magfab,{name},{sha16},{chip.gain_sel},{chip.resolution},{chip.osr},{chip.dig_filt}"
    body += f",{taxels}" if taxels else ""
    return f"{body}*{binascii.crc_hqx(body.encode('utf-8'), 0xFFFF):04X}\n"


def _image_constants() -> dict[str, Any]:
    """What the generic image's sources take from magfab: firmware constants, none of them from a spec."""
    fallback_baud = _eeprom_module().FALLBACK_BAUD  # without a valid record (the package's upload knows it too)
    fallback_ubrr, fallback_error = _uart(fallback_baud)
    return {
        "generic": 1, "fallback_baud": fallback_baud, "fallback_ubrr": fallback_ubrr,
        "fallback_baud_error_pct": f"{fallback_error * 100:+.2f}", "no_record_us": NO_RECORD_US,
        "reset_wait_us": RESET_WAIT_US, "start_tries": START_TRIES, "lost_retry_us": LOST_RETRY_US,
    }


def _context(design: Design, calibration: Mapping[str, Any], generic: bool) -> dict[str, Any]:
    spec, recipe = design.spec, design.chip
    fw = spec.firmware
    chip = chip_config(design)
    checked = calibration_json.validate(dict(calibration))
    cal = _layout(checked)
    ubrr, baud_error = _serial(design)
    board, key = rp2040.readout_board(spec), rp2040.board_key(spec)
    on_rp2040 = rp2040.is_rp2040(spec)
    settings = image_settings(design)
    twbr, twps, i2c_actual = twi_settings(fw.i2c_hz)
    record = eeprom_record(design, calibration)
    forbidden = []
    for pair in recipe.texts.get("forbidden_osr_dig_filt", "").split():
        osr, dig_filt = (int(v) for v in pair.split("/"))
        forbidden.append(osr << 3 | dig_filt)
    regs = {reg: (mask, value) for reg, mask, value in chip.registers}
    return {
        **_image_constants(),
        "generic": int(generic),
        "record": list(record), "record_len": len(record), "sha16": calibration_sha256(calibration)[:16],
        "thermal": _eeprom_module().thermal(record),  # (T0, a_x, a_y, a_z) of a version-4 or -5 record, else None
        "reference": _eeprom_module().reference(record),  # (address, shift) of a version-5 record, else None
        "i2c_address": design.i2c_address,
        "sim_address": design.i2c_address,
        "i2c_hz": fw.i2c_hz,
        "i2c_actual_hz": i2c_actual,
        "twbr": twbr, "twps_bits": twps, "twps_div": 4**twps,
        "i2c_timeout_us": settings["i2c_timeout_us"],
        "i2c_timeout_bytes": I2C_TIMEOUT_BYTES, "i2c_timeout_min_us": I2C_TIMEOUT_MIN_US,
        "baud": fw.baud, "ubrr": ubrr, "baud_error_pct": f"{baud_error * 100:+.2f}",
        "text_output": int(_value(fw.output) == "text"),
        "burst": int(chip.burst), "temperature": int(chip.temperature), "zyxt": chip.zyxt, "axes": 3,
        "gain_sel": chip.gain_sel, "resolution": chip.resolution, "osr": chip.osr, "dig_filt": chip.dig_filt,
        "hallconf": HALLCONF,
        "reg0_mask": regs[0][0], "reg0_value": regs[0][1], "reg1_mask": regs[1][0], "reg1_value": regs[1][1],
        "reg2_mask": regs[2][0], "reg2_value": regs[2][1],
        "lsb_xy_uT": chip.lsb_xy_uT, "lsb_z_uT": chip.lsb_z_uT,
        "raw_signed": int(chip.raw_signed), "raw_zero": chip.raw_zero, "raw_limit": chip.raw_limit,
        "t_raw_25c": TEMPERATURE_RAW_25C, "t_lsb_per_c": TEMPERATURE_LSB_PER_C,
        "t_c_per_lsb": 1.0 / TEMPERATURE_LSB_PER_C,
        "tconv_us": chip.tconv_us, "read_margin_us": chip.read_margin_us, "margin_pct": round(READ_MARGIN * 100),
        "tconv_ms": f"{chip.tconv_us / 1000:.3f}",
        "array": design.array is not None,  # an array's image reads its chips in turn, each read waited for
        "measured_rate": "" if design.array is not None else _measured_line(design, calibration),
        "float32_bound": "" if design.array is not None else _float32_line(checked),
        "retry_us": settings["retry_us"], "exit_wait_us": settings["exit_wait_us"],
        "board_pullups": bool(spec.pcb.pullups),
        "hex_name": HEX_NAME, "eep_name": EEP_NAME,
        "rp2040": on_rp2040, "board_name": board.name, "board_key": key,
        "uf2_name": rp2040.image_name(key),
        "calibration_uf2": rp2040.CALIBRATION_UF2,
        # the RP2040 Makefile's: toolchain.build_rp2040's flags and sources, in its order
        "arm_cflags": " ".join(rp2040.ARM_CFLAGS), "arm_ldflags": " ".join(rp2040.ARM_LDFLAGS),
        "arm_defines": " ".join(rp2040.defines(key)) if on_rp2040 else "",
        "boot2_cflags": " ".join(rp2040.BOOT2_CFLAGS), "rp2040_sources": " ".join(rp2040.RP2040_SOURCES),
        "avr_cflags": " ".join(AVR_CFLAGS), "avr_ldflags": " ".join(AVR_LDFLAGS),
        "host_cflags": " ".join(HOST_CFLAGS),
        "core_src_make": " ".join(f"$(CORE)/{s}" for s in CORE_SOURCES),
        "bench_points": _bench_points(chip, cal),
        # the simulator's own tables: every gain and resolution, straight from the recipe
        "sens_xy": [recipe[f"sensitivity_xy_gain{g}_uT_per_lsb"].nominal for g in range(8)],
        "sens_z": [recipe[f"sensitivity_z_gain{g}_uT_per_lsb"].nominal for g in range(8)],
        "out_limit": [int(recipe[f"output_limit_res{r}_lsb"].nominal) for r in range(4)],
        "out_zero": [0, 0, int(recipe["output_zero_res2_lsb"].nominal), int(recipe["output_zero_res3_lsb"].nominal)],
        "tconvm_offset": recipe["tconvm_offset_us"].nominal, "tconvm_step": recipe["tconvm_step_us"].nominal,
        "tconvt_step": recipe["tconvt_step_us"].nominal,
        "tconv_table": [[recipe[f"tconv_osr{o}_dig_filt{d}_ms"].nominal * 1000.0 for o in range(4)] for d in range(8)],
        "forbidden": forbidden,
        "reg_default": list(SIM_REGISTER_DEFAULTS),
    }


def render(design: Design, calibration: Mapping[str, Any], *, generic: bool = True) -> dict[str, bytes]:
    """Every firmware file, keyed by its path relative to the bundle's firmware folder.

    ``generic`` (the default, what a build ships): the image's sources carry no setting of the spec; it reads them
    from the EEPROM record (:func:`image_settings`), so it is the same image for every build, the one shipped
    in the wheel (:mod:`magfab.export.generic_image`). ``generic=False`` compiles the spec's settings in as
    constants (the record must then match them): what bench/firmware.py measures the generic one against.

    ``calibration`` is a calibration.json dict (docs/bundle.md); :class:`FirmwareError` names the key of
    anything the firmware cannot carry, :class:`~magfab.errors.SpecError` a spec the board cannot run
    (a baud rate the 16 MHz UART cannot make). ``*.j2`` templates are rendered (stripped of the suffix), other
    files copied; ``.bat`` files get CRLF line ends."""
    context = _context(design, calibration, generic)
    on_rp2040 = context["rp2040"]
    out = _render_tree(context, lambda rel: _for_target(rel, on_rp2040))
    if on_rp2040:  # the record in the board's flash sector (rp2040.calibration_uf2); the image .uf2 is the pipeline's
        out[rp2040.CALIBRATION_UF2] = rp2040.calibration_uf2(context["board_key"], bytes(context["record"]))
        out[f"{rp2040.RP2040_DIR}/uf2.py"] = rp2040.uf2_source()  # the Makefile's UF2 writer: magfab's, verbatim
    else:
        out[EEP_NAME] = _eeprom_module().intel_hex(bytes(context["record"]))
    return dict(sorted(out.items()))


RECORD_CAPTIONS = {  # the record's files in a build (the rest of render's are "firmware source")
    EEP_NAME: "EEPROM image beside the .hex: the calibration record the image reads (docs/bundle.md section 4)",
    rp2040.CALIBRATION_UF2: "the calibration record alone, in the board's flash sector: copy it onto the RPI-RP2 drive "
                            "of a board that runs the image, or write it with magfab-readout upload (docs/bundle.md "
                            "section 4)",
}

#: What only an ATmega328P board's bundle holds (its image, flash scripts, sketch, PlatformIO), and an RP2040 board's.
_AVR_ONLY = ("avr/", "flash.sh", "flash.bat", "platformio.ini", "magfab_readout/magfab_readout.ino")
_RP2040_ONLY = (rp2040.RP2040_DIR + "/",)


def _for_target(rel: str, on_rp2040: bool) -> bool:
    """Whether template ``rel`` belongs in the bundle of an RP2040 board (``on_rp2040``) or an ATmega328P one."""
    return not rel.startswith(_AVR_ONLY if on_rp2040 else _RP2040_ONLY)


def _render_tree(context: Mapping[str, Any], wanted) -> dict[str, bytes]:
    """The firmware templates whose relative path ``wanted`` accepts, rendered with ``context``."""
    root = templates_dir() / "firmware"
    out: dict[str, bytes] = {}
    for path in sorted(p for p in root.rglob("*") if p.is_file() and "__pycache__" not in p.parts):
        rel = path.relative_to(root).as_posix()
        if not wanted(rel):
            continue
        if rel.endswith(".j2"):
            text = render_template(f"firmware/{rel}", **context)
            rel = rel[:-3]
        else:
            text = path.read_text(encoding="utf-8")
        if rel.endswith(".bat"):
            text = text.replace("\r\n", "\n").replace("\n", "\r\n")
        out[rel] = text.encode("utf-8")
    return out


def generic_sources(target: str = "avr") -> dict[str, bytes]:
    """The sources of the generic image, keyed as in :func:`render`: the core and ``avr/main.c`` (``target``
    "avr") or ``rp2040/`` ("rp2040"), rendered without a spec, byte-equal to every build's copies (a test holds them
    to it). :func:`toolchain.build_hex` of the AVR's is the shipped image, :func:`toolchain.build_rp2040` of the
    RP2040's with a board's :func:`rp2040.defines` that board's."""
    def wanted(rel: str) -> bool:
        if rel.startswith(CORE_DIR + "/"):
            return "mf_nv_image" not in rel
        if target == "avr":
            return rel == "avr/main.c.j2"
        return rel.startswith(rp2040.RP2040_DIR + "/") and not rel.endswith("Makefile.j2")  # the image's, not a board's
    return _render_tree(_image_constants(), wanted)


def image_path(design: Design) -> str:
    """Where the build puts its ready-to-flash file: the .hex, or an RP2040 board's .uf2."""
    key = rp2040.board_key(design.spec)
    return f"firmware/{rp2040.image_name(key) if rp2040.is_rp2040(design.spec) else HEX_NAME}"


def ready_image(design: Design, calibration: Mapping[str, Any]) -> tuple[str, bytes, str]:
    """The build's ready-to-flash file (:func:`image_path`, bytes, caption): the shipped .hex (its record the .eep
    beside it), or an RP2040 board's shipped image with this build's record in one .uf2 (:func:`rp2040.build_uf2`)."""
    board, key = rp2040.readout_board(design.spec), rp2040.board_key(design.spec)
    if rp2040.is_rp2040(design.spec):
        _, made = rp2040.shipped_image(key)
        return (image_path(design), rp2040.build_uf2(key, eeprom_record(design, calibration)),
                f"ready-to-flash image and calibration for the {board.name}: copy it onto the RPI-RP2 drive (BOOTSEL); "
                f"the image the same for every build, flash {made['flash_bytes']} B, RAM {made['ram_bytes']} B "
                f"({made['toolchain']['arm-none-eabi-gcc']})")
    image, made = shipped_image()
    return (image_path(design), image, "ready-to-flash image for Arduino Uno/Nano (ATmega328P, 16 MHz), the same "
            f"for every build: settings and calibration from the .eep; flash {made['flash_bytes']} B, RAM "
            f"{made['ram_bytes']} B ({made['toolchain']['avr-gcc']}, avr-libc {made['toolchain']['avr-libc']})")


def shipped_image() -> tuple[bytes, dict[str, Any]]:
    """The generic image in the package (Intel HEX bytes) and ``toolchain.json``: the avr-gcc and avr-libc versions
    that built it, its flash and RAM, the sha256 of the image and of :func:`generic_sources`. One image for every
    build and machine, with or without avr-gcc: the settings and calibration come from the build's .eep."""
    folder = files("magfab.export").joinpath(GENERIC_DIR)
    return folder.joinpath(HEX_NAME).read_bytes(), json.loads(folder.joinpath(GENERIC_TOOLCHAIN).read_text())


@cache
def measured_rate() -> dict[str, Any] | None:
    """What the shipped image delivered on the simulated bus timed like a real one (:data:`GENERIC_RATE`): the
    chip's conversion rate, and at the worst, median and best of the fields measured across the calibrated region of
    the build it names, the frames a second, the share of the chip's conversions and the processor's busy time a
    frame, and the settings it ran with (:func:`rate_settings`). None when the package holds no record, or one of
    another image (the image was rebuilt since). Read once a process (a build quotes it three times: the firmware
    README, the report, predictions.json)."""
    folder = files("magfab.export").joinpath(GENERIC_DIR)
    record = folder.joinpath(GENERIC_RATE)
    if not record.is_file():
        return None
    data = json.loads(record.read_text())
    image, _ = shipped_image()
    return data if data.get("image_sha256") == hashlib.sha256(image).hexdigest() else None


def rate_settings(design: Design) -> dict[str, Any]:
    """What a single taxel's rate depends on besides its calibration: the conversion time the reads are paced by,
    burst or single measurements, the frames' transport and baud, the I2C clock, and a reference chip (its read every
    other sample)."""
    fw = design.spec.firmware
    return {"tconv_us": chip_config(design).tconv_us, "acquisition": _value(fw.acquisition),
            "output": _value(fw.output), "baud": int(fw.baud), "i2c_hz": int(fw.i2c_hz),
            "reference": reference_chip(design) is not None}


def rate_mismatch(design: Design, calibration: Mapping[str, Any] | None, measured: Mapping[str, Any]) -> list[str]:
    """How this build differs from the one :func:`measured_rate` measured, setting by setting ([] when it does not):
    an array, another :func:`rate_settings`, or (``calibration``: its ``method`` and ``order``, None when not yet
    made) another method or a higher order, whose cost a sample is more."""
    if design.array is not None or rp2040.is_rp2040(design.spec):
        return ["an array (its rate: docs/bundle.md section 3)" if design.array is not None
                else "an RP2040 board (the measured rate is the ATmega328P image's)"]
    ran, mine = measured.get("settings") or {}, rate_settings(design)
    out = [f"{k} {mine[k]} (measured: {ran.get(k)})" for k in mine if ran.get(k) != mine[k]]
    cal = measured["calibration"]
    if calibration is not None and calibration.get("method") != cal.get("method"):
        out.append(f"a {calibration.get('method')} calibration (measured: {cal.get('method')})")
    if calibration is not None and int(calibration.get("order", 0)) > int(cal["order"]):
        out.append(f"calibration order {calibration.get('order')} (measured: {cal['order']})")
    return out


def measured_rate_for(design: Design, calibration: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """:func:`measured_rate` when it is this build's (no :func:`rate_mismatch`), else None: a build quotes the measured
    rate only where it was measured with the build's own settings and a calibration like its own."""
    measured = measured_rate()
    return measured if measured is not None and not rate_mismatch(design, calibration, measured) else None


def _measured_line(design: Design, calibration: Mapping[str, Any]) -> str:
    """The firmware README's sentence on the measured rate (:func:`measured_rate_for`), "" without a record; a build
    the record does not apply to is told how it differs, and no figure."""
    measured = measured_rate()
    if measured is None:
        return ""
    w, cal = measured["worst"], measured["calibration"]
    differs = rate_mismatch(design, calibration, measured)
    if differs:
        return (f"Not measured for this build: the shipped image's rate was measured with {cal['spec']}'s settings "
                f"and calibration, and this build has {'; '.join(differs)}.")
    return (f"Measured: {w['rate_Hz']:.0f} frames/s, {w['delivered']:.1%} of the chip's {measured['chip_Hz']:.1f} "
            f"conversions/s at the busiest of {measured['fields']} fields across {cal['spec']}'s calibrated region "
            f"(the processor busy {w['busy_us']:.0f} of {w['cycle_us']:.0f} us a frame), the shipped image with that "
            f"calibration (order {cal['order']}, {cal['hull_points']}-point region) on a simulated bus timed like a "
            f"real {measured['i2c_Hz'] / 1000:.0f} kHz one.")


def _float32_line(checked: calibration_json.Checked) -> str:
    """The firmware README's sentence on how far its float32 forces can be from float64 ones of the build's
    calibration.json (:func:`float32_error_N`)."""
    fz, fxy = float32_error_N(checked)
    lo, hi = direction_band(checked)
    near = (f"; it does not hold for a Br from {lo:.6g} to {hi:.6g} uT, about direction_min_uT, where one evaluation "
            "may give a lateral force and the other none") if checked.direction_min_uT > 0 else ""
    return (f"The image's forces are within {fz:.2g} N (Fz) and {fxy:.2g} N (Fx, Fy) of a float64 evaluation of "
            "calibration.json wherever the temperature-corrected field is inside the valid region's box, at any chip "
            "temperature: a bound worked out from this calibration's own numbers, each float32 operation allowed one "
            f"unit in the last place (the readout package's `float32_bound.py`, docs/bundle.md section 2){near}.")

