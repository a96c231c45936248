"""The device: a serial port (or the simulator) with the firmware behind it, read as a stream of samples.

Every failure a user can meet is a :class:`DeviceError` subclass with a message that says what to do:
:class:`PortNotFound`, :class:`NoData` (nothing decodable within the timeout), :class:`CrcErrorRate` (too many
frames fail their CRC) and :class:`CalibrationMismatch` (the firmware was built with another calibration).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections import deque
from typing import Deque, Iterator, List, Optional, Tuple, Union

from . import _build, eeprom, identity
from .calibration import Calibration
from .calibration_json import calibration_sha256
from .calibration_json import validate as validate_calibration
from .frames import Decoder, DeviceInfo, EepromReply, Sample
from .simulate import SimulatedDevice

__all__ = ["Device", "DeviceError", "PortNotFound", "NoData", "CrcErrorRate", "CalibrationMismatch", "UploadFailed",
           "SerialTransport", "PORT_VARIABLE", "default_port", "find_port", "cross_check", "calibration_record",
           "TAXEL_ADDRESSES", "TAXELS"]

RESEND_S = 0.5  # a command sent while the board boots (it resets when the port opens) is lost: send again
CRC_WINDOW = 500  # frame candidates over which the CRC failure rate is judged
CRC_MIN_ATTEMPTS = 100  # below this a handful of errors (the boot, a glitch) would judge too soon
#: The environment variable naming the serial port to use when none is given (``Device(port=None)``, ``--port``).
PORT_VARIABLE = "MAGFAB_READOUT_PORT"
#: An array build's chips, 7-bit I2C addresses in taxel order (build.json's image settings); () for a single taxel.
#: Its firmware sends one cycle frame of every chip's reading a cycle (a ``Sample`` each, ``Sample.taxel``, ``force_N``
#: NaN: the host computes the forces) and its info line ends with the number of chips.
TAXEL_ADDRESSES = tuple(int(a) for a in _build.IMAGE_SETTINGS.get("taxel_addresses", ()))
#: Taxels the firmware reads: 1 for a single taxel.
TAXELS = len(TAXEL_ADDRESSES) or 1


class DeviceError(RuntimeError):
    """A readout failure the command line reports as one line (exit status 1)."""


class PortNotFound(DeviceError):
    """The serial port does not exist, or no port was given and none (or several) could be found."""


class NoData(DeviceError):
    """Nothing decodable arrived within the timeout."""


class CrcErrorRate(DeviceError):
    """Too many binary frames fail their CRC (or text lines their checksum): wrong baud rate, a bad cable or
    another writer on the port."""


class CalibrationMismatch(DeviceError):
    """The firmware reports another calibration than the one this package embeds."""


class UploadFailed(DeviceError):
    """A calibration upload was refused or did not read back as written."""


WRITE_CHUNK = 16  # bytes per EEPROM write command (the firmware's limit)
READ_CHUNK = 32  # bytes per EEPROM read command


def calibration_record(calibration: dict) -> bytes:
    """The EEPROM record (docs/bundle.md section 4) of a calibration.json dict with this build's settings: the bytes
    ``upload`` writes, the same as a build's .eep holds for its own calibration. An array build's (version 3)
    carries the chips' addresses and the settings, and of the calibration only its hash (the info line's)."""
    if TAXEL_ADDRESSES:
        validate_calibration(calibration)
        return eeprom.pack_array(TAXEL_ADDRESSES, calibration_sha256(calibration)[:16], _build.IMAGE_SETTINGS)
    return eeprom.pack(eeprom.layout(validate_calibration(calibration)), calibration_sha256(calibration)[:16],
                       _build.IMAGE_SETTINGS)


def _ports() -> list:
    from serial.tools import list_ports  # lazy: pyserial is optional (--simulate runs without it)

    return sorted(list_ports.comports(), key=lambda p: p.device)


def _describe(ports: list) -> str:
    """Each port's name, with its description and USB serial number where it has them (an RP2040 board's is its
    flash chip's unique ID: two boards tell apart)."""
    if not ports:
        return "none"
    out = []
    for p in ports:
        about = [x for x in (p.description, getattr(p, "serial_number", None)) if x and x != "n/a"]
        out.append(f"{p.device} ({', serial '.join(about)})" if about else p.device)
    return ", ".join(out)


def _import_serial():
    try:
        import serial  # lazy: pyserial is optional (--simulate runs without it)
    except ImportError:
        raise DeviceError("pyserial is not installed: pip install pyserial (or try the simulated device with "
                          "--simulate)") from None
    return serial


#: The USB IDs (VID, PID) of the readout boards: an Arduino Uno's (ArduinoCore-avr boards.txt, uno.vid/pid .0 to .3)
#: and the RP2040 image's (usb_cdc.c: Raspberry Pi's ID for a Pico SDK CDC serial port, 2E8A:000A).
BOARD_IDS = ((0x2341, 0x0043), (0x2341, 0x0001), (0x2A03, 0x0043), (0x2341, 0x0243), (0x2E8A, 0x000A))


def find_port() -> str:
    """The port of the one readout board present (a USB serial port with one of :data:`BOARD_IDS`; a Nano's USB
    bridge has its chip maker's ID, so without one of those: the one USB serial port present), or
    :class:`PortNotFound` naming what there is."""
    _import_serial()
    ports = _ports()
    usb = [p for p in ports if getattr(p, "vid", None) is not None]
    boards = [p for p in usb if (p.vid, getattr(p, "pid", None)) in BOARD_IDS]
    if len(boards) == 1:
        return boards[0].device
    if len(usb) == 1:
        return usb[0].device
    if not usb:
        raise PortNotFound(f"no USB serial port found (other ports: {_describe(ports)}): plug the board in, or pass "
                           f"--port or set {PORT_VARIABLE} (or try --simulate)")
    raise PortNotFound(f"several USB serial ports found: {_describe(usb)}; choose one with --port or {PORT_VARIABLE}")


def _named_port() -> str:
    """``$MAGFAB_READOUT_PORT``, stripped ("" when unset)."""
    return os.environ.get(PORT_VARIABLE, "").strip()


def default_port() -> str:
    """The port to open when none is given: ``$MAGFAB_READOUT_PORT`` when it is set (and not empty), else
    :func:`find_port`'s one USB serial port present."""
    return _named_port() or find_port()


class SerialTransport:
    """A pyserial port with the small interface the device needs: ``read``, ``write``, ``close``."""

    def __init__(self, port: str, baud: int) -> None:
        serial = _import_serial()
        self.port = port
        try:
            self._serial = serial.Serial(port, baud, timeout=0.05)
        except (serial.SerialException, OSError, ValueError) as exc:
            text = str(exc)
            missing = ("No such file" in text or "FileNotFoundError" in text or "cannot find" in text.lower()
                       or (os.name == "posix" and not os.path.exists(port)))
            if missing:
                try:
                    available = _describe(_ports())
                except Exception:  # listing ports is only a courtesy in this message
                    available = "unknown"
                raise PortNotFound(f"serial port {port!r} not found (available: {available}); pass --port, or try "
                                   "--simulate") from None
            if "Permission denied" in text or "PermissionError" in text:
                raise DeviceError(f"permission denied opening {port!r}: on Linux add your user to the 'dialout' group "
                                  "and log in again") from None
            raise DeviceError(f"cannot open serial port {port!r} at {baud} baud: {text}") from None

    def read(self, size: int = 4096, timeout_s: float = 0.05) -> bytes:
        """What has arrived, up to ``size`` bytes; waits up to ``timeout_s`` for the first byte."""
        self._serial.timeout = timeout_s
        waiting = self._serial.in_waiting
        return bytes(self._serial.read(max(1, min(size, waiting))))

    def write(self, data: bytes) -> int:
        """Send command bytes."""
        n = self._serial.write(data)
        self._serial.flush()
        return n

    def close(self) -> None:
        """Close the port."""
        self._serial.close()


def cross_check(sample: Sample, calibration: Calibration) -> float:
    """Largest |F_host - F_device| in newton, the host recomputing the force from the sample's field with
    ``calibration``'s global polynomial at the sample's temperature (what the firmware evaluates); NaN for a
    chip-error sample and one at the chip's full scale (no force). Binary frames carry exact counts, text lines a
    rounded field."""
    if sample.chip_error or sample.full_scale:
        return math.nan
    host = calibration.evaluate(*sample.B_uT, method="poly", temperature_C=sample.temperature_C)
    assert sample.device_force_N is not None, "Sample.__post_init__ sets it"
    return max(abs(h - d) for h, d in zip(host, sample.device_force_N))


class Device:
    """A sensor board streaming the firmware's frames (or the simulator with ``simulate=True``).

    ``port`` is the serial port's name (``"/dev/ttyACM0"``, ``"COM3"``, a pseudo-terminal); None opens the port
    named by the environment variable ``MAGFAB_READOUT_PORT`` when it is set, else the one USB serial port present.

    ``text`` switches the firmware to text lines (True), binary frames (False) or leaves it as it starts (None).
    ``timeout_s`` is how long to wait for data before :class:`NoData`. Use as a context manager, or call
    :meth:`close`. ``transport`` replaces the port by any object with ``read(size, timeout_s)``, ``write`` and
    ``close`` (a :class:`~magfab_readout.SimulatedDevice` with faults, for example).
    """

    def __init__(self, port: Optional[str] = None, baud: int = _build.BAUD, *, text: Optional[bool] = None,
                 simulate: bool = False, timeout_s: float = 3.0, calibration: Optional[Calibration] = None,
                 transport=None, max_crc_error_rate: float = 0.05) -> None:
        self.calibration = calibration if calibration is not None else Calibration.embedded()
        self.baud = int(baud)
        self.timeout_s = float(timeout_s)
        self.max_crc_error_rate = float(max_crc_error_rate)
        if transport is not None:
            self.port = getattr(transport, "port", "the device")
            self.transport = transport
        elif simulate:
            self.transport = SimulatedDevice(self.calibration)
            self.port = self.transport.port
        else:
            named = "" if port else _named_port()
            self.port = port or named or find_port()
            try:
                self.transport = SerialTransport(self.port, self.baud)
            except PortNotFound as exc:
                if not named:
                    raise
                raise PortNotFound(f"{exc} (the port named by {PORT_VARIABLE}: set it to the board's port, or unset "
                                   "it to use the one USB serial port present)") from None
        self.decoder = Decoder()
        self.offset_N: Tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.last_info: Optional[DeviceInfo] = None
        self.text: Optional[bool] = None
        self._queue: Deque[Union[Sample, DeviceInfo]] = deque()
        self._crc_mark = (0, 0)
        self._last_t_us: Optional[int] = None
        self._elapsed_us = 0
        self._mode_sent = 0.0
        if text is not None:
            self.set_mode(text)

    def __enter__(self) -> Device:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the port."""
        self.transport.close()

    @property
    def stats(self):
        """The decoder's :class:`~magfab_readout.frames.DecoderStats`."""
        return self.decoder.stats

    def set_mode(self, text: bool) -> None:
        """Ask the firmware for text lines (True) or binary frames (False)."""
        self.text = bool(text)
        self.transport.write(b"t" if self.text else b"b")
        self._mode_sent = time.monotonic()

    # --- reading ------------------------------------------------------------------------------------------

    def _fill(self, wait_s: float) -> None:
        data = self.transport.read(4096, max(0.001, min(0.05, wait_s)))
        if data:
            self._queue.extend(self.decoder.feed(data))
            self._check_crc()

    def _check_crc(self) -> None:
        stats = self.decoder.stats
        mark = (stats.frames + stats.lines, stats.crc_errors + stats.bad_lines)
        good, bad = mark[0] - self._crc_mark[0], mark[1] - self._crc_mark[1]
        attempts = good + bad
        if attempts >= CRC_MIN_ATTEMPTS and bad > self.max_crc_error_rate * attempts:
            raise CrcErrorRate(
                f"{bad} of the last {attempts} frames or lines from {self.port} failed their CRC "
                f"({100.0 * bad / attempts:.0f} %, the limit is {100.0 * self.max_crc_error_rate:.0f} %): check that "
                f"the baud rate ({self.baud}) matches the firmware's, the cable and its length, and that nothing else "
                "uses the port")
        if attempts >= CRC_WINDOW:
            self._crc_mark = mark

    def _no_data(self, what: str, received: int) -> NoData:
        stats = self.decoder.stats
        if stats.bytes == 0:
            hint = "nothing arrived: is the board plugged in and the firmware flashed?"
        elif stats.samples == 0 and stats.infos == 0:
            hint = (f"{stats.bytes} bytes arrived but none formed a frame or line: check that the baud rate "
                    f"({self.baud}) matches the firmware's")
        else:
            hint = f"the stream stopped after {received} samples: was the board unplugged or reset?"
        return NoData(f"no {what} from {self.port} within {self.timeout_s:g} s; {hint}")

    def _stamp(self, sample: Sample) -> Sample:
        if self._last_t_us is not None:
            delta = (sample.t_us - self._last_t_us) % 2**32
            self._elapsed_us += delta if delta < 2**31 else 0  # a backwards step is a board reset, not a wrap
        self._last_t_us = sample.t_us
        device_force, offset = sample.device_force_N, self.offset_N
        assert device_force is not None, "Sample.__post_init__ sets it"
        force = (device_force[0] - offset[0], device_force[1] - offset[1], device_force[2] - offset[2])
        return dataclasses.replace(sample, time_s=self._elapsed_us * 1e-6, force_N=force,
                                   device_force_N=sample.device_force_N)

    def samples(self, count: Optional[int] = None, seconds: Optional[float] = None) -> Iterator[Sample]:
        """Samples as they arrive, with ``time_s`` (device time since the first sample of this device) and the
        zero offset applied; stops after ``count`` samples or ``seconds`` of device time (None: never)."""
        n = 0
        start: Optional[float] = None
        last = time.monotonic()
        while count is None or n < count:
            if not self._queue:
                self._fill(self.timeout_s - (time.monotonic() - last))
                if not self._queue:
                    if time.monotonic() - last > self.timeout_s:
                        raise self._no_data("frames", n)
                    continue
            item = self._queue.popleft()
            if not isinstance(item, Sample):
                if isinstance(item, DeviceInfo):
                    self.last_info = item
                continue
            last = time.monotonic()
            if self.text is not None and (item.source == "text") != self.text and last - self._mode_sent > RESEND_S:
                self.set_mode(self.text)
            sample = self._stamp(item)
            assert sample.time_s is not None, "_stamp sets the device time"
            if start is None:
                start = sample.time_s
            if seconds is not None and sample.time_s - start > seconds:
                return
            n += 1
            yield sample

    def read(self, count: int) -> List[Sample]:
        """The next ``count`` samples."""
        return list(self.samples(count=count))

    def drain(self, max_s: float = 0.5) -> int:
        """Drop every sample already queued or waiting in the port (stale ones: read while nobody listened, say
        during a prompt), so the next sample is a fresh one. Returns how many samples were dropped."""
        dropped = sum(1 for item in self._queue if isinstance(item, Sample))
        self._queue.clear()
        start = time.monotonic()
        while time.monotonic() - start < max_s:
            data = self.transport.read(65536, 0.001)
            if not data:
                break
            items = self.decoder.feed(data)
            self._check_crc()
            for item in items:
                if isinstance(item, Sample):
                    self._stamp(item)  # keeps the device clock running through the dropped samples
                    dropped += 1
                elif isinstance(item, DeviceInfo):
                    self.last_info = item
        return dropped

    def zero(self, count: int) -> Tuple[float, float, float]:
        """Average ``count`` samples at rest (chip-error and full-scale samples are skipped) and subtract that force
        from every later sample (tare). Returns the offset (Fx, Fy, Fz) in newton."""
        if count < 1:
            raise ValueError(f"zero needs at least one sample; instead received {count!r}")
        self.offset_N = (0.0, 0.0, 0.0)
        total = [0.0, 0.0, 0.0]
        used = skipped = 0
        for sample in self.samples():
            device_force = sample.device_force_N
            assert device_force is not None, "Sample.__post_init__ sets it"
            if sample.chip_error or any(math.isnan(f) for f in device_force):
                skipped += 1
                if skipped > 10 * count + 100:
                    raise DeviceError(f"cannot zero: {skipped} of the last samples from {self.port} were chip errors "
                                      "or at the chip's full scale (check the sensor board's wiring and supply, and "
                                      "that nothing presses the tip)")
                continue
            total = [t + f for t, f in zip(total, device_force)]
            used += 1
            if used == count:
                break
        self.offset_N = (total[0] / used, total[1] / used, total[2] / used)
        return self.offset_N

    def info(self) -> DeviceInfo:
        """Ask the firmware which spec and calibration it runs ('i'); samples arriving meanwhile are dropped."""
        start = time.monotonic()
        sent = -math.inf
        while True:
            now = time.monotonic()
            if now - start > self.timeout_s:
                raise self._no_data("info line (answer to 'i')", self.decoder.stats.samples)
            if now - sent > RESEND_S:
                self.transport.write(b"i")
                sent = now
            if not self._queue:
                self._fill(RESEND_S)
                continue
            item = self._queue.popleft()
            if isinstance(item, DeviceInfo):
                self.last_info = item
                return item

    # --- the EEPROM: calibration upload ------------------------------------------------------------------------

    def _command(self, command: bytes, kind: str, address: int) -> EepromReply:
        """Send an EEPROM command (again every RESEND_S: both kinds may be repeated) and wait for its answer;
        samples arriving meanwhile are dropped."""
        start = time.monotonic()
        sent = -math.inf
        while True:
            now = time.monotonic()
            if now - start > self.timeout_s:
                raise self._no_data(f"answer to the EEPROM command '{command[:1].decode()}'",
                                    self.decoder.stats.samples)
            if now - sent > RESEND_S:
                self.transport.write(command)
                sent = now
            if not self._queue:
                self._fill(0.05)
                continue
            item = self._queue.popleft()
            if isinstance(item, EepromReply) and item.kind == kind and item.address == address:
                return item
            if isinstance(item, DeviceInfo):
                self.last_info = item

    def eeprom_read(self, address: int, length: int) -> bytes:
        """``length`` bytes of the board's EEPROM from ``address``."""
        out = b""
        while len(out) < length:
            n = min(READ_CHUNK, length - len(out))
            a = address + len(out)
            reply = self._command(b"r" + bytes((a & 0xFF, a >> 8, n)), "R", a)
            if len(reply.data) != n:
                raise UploadFailed(f"the board returned {len(reply.data)} bytes of EEPROM at {a} instead of {n}")
            out += reply.data
        return out

    def eeprom_write(self, address: int, data: bytes) -> EepromReply:
        """Write ``data`` to the board's EEPROM from ``address``; the last chunk's answer (its ``record`` is 0
        when the calibration record is valid afterwards)."""
        reply = None
        for k in range(0, len(data), WRITE_CHUNK):
            a, chunk = address + k, bytes(data[k:k + WRITE_CHUNK])
            body = b"w" + bytes((a & 0xFF, a >> 8, len(chunk))) + chunk
            crc = eeprom.crc16(body)
            reply = self._command(body + bytes((crc & 0xFF, crc >> 8)), "W", a)
            if reply.status != 0 or reply.length != len(chunk):
                raise UploadFailed("the board refused the EEPROM write at {} ({})".format(
                    a, {1: "bad CRC", 2: "outside the EEPROM"}.get(reply.status, reply.status)))
        if reply is None:
            raise ValueError("eeprom_write needs at least one byte")
        return reply

    def upload(self, calibration: dict) -> DeviceInfo:
        """Write ``calibration`` (a calibration.json dict, checked first) into the board's EEPROM, read it back,
        and check that the board now runs it (its info line carries the new hash). No compiler, no reflash.
        Returns the new info line; :class:`UploadFailed` when anything differs."""
        record = calibration_record(calibration)
        last = self.eeprom_write(0, record)
        back = self.eeprom_read(0, len(record))
        if back != record:
            first = next(k for k, (a, b) in enumerate(zip(back, record)) if a != b)
            raise UploadFailed(f"the EEPROM read back differs from what was written at byte {first}")
        if last.record != 0:
            raise UploadFailed("the board does not accept the record written (made for other chip settings, or a "
                               f"firmware older than record version {record[2]}?)")
        info = self.info()
        if info.calibration_hash.lower() != calibration_sha256(calibration)[:16]:
            raise UploadFailed(f"the board reports calibration {info.calibration_hash} after the upload, "
                               f"not {calibration_sha256(calibration)[:16]}")
        self.calibration = Calibration(dict(calibration))
        return info

    def read_identity(self) -> Optional[identity.Identity]:
        """The sensor identity the board's EEPROM holds (docs/bundle.md section 4), None when it holds none."""
        return identity.unpack(self.eeprom_read(identity.ADDRESS, identity.SIZE))

    def write_identity(self, ident: identity.Identity) -> None:
        """Write the sensor identity block into the board's EEPROM (after the calibration record, which it leaves
        alone) and read it back; :class:`UploadFailed` when it reads back otherwise."""
        block = identity.pack(ident)
        self.eeprom_write(identity.ADDRESS, block)
        if self.eeprom_read(identity.ADDRESS, identity.SIZE) != block:
            raise UploadFailed(f"the sensor identity read back from EEPROM address {identity.ADDRESS} differs from "
                               "what was written")

    def check_info(self, info: DeviceInfo, expected: Optional[str] = None) -> List[str]:
        """Raise :class:`CalibrationMismatch` unless the device runs this package's calibration (or carries the hash
        ``expected``, 16 hex digits: an array's record); return warnings for a different spec name or chip
        settings."""
        mine = expected or self.calibration.short_hash
        if info.calibration_hash.lower() != mine:
            raise CalibrationMismatch(
                f"calibration mismatch: the device on {self.port} runs calibration {info.calibration_hash} "
                f"(spec {info.spec_name!r}) but this readout package embeds {mine} (spec {_build.SPEC_NAME!r}); flash "
                "the firmware and install the readout package from the same magfab build")
        warnings = []
        if info.spec_name != _build.SPEC_NAME:
            warnings.append(f"the device reports spec {info.spec_name!r}, this package was built for "
                            f"{_build.SPEC_NAME!r}")
        if info.taxels != TAXELS:
            warnings.append(f"the device reads {info.taxels} taxel(s), this package was built for {TAXELS}")
        settings = (_build.GAIN_SEL, _build.RESOLUTION, _build.OSR, _build.DIG_FILT)
        if info.settings != settings:
            warnings.append(f"the device reports gain_sel/resolution/osr/dig_filt {info.settings} but this package "
                            f"expects {settings}: the field in microtesla will be wrong")
        return warnings
