"""An array on the host: every taxel's force from one cycle of its chips' readings (docs/bundle.md section 5).

An array's image sends each cycle one cycle frame of every chip's reading in taxel order (an earlier image a field
frame per chip), all of a cycle with the same sequence number, and no force (:mod:`.frames`). The host

1. groups the samples into cycles (:class:`CycleAssembler`): a cycle ends with its last taxel's frame, or when a
   frame of another sequence number or of a taxel already seen arrives; a taxel whose frame never came (refused
   for its CRC, say) is *missing* from that cycle;
2. removes from each chip's reading what the other taxels' magnets put there: ``array_json.Compensator.apply``
   with the build's array.json (the compensation magfab itself computes with, copied into the package);
3. evaluates each taxel's own calibration (``taxel_NN.json``) on its compensated field, sets the 'outside the
   calibrated region' flag (the firmware computes no force, so the host owns that bit), and subtracts the
   taxel's zero (:meth:`ArrayReader.zero`).

A taxel with a chip error or a missing frame reads NaN and is flagged ('E', or 'M' for missing); the others are
still computed. Its magnet is still there, so its slot in the compensation takes its **last good reading** when that
is at most :data:`HOLD_S` old: a neighbour pressed or slid moves another chip's reading by up to ~190 mN worth at
14 mm (array/crosstalk.json), and in a few cycles it moves little, so holding its reading leaves far less than
dropping its motion would. Older than that (a chip that stopped answering), its slot takes its field at rest: its
motion is then taken as none and only its static offset is removed. Either way its own force stays NaN, and
:attr:`Cycle.held` names the taxels whose slot was filled in.

Standard library only, as the rest of the package; ``array_json`` exists only in an array build's package, so it
is imported when an :class:`ArrayCalibration` is made.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import pkgutil
import time
from dataclasses import dataclass
from typing import Iterator, List, Optional, Sequence, Tuple

from . import array_json, bounded  # array_json: an array build's compensation (docs/bundle.md section 5)
from .calibration import Calibration, CalibrationError
from .device import DeviceError
from .readings import (
    STATUS_OUTSIDE_REGION,
    Sample,
    StatusBits,
    flag_letters,
    reading_fault,
)

__all__ = ["HOLD_S", "ArrayCalibration", "TaxelReading", "Cycle", "CycleAssembler", "ArrayEvaluator", "ArrayReader",
           "WrongFirmware"]

#: Largest lag behind the board's clock a live view (``cycles(keep_up=True)``) lets build up before leaving cycles
#: out, s.
MAX_LAG_S = 0.25
#: A wait this long for the next sample means the host has caught up with the board.
CAUGHT_UP_S = 0.002
#: Longest a missing or failed taxel's last good reading stands in for it in the compensation, s (module doc).
HOLD_S = 0.1
Vector = Tuple[float, float, float]
_NAN3 = (math.nan, math.nan, math.nan)


class WrongFirmware(DeviceError):
    """The board sends a single taxel's force frames to an array's package (or the other way round)."""


def _text(raw: bytes, name: str) -> str:
    """A taxel's calibration file as text: :class:`~magfab_readout.calibration.CalibrationError` unless UTF-8."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CalibrationError("", name, f"is not UTF-8 text ({exc})") from None


def _finite(v: Sequence[float]) -> bool:
    return all(math.isfinite(x) for x in v)


class ArrayCalibration:
    """array.json (format magfab-array/1) with every taxel's calibration: what the host needs to read the array.

    ``array`` is the parsed array.json, ``calibrations`` each taxel's calibration.json (dicts or
    :class:`~magfab_readout.Calibration`), in taxel order. :meth:`embedded` gives this package's (None for a single
    taxel's package)."""

    def __init__(self, array: dict, calibrations: Sequence) -> None:
        self.compensator = array_json.validate(array)
        self.layout = tuple(dict(t) for t in array["taxels"])
        n = len(self.layout)
        cals = tuple(c if isinstance(c, Calibration) else Calibration(c) for c in calibrations)
        if len(cals) != n:
            raise ValueError(f"{len(cals)} calibrations for the {n} taxels of array.json")
        self.calibrations = cals
        #: The hash the board's array record carries when it is read with these calibrations (16 hex digits): the
        #: package's taxel 0 calibration's; a sensor's set of taxel calibrations has its own
        #: (:meth:`with_calibrations`).
        self.board_hash = cals[0].short_hash if cals else ""
        self.dynamic = bool(array["dynamic"])
        self.sha256 = hashlib.sha256(
            json.dumps(array, sort_keys=True, separators=(",", ":")).encode("utf-8")).hexdigest()
        rest = array.get("rest_uT") or [[0.0, 0.0, t["polarity"] * self.compensator.own[0]] for t in self.layout]
        #: What each chip reads with every magnet at rest (own field plus the others' offset), uT.
        self.rest_readings = tuple(tuple(float(r[a]) + self.compensator.offset[k][a] for a in range(3))
                                   for k, r in enumerate(rest))

    @classmethod
    def from_files(cls, read) -> ArrayCalibration:
        """From ``read(name) -> bytes`` (array.json, then the taxel files it names)."""
        try:
            array = bounded.loads_json(read("array.json"), "array.json")
        except bounded.InputFileError:
            raise
        except ValueError as exc:  # json's error, or UnicodeDecodeError: the file's, in the format's one line
            raise array_json.ArrayError("", "(contents)", f"is not valid JSON ({exc})") from None
        array_json.validate(array)  # the taxels and their calibration file names, before any of them is read
        return cls(array, [Calibration.from_json(_text(read(t["calibration"]), t["calibration"]))
                           for t in array["taxels"]])

    @classmethod
    def load(cls, folder: str) -> ArrayCalibration:
        """From a folder holding array.json and the taxel files (a build's ``calibration/``)."""
        def read(name: str) -> bytes:
            return bounded.read_bytes(os.path.join(folder, os.path.basename(name)),
                                      "array.json" if name == "array.json" else "calibration.json")
        return cls.from_files(read)

    @classmethod
    def embedded(cls) -> Optional[ArrayCalibration]:
        """This package's array (array.json and every taxel's calibration), or None: a single taxel's package."""
        try:
            if pkgutil.get_data("magfab_readout", "array.json") is None:
                return None
        except OSError:
            return None

        def read(name: str) -> bytes:
            data = pkgutil.get_data("magfab_readout", name)
            if data is None:
                raise OSError(f"the package's {name} cannot be read: reinstall it")
            return data
        return cls.from_files(read)

    def with_calibrations(self, calibrations: Sequence, board_hash: str) -> ArrayCalibration:
        """The same array read with other taxel calibrations (a sensor's, from its record), in taxel order; the
        board running them carries ``board_hash`` (16 hex digits) in its record."""
        cals = tuple(c if isinstance(c, Calibration) else Calibration(c) for c in calibrations)
        if len(cals) != self.taxels:
            raise ValueError(f"{len(cals)} calibrations for the {self.taxels} taxels of array.json")
        other = copy.copy(self)
        other.calibrations, other.board_hash = cals, board_hash.lower()
        return other

    @property
    def taxels(self) -> int:
        return len(self.layout)

    @property
    def short_hash(self) -> str:
        """First 16 hex digits of array.json's hash (canonical JSON)."""
        return self.sha256[:16]

    @property
    def addresses(self) -> Tuple[int, ...]:
        """Each taxel's I2C address, in taxel order."""
        return tuple(int(t["i2c_address"]) for t in self.layout)

    def own_fields(self, readings: Sequence[Sequence[float]]) -> List[Vector]:
        """One cycle's readings (one (Bx, By, Bz) uT per taxel) -> each taxel's own field (array.json)."""
        return self.compensator.apply(readings)

    def forces(self, readings: Sequence[Sequence[float]], method=None) -> List[Vector]:
        """One complete cycle's readings -> each taxel's (Fx, Fy, Fz) in N, untared."""
        return [cal.evaluate(*own, method=method) for cal, own in zip(self.calibrations, self.own_fields(readings))]


@dataclass(frozen=True)
class TaxelReading(StatusBits):
    """One taxel in one cycle: the field its chip read (``B_uT``), its own field after the compensation
    (``own_uT``), its force (``force_N``, minus the taxel's zero) and the frame's status with the host's
    'outside the calibrated region' bit. A taxel with a chip error, a missing frame or an axis at the chip's full
    scale reads NaN force (the last keeps its field: ``B_uT``, ``counts``)."""

    taxel: int
    seq: int
    time_s: Optional[float]
    status: int
    B_uT: Vector
    own_uT: Vector
    force_N: Vector
    temperature_C: Optional[float]
    fault: Optional[int] = None
    missing: bool = False
    counts: Optional[Tuple[int, int, int]] = None
    temperature_raw: Optional[int] = None

    @property
    def ok(self) -> bool:
        """A force was computed (the frame came, without a chip error, with no axis at full scale)."""
        return not self.missing and not self.chip_error and not self.full_scale

    @property
    def fault_name(self) -> Optional[str]:
        return "missing frame" if self.missing else reading_fault(self.status, self.fault, self.counts)

    @property
    def flags(self) -> str:
        """Five letters, '-' where clear: o outside region, E chip error, S full scale, R recovered, M missing."""
        return flag_letters(self.status) + ("M" if self.missing else "-")


@dataclass(frozen=True)
class Cycle:
    """Every taxel of one cycle, in taxel order; ``held`` the taxels whose compensation slot was filled in (their
    last good reading, or their field at rest: module doc)."""

    seq: int
    time_s: Optional[float]
    taxels: Tuple[TaxelReading, ...]
    held: Tuple[int, ...] = ()

    def __getitem__(self, k: int) -> TaxelReading:
        return self.taxels[k]

    def __len__(self) -> int:
        return len(self.taxels)

    def __iter__(self) -> Iterator[TaxelReading]:
        return iter(self.taxels)

    @property
    def complete(self) -> bool:
        """Every taxel's frame came."""
        return not any(t.missing for t in self.taxels)


class CycleAssembler:
    """Groups an array's samples into cycles: ``feed(sample)`` returns the cycles it completes, each a list of
    one sample or None (missing) per taxel (module doc). ``foreign`` counts samples of a taxel the array has not."""

    def __init__(self, taxels: int) -> None:
        self.n = int(taxels)
        self.foreign = 0
        self._slots: Optional[List[Optional[Sample]]] = None
        self._seq = -1
        self._last = -1

    def feed(self, sample: Sample) -> List[List[Optional[Sample]]]:
        out: List[List[Optional[Sample]]] = []
        k = sample.taxel
        if not 0 <= k < self.n:
            self.foreign += 1
            return out
        if self._slots is not None and (sample.seq != self._seq or k <= self._last):
            out.append(self._emit())
        if self._slots is None:
            self._slots, self._seq = [None] * self.n, sample.seq
        self._slots[k] = sample
        self._last = k
        if k == self.n - 1:
            out.append(self._emit())
        return out

    def flush(self) -> List[List[Optional[Sample]]]:
        """The cycle begun, if any (its later taxels missing)."""
        return [self._emit()] if self._slots is not None else []

    def _emit(self) -> List[Optional[Sample]]:
        slots = self._slots or []
        self._slots, self._last = None, -1
        return slots


def _time(sample: Sample) -> float:
    return sample.time_s if sample.time_s is not None else sample.t_us * 1e-6


class ArrayEvaluator:
    """One cycle's samples -> a :class:`Cycle` of forces (module doc); keeps each taxel's last good reading for the
    compensation and each taxel's zero (``offset_N``). ``method`` as in :meth:`Calibration.evaluate`."""

    def __init__(self, calibration: ArrayCalibration, hold_s: float = HOLD_S, method=None) -> None:
        self.calibration = calibration
        self.hold_s = float(hold_s)
        self.method = method
        n = calibration.taxels
        self.offset_N: List[Vector] = [(0.0, 0.0, 0.0)] * n
        self._last: List[Optional[Tuple[float, Vector]]] = [None] * n

    def remember(self, slots: Sequence[Optional[Sample]]) -> None:
        """Keep the good readings of a cycle that is not evaluated (for the compensation's held slots)."""
        for k, s in enumerate(slots):
            if s is not None and _usable(s):
                self._last[k] = (_time(s), s.B_uT)

    def cycle(self, slots: Sequence[Optional[Sample]]) -> Cycle:
        cal = self.calibration
        good = [_usable(s) for s in slots]
        present = [s for s in slots if s is not None]
        now = min(_time(s) for s in present) if present else None
        readings, held = [], []
        for k, s in enumerate(slots):
            if s is not None and good[k]:  # good[k]: s is a sample
                readings.append(s.B_uT)
                self._last[k] = (_time(s), s.B_uT)
                continue
            last = self._last[k]
            fresh = last is not None and now is not None and now - last[0] <= self.hold_s
            readings.append(last[1] if fresh else cal.rest_readings[k])  # type: ignore[index]
            held.append(k)
        own = cal.own_fields(readings) if any(good) else [_NAN3] * len(slots)
        out = [self._reading(k, s, own[k] if good[k] else _NAN3) for k, s in enumerate(slots)]
        seq = present[0].seq if present else -1
        times = [s.time_s for s in present]
        return Cycle(seq, times[0] if times else None, tuple(out), tuple(held))

    def _reading(self, k: int, s: Optional[Sample], own: Vector) -> TaxelReading:
        if s is None:
            return TaxelReading(k, -1, None, 0, _NAN3, _NAN3, _NAN3, None, missing=True)
        status = s.status & ~STATUS_OUTSIDE_REGION
        force = _NAN3
        if _finite(own):
            cal = self.calibration.calibrations[k]
            if not cal.in_region_B(*cal.corrected(*own, s.temperature_C)):  # the chip's temperature, as one taxel's
                status |= STATUS_OUTSIDE_REGION
            force = tuple(f - o for f, o in zip(cal.evaluate(*own, method=self.method, temperature_C=s.temperature_C),
                                                self.offset_N[k]))
        return TaxelReading(k, s.seq, s.time_s, status, s.B_uT, own, force, s.temperature_C,
                            s.fault, counts=s.counts, temperature_raw=s.temperature_raw)


def _usable(s: Optional[Sample]) -> bool:
    """A taxel's sample whose field is a reading: it came, without a chip error, finite and with no axis at full
    scale (a clipped field would mis-compensate the neighbours too; the taxel's last good field stands in)."""
    return s is not None and not s.chip_error and not s.full_scale and _finite(s.B_uT)


class ArrayReader:
    """An array's cycles from a :class:`~magfab_readout.Device` (module doc): ``cycles()``, ``read(n)`` and
    ``zero(n)`` as a single taxel's ``samples()``, ``read(n)`` and ``zero(n)``."""

    def __init__(self, device, calibration: Optional[ArrayCalibration] = None, hold_s: float = HOLD_S,
                 method=None) -> None:
        calibration = calibration if calibration is not None else ArrayCalibration.embedded()
        if calibration is None:
            raise ValueError("this package is a single taxel's: it has no array.json")
        self.device = device
        self.calibration = calibration
        self.evaluator = ArrayEvaluator(calibration, hold_s, method)
        self.assembler = CycleAssembler(calibration.taxels)
        self.incomplete = 0  # cycles with a missing frame
        self.missing = 0  # frames missing from them
        self.skipped = 0  # cycles left out to keep up (``cycles(keep_up=True)``)
        self.computed = 0  # cycles evaluated, and the time it took (perf_counter seconds)
        self.compute_s = 0.0
        self._clock: Optional[Tuple[float, float]] = None  # (host, device) time of the first cycle
        #: How far this computer's processing ran behind the board's clock at the latest cycle, s.
        self.lag_s = 0.0

    def _track(self, slots: Sequence[Optional[Sample]]) -> float:
        """How far this computer runs behind the board's clock at this cycle, s (:attr:`lag_s`)."""
        times = [_time(s) for s in slots if s is not None]
        if times:
            host, device = time.monotonic(), min(times)
            if self._clock is None:
                self._clock = (host, device)
            self.lag_s = (host - self._clock[0]) - (device - self._clock[1])
        return self.lag_s

    @property
    def cost(self) -> Optional[float]:
        """Seconds of this computer's time per cycle evaluated (None before the first)."""
        return self.compute_s / self.computed if self.computed else None

    @property
    def offset_N(self) -> List[Vector]:
        return self.evaluator.offset_N

    def cycles(self, count: Optional[int] = None, seconds: Optional[float] = None,
               keep_up: bool = False) -> Iterator[Cycle]:
        """Cycles as they complete; stops after ``count`` cycles or ``seconds`` of device time (None: never).
        ``keep_up``: when this computer falls more than :data:`MAX_LAG_S` behind the board's clock, cycles are left
        out (counted in ``skipped``; their readings still serve as the last good ones) until it has caught up."""
        n = 0
        start = None
        samples = self.device.samples()
        while True:
            asked = time.monotonic()
            sample = next(samples)
            if time.monotonic() - asked > CAUGHT_UP_S:
                self._clock = None  # it waited for the board: caught up, the clocks are compared afresh (drift)
            if _finite(sample.device_force_N):
                raise WrongFirmware(
                    f"the board on {self.device.port} sends a single taxel's force frames, but this readout package "
                    f"is for an array of {self.calibration.taxels} taxels: flash the array build's firmware, or "
                    "install the readout package of the board's build")
            for slots in self.assembler.feed(sample):
                if self._track(slots) > MAX_LAG_S and keep_up:
                    self.skipped += 1
                    self.evaluator.remember(slots)
                    continue
                clock = time.perf_counter()
                cycle = self.evaluator.cycle(slots)
                self.compute_s += time.perf_counter() - clock
                self.computed += 1
                lost = sum(t.missing for t in cycle)
                self.incomplete += bool(lost)
                self.missing += lost
                start = cycle.time_s if start is None else start
                if (seconds is not None and cycle.time_s is not None and start is not None
                        and cycle.time_s - start > seconds):
                    return
                n += 1
                yield cycle
                if count is not None and n >= count:
                    return

    def read(self, count: int) -> List[Cycle]:
        """The next ``count`` cycles."""
        return list(self.cycles(count=count))

    def zero(self, count: int) -> List[Vector]:
        """Average each taxel's force over ``count`` of its good readings at rest and subtract it from every later
        reading of that taxel (tare). Returns the offsets, (Fx, Fy, Fz) N per taxel."""
        if count < 1:
            raise ValueError(f"zero needs at least one sample; instead received {count!r}")
        n = self.calibration.taxels
        self.evaluator.offset_N = [(0.0, 0.0, 0.0)] * n
        total = [[0.0, 0.0, 0.0] for _ in range(n)]
        used = [0] * n
        for cycles, cycle in enumerate(self.cycles(), start=1):
            for t in cycle:
                if t.ok and used[t.taxel] < count and _finite(t.force_N):
                    total[t.taxel] = [a + f for a, f in zip(total[t.taxel], t.force_N)]
                    used[t.taxel] += 1
            if min(used) >= count:
                break
            if cycles > 10 * count + 100:
                failing = [k for k in range(n) if used[k] < count]
                raise DeviceError("cannot zero: taxel(s) {} gave {} good readings in {} cycles from {} (check the "
                                  "chips' wiring and addresses: magfab-readout info)".format(
                                      ", ".join(map(str, failing)), min(used), cycles, self.device.port))
        self.evaluator.offset_N = [tuple(x / used[k] for x in total[k]) for k in range(n)]  # type: ignore[misc]
        return list(self.evaluator.offset_N)
