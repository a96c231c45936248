"""A bench in software, for the pages' commands: an Arduino Uno on a serial port (a pseudo-terminal), with
the MLX90393 breakout on its I2C bus and a tip the test can press.

* Until something is flashed, the board is its bootloader: :class:`Stk500` answers avrdude's ``arduino``
  programmer (STK500 v1, as Optiboot does), so ``sh firmware/flash.sh uno PORT`` runs the real avrdude
  against it. When avrdude leaves programming mode, the bytes it wrote are what the board runs.
* Then the board is the ATmega328P in simavr running those bytes (``tests/export/simbus``: libsimavr and
  the build's own MLX90393 model), its EEPROM empty as a bootloader leaves it, paced to the wall clock so
  ``magfab-readout`` sees the firmware's real rate, its UART bridged to the pseudo-terminal.
* :meth:`Rig.set_field` is what the magnet does to the chip: the test sets the field a press gives.
* An array build (design.json's ``array.taxels``) puts one chip model per taxel on the bus, at the build's addresses in
  taxel order; :meth:`Rig.set_fields` sets every chip's field at once (a press moves one magnet, and its
  neighbours' chips see it too), ``set_field(..., taxel=k)`` one chip's.

    with Rig(build_dir, lib, work) as rig:    # rig.port: the serial port to hand to the commands
        rig.set_field(0, 0, 18763)            # uT, taxel 0's chip (a single taxel's only one)
        rig.set_fields([(0, 0, 17752)] * 5)   # an array's: one (Bx, By, Bz) per taxel, in taxel order
"""

from __future__ import annotations

import json
import os
import select
import sys
import threading
import time
import tty
from contextlib import suppress
from pathlib import Path
from typing import ClassVar

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "export"))
from simbus import Bus, build_library

from magfab.export.firmware import _eeprom_module

__all__ = ["Rig", "Stk500", "addresses", "build_library"]

_SIGNATURE_M328P = bytes([0x1E, 0x95, 0x0F])
_INSYNC, _OK, _EOP = 0x14, 0x10, 0x20
_CHUNK = 16  # host bytes handed to the AVR's UART per step
EEPROM_BYTES = 1024  # ATmega328P
#: A slice of simulated time while a stage moves (Rig.follow), us: the field is held for a slice.
TRACK_SLICE_US = 2_000


class Stk500:
    """The bootloader's side of STK500 v1 (the commands avrdude's ``arduino`` programmer sends).

    ``feed(bytes) -> bytes`` consumes what avrdude sent and returns the answers; ``done`` is set when it
    leaves programming mode; ``flash`` is the program memory written so far."""

    # command -> bytes that follow it before Sync_CRC_EOP (None: its own length rule)
    _ARGS: ClassVar[dict[int, int | None]] = {0x30: 0, 0x41: 1, 0x40: 2, 0x42: 20, 0x45: None, 0x50: 0, 0x51: 0,
                                              0x55: 2, 0x56: 4, 0x64: None, 0x74: 3, 0x75: 0}

    def __init__(self) -> None:
        self.buf = bytearray()
        self.flash = bytearray(b"\xff" * 32768)
        self.written = 0
        self.address = 0
        self.done = False

    def _need(self) -> int | None:
        """Bytes the command at the front needs in all (with its EOP), or None until that is known."""
        cmd = self.buf[0]
        if cmd == 0x45:
            return None if len(self.buf) < 2 else 1 + self.buf[1] + 1
        if cmd == 0x64:
            return None if len(self.buf) < 3 else 4 + (self.buf[1] << 8 | self.buf[2]) + 1
        return 1 + self._ARGS.get(cmd, 0) + 1

    def feed(self, data: bytes) -> bytes:
        self.buf += data
        out = bytearray()
        while self.buf:
            need = self._need()
            if need is None or len(self.buf) < need:
                break
            frame, self.buf = bytes(self.buf[:need]), self.buf[need:]
            out += self._answer(frame) if frame[-1] == _EOP else bytes([0x15])  # NOSYNC
        return bytes(out)

    def _answer(self, frame: bytes) -> bytes:
        cmd = frame[0]
        if cmd == 0x41:  # GET_PARAMETER: hardware 2, software 8.0 (Optiboot's)
            return bytes([_INSYNC, {0x80: 2, 0x81: 8, 0x82: 0}.get(frame[1], 0x03), _OK])
        if cmd == 0x75:
            return bytes([_INSYNC, *_SIGNATURE_M328P, _OK])
        if cmd == 0x56:  # universal SPI command (fuses, lock): answer 0
            return bytes([_INSYNC, 0, _OK])
        if cmd == 0x55:  # word address
            self.address = (frame[1] | frame[2] << 8) * 2
        elif cmd == 0x64 and chr(frame[3]) == "F":
            data = frame[4:-1]
            self.flash[self.address:self.address + len(data)] = data
            self.written = max(self.written, self.address + len(data))
        elif cmd == 0x74:
            size = frame[1] << 8 | frame[2]
            data = self.flash[self.address:self.address + size] if chr(frame[3]) == "F" else b"\xff" * size
            return bytes([_INSYNC]) + bytes(data) + bytes([_OK])
        elif cmd == 0x51:
            self.done = True
        return bytes([_INSYNC, _OK])


class Stage:
    """What the walk sets on a simulated board: every chip's field (``_fields``, one (Bx, By, Bz, T) per address of
    ``addresses``) and a stage moving on the board's clock (``_track``), under ``_lock``; the board reads them. The
    board's bytes go to the host through the pseudo-terminal's non-blocking ``master`` (:meth:`_send`)."""

    addresses: list[int]
    master: int
    _fields: list[tuple[float, float, float, float]]
    _track: object
    _lock: threading.Lock

    def set_field(self, bx_uT: float, by_uT: float, bz_uT: float, t_C: float = 25.0, *, taxel: int = 0) -> None:
        """The field at the chip (an array's: taxel ``taxel``'s) from now on (the magnets', as a press moves them)."""
        with self._lock:
            self._fields[taxel] = (bx_uT, by_uT, bz_uT, t_C)

    def set_fields(self, fields, t_C: float = 25.0) -> None:
        """Every chip's field at once, from now on: one (Bx, By, Bz) in uT per taxel, in taxel order."""
        fields = [tuple(float(b) for b in f) for f in fields]
        if len(fields) != len(self.addresses) or any(len(f) != 3 for f in fields):
            raise ValueError(f"one (Bx, By, Bz) per chip: {len(self.addresses)} chip(s), got {fields!r}")
        with self._lock:
            self._fields = [(*f, t_C) for f in fields]

    def _send(self, data: bytes) -> None:
        """To the host; dropped when nobody reads the port and its buffer is full, as a USB serial line drops (a host
        whose program runs something else for seconds, a compiler say, while the board streams)."""
        with suppress(BlockingIOError):
            os.write(self.master, data)

    def follow(self, track) -> None:
        """From now on every chip's field is ``track(board_s)`` (one (Bx, By, Bz) per taxel, uT) at the middle of each
        simulated slice of the board (:data:`TRACK_SLICE_US` at most here): a stage moving on the board's own clock,
        so a recording's samples see the stage where it was at their device time however loaded the machine is (a
        stage moving on the wall clock meets a board that falls behind it, then catches up, at varying delays).
        None: the fields keep their last values."""
        with self._lock:
            self._track = track


class Rig(Stage):
    """The board on a pseudo-terminal (see the module's docstring)."""

    def __init__(self, build_dir: Path, lib: Path, work: Path) -> None:
        self.build_dir, self.lib, self.work = Path(build_dir), Path(lib), Path(work)
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo: what the board sends is never read back as the host's
        os.set_blocking(self.master, False)
        self.port = os.ttyname(self._slave)
        self.loader = Stk500()
        self.bus: Bus | None = None
        self._eeprom: bytes | None = None
        self._pending = b""
        self._last_rx = 0.0
        self.resets = 0
        self.flashed: Path | None = None
        self.addresses = addresses(self.build_dir)
        self._fields = [(0.0, 0.0, 0.0, 25.0)] * len(self.addresses)
        self._track = None  # a stage moving on the board's clock (follow)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="rig", daemon=True)

    def __enter__(self) -> Rig:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(10)
        if self._thread.is_alive():  # never free the simulator under a thread still running it
            raise RuntimeError("the simulated board's thread did not stop")
        if self.bus is not None:
            self.bus.close()
        os.close(self.master)
        os.close(self._slave)
        if self._error is not None and exc[0] is None:
            raise RuntimeError("the simulated board failed") from self._error

    @property
    def error(self) -> BaseException | None:
        """What stopped the board's thread (None while it runs); raised again when the rig closes."""
        return self._error

    @property
    def board_s(self) -> float:
        """The board's own clock, s: the simulated time it has run since it was flashed (0 before). Paced to the wall
        clock, it falls behind it when the machine is too loaded to simulate the board in real time."""
        with self._lock:
            return self.bus.time_us / 1e6 if self.bus is not None else 0.0

    def eeprom(self, size: int) -> bytes:
        """The EEPROM's first ``size`` bytes: the running board's, or what it kept when it was reset or unplugged."""
        with self._lock:
            if self.bus is not None:
                return self.bus.eeprom(0, size)
            return self._eeprom[:size] if self._eeprom is not None else b""

    def power_off(self) -> None:
        """Unplugged: the board stops (its simulator freed, nothing runs on the port); the image it was flashed with
        and its EEPROM are kept, as a real board's flash and EEPROM keep them."""
        self._stop.set()
        self._thread.join(10)
        if self._thread.is_alive():
            raise RuntimeError("the simulated board's thread did not stop")
        with self._lock:
            if self.bus is not None:
                self._eeprom = self.bus.eeprom(0, EEPROM_BYTES)
                self.bus.close()
                self.bus = None

    def power_on(self) -> None:
        """Plugged in again (a no-op while it runs): a flashed board boots the image it holds, its EEPROM as it was
        left; a board never flashed waits in its bootloader for avrdude."""
        if self._thread.is_alive():
            return
        if self._error is not None:
            raise RuntimeError("the simulated board failed") from self._error
        self._pending = b""
        if self.loader.done:  # the image avrdude wrote last (a reset starts a new loader, which avrdude then fills)
            self._boot()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="rig", daemon=True)
        self._thread.start()

    def _receive(self) -> bytes:
        try:
            return os.read(self.master, 4096) if select.select([self.master], [], [], 0.002)[0] else b""
        except (BlockingIOError, OSError):
            return b""

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                data = self._receive()
                quiet = time.monotonic() - self._last_rx > 0.05  # not the rest of a host command cut by a read
                if data:
                    self._last_rx = time.monotonic()
                if self.bus is not None and data.startswith(b"0 ") and not self._pending and quiet:
                    self._reset()  # avrdude opening the port: a real Uno resets into its bootloader on DTR
                if self.bus is None:
                    self._send(self.loader.feed(data))
                    if self.loader.done:
                        self._boot()
                else:
                    self._step(data)
        except BaseException as exc:
            self._error = exc

    def _reset(self) -> None:
        """Into the bootloader, the EEPROM kept (the bootloader does not touch it)."""
        with self._lock:
            self._eeprom = self.bus.eeprom(0, EEPROM_BYTES)
            self.bus.close()
            self.bus = None
        self.loader = Stk500()
        self.resets += 1

    def _boot(self) -> None:
        """The bootloader hands over: the board runs what avrdude wrote, with the EEPROM as it was (empty,
        0xFF, on a new board)."""
        self.flashed = self.work / "flashed.hex"
        self.flashed.write_bytes(_eeprom_module().intel_hex(bytes(self.loader.flash[:self.loader.written])))
        with self._lock:
            self.bus = Bus(self.lib, self.flashed, addr7=self.addresses[0])
            for address in self.addresses[1:]:
                self.bus.add_chip(address)
            if self._eeprom is not None:
                self.bus.eeprom_set(0, self._eeprom)
        self._t0 = time.monotonic()
        self._byte_us = 10e6 / _baud(self.build_dir)  # 10 bits a byte

    def _step(self, data: bytes) -> None:
        """Host bytes in at the line's rate (the AVR's receive buffer is small), simulated time up to the wall
        clock (at most 20 ms a step; while a stage moves, in slices of TRACK_SLICE_US, each with the field of its
        middle), board bytes out."""
        self._pending += data
        chunk, self._pending = self._pending[:_CHUNK], self._pending[_CHUNK:]
        out: list[bytes] = []  # what each slice made
        with self._lock:
            self.bus.send(chunk)
            dt = min((time.monotonic() - self._t0) * 1e6 - self.bus.time_us, 20_000)
            dt = max(dt, len(chunk) * self._byte_us)
            while dt > 0:  # a moving stage's field is set again every slice: the whole step, in slices
                run = dt if self._track is None else min(dt, TRACK_SLICE_US)
                if self._track is not None:
                    at = (self.bus.time_us + run / 2) / 1e6  # the slice's middle: off by half a slice's motion at most
                    self._fields = [(*(float(b) for b in f), 25.0) for f in self._track(at)]
                for k, f in enumerate(self._fields):
                    self.bus.target(k).set_field(*f)
                made = self.bus.run_us(run)
                if made:
                    out.append(made)
                dt -= run
        for made in out:
            self._send(made)


def _spec(build_dir: Path) -> dict:
    return json.loads((build_dir / "spec.json").read_text())


def addresses(build_dir: Path) -> list[int]:
    """The chips' 7-bit I2C addresses in taxel order: an array build's design.json ``array.taxels``, else the spec's
    one."""
    design = build_dir / "design.json"
    taxels = (json.loads(design.read_text()).get("array") or {}).get("taxels") if design.is_file() else None
    return [int(t["i2c_address"]) for t in taxels] if taxels else [int(_spec(build_dir)["sensor"]["i2c_address"])]


def _baud(build_dir: Path) -> int:
    return int(_spec(build_dir)["firmware"]["baud"])
