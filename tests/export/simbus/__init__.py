"""The shipped .hex on a simulated MLX90393 bus: ``mlxbus.c`` (libsimavr + the build's chip model) compiled into a
shared library and driven through ctypes.

    lib = build_library(build_dir, out_dir)     # cc + pkg-config simavr; None when either is missing
    bus = Bus(lib, build_dir / "firmware" / "magfab-atmega328p.hex", addr7=0x0C,
              eep=build_dir / "firmware" / "magfab-atmega328p.eep")   # the EEPROM avrdude would write
    bus.set_field(bx_uT, by_uT, bz_uT, t_C)
    bus.ramp((bx_uT, by_uT, bz_uT), 20.0, 500.0, -0.0012)   # or a temperature ramp: 500 C per simulated s
    data = bus.run_us(20_000)                   # UART bytes the image sent in that simulated time

An array: :meth:`Bus.add_chip` puts more chip models on the bus, :meth:`Bus.target` picks the one the per-chip
calls act on (``bus.target(2).set_field(...)``).

Faults: :meth:`Bus.chip_fault` (inside the chip model: ``error``, ``short``, ``reset``, ``stuck``),
:meth:`Bus.nack`, :meth:`Bus.all_ff`, :meth:`Bus.hang_us`, :meth:`Bus.absent`, :meth:`Bus.reset_in` (on the bus).

Timing: :meth:`Bus.real_timing` times I2C as a real bus at the image's SCL clock (simavr alone: about 9 us a byte).
A profile of the image: :meth:`Bus.profile_start`, then :attr:`Bus.profile` (program-counter samples, and those
taken while a TWI step was in flight) grouped by :func:`grouped` over the ELF's :func:`functions`.
:func:`region_fields` samples a calibration's region.
"""

from __future__ import annotations

import ctypes
import math
import re
import shutil
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
F_CPU_HZ = 16_000_000
#: enum sim_fault of firmware/host/sim_mlx90393.h
CHIP_FAULTS = {"nack": 0, "error": 1, "short": 2, "trunc": 3, "timeout": 4, "stuck": 5, "reset": 6}
_CPU_DONE = 5  # sim_avr.h: cpu_Done, then cpu_Crashed


class HarnessUnavailable(Exception):
    """The harness cannot be built here (the reason says which tool or library is missing)."""


def build_library(build_dir: Path, out_dir: Path) -> Path:
    """Compile mlxbus.c with the build's chip model into ``out_dir/libmlxbus.so``; raises
    :class:`HarnessUnavailable` when cc, pkg-config or libsimavr-dev is missing."""
    for tool in ("cc", "pkg-config"):
        if shutil.which(tool) is None:
            raise HarnessUnavailable(f"{tool} is not installed")
    flags = subprocess.run(["pkg-config", "--cflags", "--libs", "simavr"], capture_output=True, text=True)
    if flags.returncode != 0:
        raise HarnessUnavailable("libsimavr is not installed (Debian package libsimavr-dev; .ci/run installs it)")
    fw = Path(build_dir) / "firmware"
    lib = Path(out_dir) / "libmlxbus.so"
    command = ["cc", "-std=gnu99", "-O2", "-Wall", "-Wextra", "-Werror", "-shared", "-fPIC", "-o", str(lib),
               f"-I{fw / 'host'}", f"-I{fw / 'magfab_readout' / 'src'}", str(HERE / "mlxbus.c"),
               str(fw / "host" / "sim_mlx90393.c"), *flags.stdout.split(), "-lm"]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=120)
    if proc.returncode != 0:
        raise RuntimeError(f"building the bus harness failed:\n{proc.stderr[-3000:]}")
    return lib


def read_intel_hex(text: str) -> list[tuple[int, bytes]]:
    """(address, bytes) of each data record of an Intel HEX file (checksums checked)."""
    out = []
    for line in text.split():
        raw = bytes.fromhex(line[1:])
        if sum(raw) & 0xFF:
            raise ValueError(f"bad Intel HEX checksum: {line}")
        if raw[3] == 0:
            out.append((raw[1] << 8 | raw[2], raw[4:4 + raw[0]]))
    return out


def _declare(lib: ctypes.CDLL) -> ctypes.CDLL:
    p, u8, u16, u32, u64, d = (ctypes.c_void_p, ctypes.c_uint8, ctypes.c_uint16, ctypes.c_uint32,
                               ctypes.c_uint64, ctypes.c_double)
    signatures = {
        "bus_open": (p, [ctypes.c_char_p, u8, u32]), "bus_run_until": (ctypes.c_int, [p, u64]),
        "bus_time_us": (u64, [p]), "bus_take_uart": (u32, [p, ctypes.c_char_p, u32]),
        "bus_send_uart": (None, [p, u8]), "bus_set_field": (None, [p, d, d, d, d]),
        "bus_chip_fault": (None, [p, ctypes.c_int, u16]), "bus_nack": (None, [p, u32, u32]),
        "bus_ff_reads": (None, [p, u32]), "bus_reset_in": (None, [p, u32]), "bus_hang_us": (None, [p, u64]),
        "bus_absent": (None, [p, ctypes.c_int]), "bus_clock_scale": (None, [p, d]), "bus_status_fixes": (u32, [p]),
        "bus_phases": (u32, [p]),
        "bus_held": (u32, [p]), "bus_uart_cycles_per_byte": (u32, [p]), "bus_chip_register": (u16, [p, u8]),
        "bus_chip_mode": (ctypes.c_int, [p]), "bus_conversion_us": (d, [p]), "bus_conversions": (u64, [p]),
        "bus_close": (None, [p]), "bus_eeprom_set": (ctypes.c_int, [p, u16, ctypes.c_char_p, u32]),
        "bus_eeprom_get": (ctypes.c_int, [p, u16, ctypes.c_char_p, u32]),
        "bus_add_chip": (ctypes.c_int, [p, u8]), "bus_target": (None, [p, u8]),
        "bus_ramp": (None, [p, d, d, d, d, d, d, d]), "bus_real_timing": (None, [p, ctypes.c_int]),
        "bus_profile": (None, [p, ctypes.c_void_p, u32]), "bus_profile_bus_samples": (u32, [p]),
        "bus_timed_steps": (u32, [p]), "bus_byte_us": (d, [p]),
    }
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    return lib


class Bus:
    """One ATmega328P running ``hex_path`` with a simulated MLX90393 at ``addr7`` on its TWI bus."""

    def __init__(self, lib: Path, hex_path: Path, addr7: int, eep: Path | None = None) -> None:
        self._lib = _declare(ctypes.CDLL(str(lib)))
        self._h = self._lib.bus_open(str(hex_path).encode(), addr7, F_CPU_HZ)
        if not self._h:
            raise OSError(f"simavr cannot load {hex_path}")
        self._buf = ctypes.create_string_buffer(1 << 20)
        self._hist: ctypes.Array | None = None  # the profiler's counters (profile_start)
        if eep is not None:
            for address, data in read_intel_hex(Path(eep).read_text()):
                if self._lib.bus_eeprom_set(self._h, address, data, len(data)) != 0:
                    raise OSError(f"simavr cannot load {eep} into the EEPROM")

    def add_chip(self, addr7: int) -> int:
        """Another chip model on the bus at ``addr7`` (an array's); its index for :meth:`target`."""
        k = self._lib.bus_add_chip(self._h, addr7)
        if k < 0:
            raise ValueError("the harness holds at most 16 chips")
        return k

    def target(self, k: int) -> Bus:
        """The chip (index: 0 the first, then in :meth:`add_chip` order) that the per-chip calls act on: the
        field, chip faults, address NACKs, absent, reset_in, clock_scale, register, chip_mode, conversions."""
        self._lib.bus_target(self._h, k)
        return self

    def eeprom_set(self, offset: int, data: bytes) -> None:
        """Bytes into the EEPROM now (as a programmer would write them)."""
        if self._lib.bus_eeprom_set(self._h, offset, bytes(data), len(data)) != 0:
            raise OSError("simavr cannot write the EEPROM")

    def eeprom(self, offset: int, size: int) -> bytes:
        """The EEPROM's bytes now."""
        out = ctypes.create_string_buffer(size)
        if self._lib.bus_eeprom_get(self._h, offset, out, size) != 0:
            raise OSError("simavr cannot read the EEPROM")
        return out.raw

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._h:
            self._lib.bus_close(self._h)
            self._h = None

    def run_us(self, dt_us: float) -> bytes:
        """Run ``dt_us`` of simulated time; the bytes the image sent on its UART meanwhile."""
        state = self._lib.bus_run_until(self._h, self.time_us + int(dt_us))
        if state >= _CPU_DONE:
            raise RuntimeError(f"the AVR core stopped (simavr state {state})")
        n = self._lib.bus_take_uart(self._h, self._buf, len(self._buf))
        return self._buf.raw[:n]

    def send(self, data: bytes) -> None:
        """Bytes from the host to the image's UART."""
        for c in data:
            self._lib.bus_send_uart(self._h, c)

    def set_field(self, bx_uT: float, by_uT: float, bz_uT: float, t_C: float = 25.0) -> None:
        self._lib.bus_set_field(self._h, bx_uT, by_uT, bz_uT, t_C)

    def ramp(self, b_uT: tuple[float, float, float], t_start_C: float, rate_C_per_s: float, alpha_per_C: float,
             t_ref_C: float = 25.0) -> None:
        """A temperature ramp from now on: the chip's temperature t_start_C + rate_C_per_s x elapsed (simulated
        time) and its field ``b_uT`` x (1 + alpha_per_C (T - t_ref_C)), served whenever the image reads the chip;
        :meth:`set_field` ends it."""
        self._lib.bus_ramp(self._h, *b_uT, t_start_C, rate_C_per_s, alpha_per_C, t_ref_C)

    def chip_fault(self, name: str, count: int = 1) -> None:
        """A fault inside the chip model: ``error`` (next commands rejected), ``short`` (RM one word short),
        ``reset`` (power-on now: registers to defaults, RS pending), ``stuck`` (conversions stop until RT)."""
        self._lib.bus_chip_fault(self._h, CHIP_FAULTS[name], count)

    def nack(self, addr_phases: int = 0, data_bytes: int = 0) -> None:
        """The next address phases / written data bytes for the chip get no ACK."""
        self._lib.bus_nack(self._h, addr_phases, data_bytes)

    def all_ff(self, reads: int = 1) -> None:
        """The next reads are ACKed and then read all 0xFF (the chip lets SDA go)."""
        self._lib.bus_ff_reads(self._h, reads)

    def reset_in(self, phases: int) -> None:
        """The chip restarts at the start of the ``phases``-th address phase from now (1: the next)."""
        self._lib.bus_reset_in(self._h, phases)

    def hang_us(self, us: float) -> None:
        """From the next TWI step on, every step for ``us`` microseconds is held (SCL low): TWINT never comes."""
        self._lib.bus_hang_us(self._h, int(us))

    def absent(self, on: bool) -> None:
        """The chip off the bus (nothing ACKs) or back on it."""
        self._lib.bus_absent(self._h, int(on))

    def clock_scale(self, scale: float) -> None:
        """The chip's conversions take ``scale`` times the datasheet table's time from now on (a slow oscillator)."""
        self._lib.bus_clock_scale(self._h, scale)

    def real_timing(self, on: bool = True) -> None:
        """I2C timed as on a real bus at the SCL clock the image sets, from now on (mlxbus.c), or as simavr times it."""
        self._lib.bus_real_timing(self._h, int(on))

    def profile_start(self, period_cycles: int = 37) -> None:
        """Sample where the CPU is every ``period_cycles`` from now on (a prime: no loop's period aliases it)."""
        self._hist = (ctypes.c_uint32 * PROFILE_WORDS)()
        self._lib.bus_profile(self._h, ctypes.cast(self._hist, ctypes.c_void_p), period_cycles)

    @property
    def profile(self) -> tuple[dict[int, int], int]:
        """(samples by byte address of the program counter, samples taken while a TWI step was in flight) since
        :meth:`profile_start`."""
        counts = {2 * w: n for w, n in enumerate(self._hist or ()) if n}
        return counts, self._lib.bus_profile_bus_samples(self._h)

    def register(self, reg: int) -> int:
        """The chip model's register ``reg`` now."""
        return self._lib.bus_chip_register(self._h, reg)

    time_us = property(lambda self: self._lib.bus_time_us(self._h))
    phases = property(lambda self: self._lib.bus_phases(self._h), doc="address phases on the bus so far")
    status_fixes = property(lambda self: self._lib.bus_status_fixes(self._h))
    held = property(lambda self: self._lib.bus_held(self._h), doc="TWI steps held by hang_us")
    timed_steps = property(lambda self: self._lib.bus_timed_steps(self._h), doc="TWI steps given real timing")
    byte_us = property(lambda self: self._lib.bus_byte_us(self._h),
                       doc="the address and data bytes' mean time from the firmware's start of the step to TWINT, us")
    uart_cycles_per_byte = property(lambda self: self._lib.bus_uart_cycles_per_byte(self._h))
    chip_mode = property(lambda self: self._lib.bus_chip_mode(self._h), doc="0 idle, 1 burst, 2 single")
    conversion_us = property(lambda self: self._lib.bus_conversion_us(self._h),
                             doc="the chip's conversion time at its current registers, us")
    conversions = property(lambda self: self._lib.bus_conversions(self._h),
                           doc="conversions completed since the chip's burst started")


#: Flash words the profile counts (the ATmega328P's 32 KB; mlxbus.c's PROFILE_WORDS).
PROFILE_WORDS = 16384
#: The groups a profile reports, each by the symbols it holds (the first pattern a function matches).
PROFILE_GROUPS = (
    ("float arithmetic (avr-libc)", re.compile(r"__(add|sub|mul|div)sf3.*|__fp_.*|__float.*|__fix.*|sqrt.*")),
    ("calibration (Horner, direction, region test)", re.compile(r"mf_calib_.*|fan_side|eeprom_.*|mf_nv_.*")),
    ("sample conversion", re.compile(r"mf_sample_.*|fill_counts|count_of|counts|clamp16|mf_app_process|"
                                     r"mf_app_field_sample|mf_ref_.*")),
    ("frame, CRC and queueing", re.compile(r"mf_frame_.*|mf_crc16_.*|avr_serial_write|mf_app_emit.*|mf_app_flush|"
                                           r"send_frame|send_cycle_piece")),
    ("UART interrupts", re.compile(r"__vector_(18|19|20)")),
    ("I2C driver and its interrupt",
     re.compile(r"twi_.*|avr_i2c_.*|mlx_.*|measurement_reply|status_rc|read_first|read_rest|mf_app_read_measurement|"
                r"mf_app_queue|mf_app_take_chained|mf_app_settle|__vector_24")),
    ("the readout loop (its steps, inlined into main)",
     re.compile(r"main|mf_app_poll|acquire|mf_array_.*|poll_taxel|read_taxel|channels|mf_app_commands|"
                r"avr_serial_read")),
    ("idle until the next conversion, clock reads",
     re.compile(r"avr_micros|avr_delay_us|__vector_13|mf_app_wait_until|mf_app_now")),
)
#: The group of :data:`PROFILE_GROUPS` that is the cycle's spare time (with the few clock reads of the work).
IDLE = PROFILE_GROUPS[-1][0]


def functions(elf: Path) -> list[tuple[int, int, str]]:
    """(start, size, name) of each function of ``elf`` (avr-nm), by address."""
    text = subprocess.run(["avr-nm", "-n", "-S", "--defined-only", str(elf)], capture_output=True, text=True,
                          check=True).stdout
    out = []
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "tTwW":  # a link-time optimised clone by its function's name
            out.append((int(parts[0], 16), int(parts[1], 16), parts[3].split(".")[0]))
    return out


#: The share :func:`grouped` gives the bus's busy time: it overlaps the CPU's (the CPU waits on the bus, or does
#: other work while the transfer runs from its interrupt), so it is not one of the shares that add up to 1.
BUS_BUSY = "I2C bus busy (overlaps the rest)"


def grouped(counts: dict[int, int], bus_samples: int, symbols: list[tuple[int, int, str]]) -> dict[str, float]:
    """A profile's shares of the CPU's time: each of :data:`PROFILE_GROUPS`, and "other" (together 1); and
    :data:`BUS_BUSY`, the share of the time a TWI step was in flight."""
    total = sum(counts.values())
    out = {BUS_BUSY: bus_samples / total}
    out.update({name: 0.0 for name, _ in PROFILE_GROUPS})
    out["other"] = 0.0
    for address, n in counts.items():
        name = next((nm for start, size, nm in symbols if start <= address < start + size), "")
        group = next((g for g, pattern in PROFILE_GROUPS if pattern.fullmatch(name)), "other")
        out[group] += n / total
    return out


@dataclass
class Steady:
    """A span of steady streaming (:func:`steady`): what ``feed`` made of its output, its simulated seconds, the
    first chip's conversions over it and its conversion rate, and the profile (:attr:`Bus.profile`) when asked."""

    out: Any
    seconds: float
    conversions: int
    chip_Hz: float
    profile: tuple[dict[int, int], int] | None

    def budget_us(self, frames: int, symbols: list[tuple[int, int, str]]) -> dict[str, float]:
        """The profile's :func:`grouped` shares as microseconds a frame, over ``frames`` frames."""
        per_frame_us = self.seconds * 1e6 / frames
        return {k: v * per_frame_us for k, v in grouped(*self.profile, symbols).items()} if self.profile else {}

    def busy_us(self, frames: int, symbols: list[tuple[int, int, str]]) -> float:
        """The processor's busy time a frame (us): the frame's time less its :data:`IDLE` share of the profile."""
        return self.seconds * 1e6 / frames - self.budget_us(frames, symbols)[IDLE]


def steady(bus: Bus, seconds: float, settle_us: float, feed: Callable[[bytes], Any] = bytes,
           setup: Callable[[Bus], None] | None = None, profile: bool = False) -> Steady:
    """``settle_us`` of streaming (and, with ``setup``, that called and as long again), then ``seconds`` measured:
    ``feed`` sees every output in turn (a decoder's, so that no frame is cut at the span's edge); the conversions
    are the first chip's (``bus.target(0)``), the sensing chip's of a single taxel."""
    feed(bus.run_us(settle_us))
    if setup is not None:
        setup(bus)
        feed(bus.run_us(settle_us))
    if profile:
        bus.profile_start()
    t0, c0 = bus.time_us, bus.target(0).conversions
    out = feed(bus.run_us(seconds * 1e6))
    return Steady(out, (bus.time_us - t0) * 1e-6, bus.target(0).conversions - c0, 1e6 / bus.conversion_us,
                  bus.profile if profile else None)


def region_fields(calibration: dict, pull: float = 0.97) -> list[tuple[float, float, float]]:
    """Fields across a calibration.json's valid region: each vertex of its convex hull in (Bz, Br) moved ``pull``
    of the way from the hull's centroid, the centroid, and the midpoints between it and each vertex; the lateral
    field at 0, 45 and 135 degrees in turn (uT)."""
    hull = calibration["valid_region"]["hull"]
    cz, cr = sum(p[0] for p in hull) / len(hull), sum(p[1] for p in hull) / len(hull)
    points = [(cz, cr)] + [(cz + f * (z - cz), cr + f * (r - cr)) for z, r in hull for f in (pull, 0.5)]
    out = []
    for k, (bz, br) in enumerate(points):
        angle = math.radians((0.0, 45.0, 135.0)[k % 3])
        out.append((br * math.cos(angle), br * math.sin(angle), bz))
    return out
