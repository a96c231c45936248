"""A simulated array: an array image's cycle frames (every chip's reading of a cycle in one, docs/bundle.md section 3)
from a press pattern, for trying an array's readout without hardware.

The fields are not computed from the magnets here (the package carries no field solver): :class:`ArrayPressPattern`
moves one magnet at a time and gives every chip's reading through array.json's own tables, the forward model its
compensation inverts: each chip reads its own magnet (``own_Bz_uT`` and ``own_lateral_uT`` over the magnet's travel
and lateral offset, with its polarity), the others at rest (``offset_uT``), and what every moved magnet changes at
it (``array_json.Compensator``: the exact axial tables and the spread moment). So the host's compensation leaves
almost nothing of a pressed taxel on its neighbours here; magfab's tests feed the readout fields from the exact model
instead. Anything with ``fields(t_s) -> [(Bx, By, Bz) uT per taxel]`` can stand in for the pattern.

The cycle rate is the chip's conversion rate or what the serial link carries of cycle frames of N chips, whichever is
lower.
"""

from __future__ import annotations

import math
from typing import List, Optional, Protocol, Sequence, Tuple

from . import _build, eeprom
from .frames import (
    STATUS_CHIP_ERROR,
    STATUS_FULL_SCALE,
    STATUS_RECOVERED,
    cycle_frame_length,
    encode_cycle_frame,
    encode_field_line,
    encode_info_line,
    temperature_C,
)
from .simulate import GOLDEN_ANGLE, SIMULATED_FAULT, RestTip, SimulatedDevice, _temperature_raw
from .taxels import ArrayCalibration

__all__ = ["ArrayPressPattern", "ArrayRestTip", "SimulatedArray", "cycle_rate_Hz"]

Vector = Tuple[float, float, float]
#: Microtesla per count of X, Y, Z (the build's chip settings).
_LSB = (_build.LSB_XY_UT, _build.LSB_XY_UT, _build.LSB_Z_UT)


def cycle_rate_Hz(taxels: int, baud: int = _build.BAUD) -> float:
    """Cycles a second: one conversion per cycle (every chip converts at once), unless the link (10 bits a byte)
    carries fewer cycle frames of ``taxels`` chips."""
    return min(_build.SAMPLE_RATE_HZ, baud / 10.0 / cycle_frame_length(taxels))


def _interp(x: float, xs: Sequence[float], ys: Sequence[float]) -> Tuple[int, float]:
    """(index, fraction) of ``x`` in increasing ``xs``, held at the ends (``ys`` unused: the table's row)."""
    if x <= xs[0]:
        return 1, 0.0
    if x >= xs[-1]:
        return len(xs) - 1, 1.0
    hi = next(i for i in range(1, len(xs)) if xs[i] >= x)
    return hi, (x - xs[hi - 1]) / (xs[hi] - xs[hi - 1])


class ArrayPressPattern:
    """At rest for ``rest_s``, then a raised-cosine press of ``press_s`` on one taxel, taxel after taxel: its magnet
    travels towards its chip and slides sideways (a direction turning from press to press) to a target inside its
    calibrated region (``reach`` of the tables' travel and offset, shrunk until inside), and back."""

    def __init__(self, calibration: ArrayCalibration, rest_s: float = 1.0, press_s: float = 1.5,
                 reach: float = 0.6) -> None:
        self.calibration = calibration
        self.comp = calibration.compensator
        self.rest_s, self.press_s = float(rest_s), float(press_s)
        self.targets = [self._target(k, reach) for k in range(calibration.taxels)]

    def own(self, k: int, motion: Vector) -> Vector:
        """Chip k's field from its own magnet moved by ``motion`` (mm, board frame; z negative towards the chip)."""
        comp = self.comp
        travel, offset = -motion[2], math.hypot(motion[0], motion[1])
        i, f = _interp(travel, comp.travel, comp.travel)
        j, g = _interp(offset, comp.lateral, comp.lateral)
        t = comp.table
        pair = [(1 - f) * ((1 - g) * t[i - 1][j - 1][a] + g * t[i - 1][j][a])
                + f * ((1 - g) * t[i][j - 1][a] + g * t[i][j][a]) for a in (0, 1)]
        s = comp.polarity[k]
        c, d = (motion[0] / offset, motion[1] / offset) if offset > 0 else (1.0, 0.0)
        return (s * pair[0] * c, s * pair[0] * d, s * pair[1])

    def readings(self, motions: dict) -> List[Vector]:
        """Every chip's reading with the magnets of ``motions`` ({taxel: (dx, dy, dz) mm}) moved, the rest at rest."""
        comp, cal = self.comp, self.calibration
        out = []
        for k in range(cal.taxels):
            b = list(cal.rest_readings[k])
            if k in motions:
                own, rest = self.own(k, motions[k]), self.own(k, (0.0, 0.0, 0.0))
                b = [x + o - r for x, o, r in zip(b, own, rest)]
            for j, t in motions.items():
                if j != k:
                    b = [x + e for x, e in zip(b, comp._from(j, k, t))]
            out.append((b[0], b[1], b[2]))
        return out

    def _target(self, k: int, reach: float) -> Tuple[float, float]:
        """(travel, offset) mm of taxel k's press: inside its calibrated region."""
        comp, cal = self.comp, self.calibration.calibrations[k]
        travel, offset = reach * comp.travel[-1], 0.5 * reach * comp.lateral[-1]
        for _ in range(40):
            if cal.in_region_B(*self.own(k, (offset, 0.0, -travel))):
                break
            travel, offset = 0.85 * travel, 0.85 * offset
        return travel, offset

    def motion(self, t_s: float) -> Tuple[int, Vector]:
        """(taxel pressed, its magnet's motion) at ``t_s``."""
        period = self.rest_s + self.press_s
        cycle = int(t_s // period)
        tau = t_s - cycle * period
        s = math.sin(math.pi * (tau - self.rest_s) / self.press_s) ** 2 if tau > self.rest_s else 0.0
        k = cycle % self.calibration.taxels
        travel, offset = self.targets[k]
        phi = GOLDEN_ANGLE * (cycle + 1)
        return k, (s * offset * math.cos(phi), s * offset * math.sin(phi), -s * travel)

    def fields(self, t_s: float) -> List[Vector]:
        k, motion = self.motion(t_s)
        return self.readings({k: motion} if any(motion) else {})


class ArrayRestTip:
    """Every taxel at rest as array.json has it, and a known weight on one taxel (:meth:`place_weight`), for the
    acceptance test: the weighted taxel's magnet travels towards its chip by what raises its own Bz by the nominal
    rise under that weight (acceptance.json ``weight.table``, times ``softness[k]``: a softer or stiffer skin than the
    recipe's), and each other magnet i by ``coupling[i][k]`` of that travel (crosstalk.json: a continuous skin; zero
    for separate tips). Every chip's reading then follows from array.json's tables as :class:`ArrayPressPattern`'s."""

    def __init__(self, calibration: ArrayCalibration, force_N: Sequence[float], delta_Bz_uT: Sequence[float],
                 coupling: Optional[Sequence[Sequence[float]]] = None,
                 softness: Optional[Sequence[float]] = None) -> None:
        n = calibration.taxels
        self.calibration = calibration
        self.readings = ArrayPressPattern(calibration).readings
        self.tip = RestTip(0.0, force_N, delta_Bz_uT)
        self.coupling = [[float(c) for c in row] for row in coupling] if coupling is not None else [[0.0] * n] * n
        self.softness = [float(x) for x in softness] if softness is not None else [1.0] * n
        self.load: Tuple[int, float] = (0, 0.0)

    @classmethod
    def from_acceptance(cls, calibration: ArrayCalibration, acceptance: dict, crosstalk: Optional[dict] = None,
                        softness: Optional[Sequence[float]] = None) -> ArrayRestTip:
        table = acceptance["weight"]["table"]
        coupling = None if crosstalk is None else crosstalk.get("coupling")
        return cls(calibration, table["force_N"], table["delta_Bz_nominal_uT"], coupling, softness)

    def place_weight(self, grams: float, taxel: int = 0) -> None:
        """A weight of ``grams`` on ``taxel`` (0 g: nothing on any)."""
        if not (math.isfinite(grams) and grams >= 0) or not 0 <= taxel < self.calibration.taxels:
            raise ValueError(f"a weight needs grams >= 0 and a taxel of the array; instead received {grams!r}, "
                             f"{taxel!r}")
        self.load = (int(taxel), float(grams))

    def travel_mm(self, rise_uT: float) -> float:
        """The travel towards the chip that raises the own Bz (polarity +1) by ``rise_uT`` (array.json's table)."""
        comp = self.calibration.compensator
        own, travel = comp.own, comp.travel
        target = own[0] + rise_uT
        if target >= own[-1]:
            return travel[-1]
        hi = next(i for i in range(1, len(own)) if own[i] >= target)
        return travel[hi - 1] + (target - own[hi - 1]) / (own[hi] - own[hi - 1]) * (travel[hi] - travel[hi - 1])

    def fields(self, t_s: float) -> List[Vector]:
        k, grams = self.load
        if grams <= 0:
            return [(r[0], r[1], r[2]) for r in self.calibration.rest_readings]
        travel = self.travel_mm(self.tip.rise_uT(grams) * self.softness[k])
        motions = {i: (0.0, 0.0, -self.coupling[i][k] * travel) for i in range(self.calibration.taxels)
                   if i != k and self.coupling[i][k]}
        motions[k] = (0.0, 0.0, -travel)
        return self.readings(motions)


def _clamp16(x: float) -> int:
    return max(-32768, min(32767, round(x)))


class _ArrayPattern(Protocol):
    """What a simulated array's ``pattern`` is: every taxel's field (Bx, By, Bz) uT at device time ``t_s``."""

    def fields(self, t_s: float) -> List[Vector]: ...


class SimulatedArray(SimulatedDevice):
    """Stands in for a serial port with an array's image behind it, as :class:`~magfab_readout.SimulatedDevice` does
    for a single taxel (whose serial side it shares: ``read``, ``write``, ``close``, pacing, the commands), sending
    a cycle frame of every chip where a single taxel sends one force frame; the info line ends with the number of
    taxels. Faults for testing: ``corrupt_fraction`` of the cycle frames get a bit flipped after the CRC; every
    ``chip_error_every``-th cycle the chip of taxel ``chip_error_taxel`` reports a chip error (then a recovered
    flag). ``chunk`` is in cycles; ``rate_Hz`` cycles a second (default :func:`cycle_rate_Hz`). ``temperature`` and
    ``thermal_per_C`` as the single taxel's: every chip reads that temperature and every magnet's field follows it."""

    port = "the simulated array"
    pattern: _ArrayPattern  # an ArrayPressPattern unless the caller gives another with every taxel's fields

    def __init__(self, calibration: Optional[ArrayCalibration] = None, *, seed: int = 0,
                 rate_Hz: Optional[float] = None, realtime: bool = True, text: Optional[bool] = None,
                 noise_lsb: float = 0.7, corrupt_fraction: float = 0.0, chip_error_taxel: Optional[int] = None,
                 chip_error_every: int = 0, chunk: int = 16, spec_name: str = _build.SPEC_NAME,
                 calibration_hash: Optional[str] = None, pattern=None, temperature=None, thermal_per_C=None,
                 eeprom_file: Optional[str] = None) -> None:
        cal = calibration if calibration is not None else ArrayCalibration.embedded()
        if cal is None:
            raise ValueError("this package is a single taxel's: simulate it with SimulatedDevice")
        self.n = cal.taxels
        super().__init__(cal.calibrations[0], seed=seed, rate_Hz=rate_Hz or cycle_rate_Hz(self.n), realtime=realtime,
                         text=text, noise_lsb=noise_lsb, corrupt_fraction=corrupt_fraction, chunk=chunk,
                         spec_name=spec_name, calibration_hash=calibration_hash,
                         pattern=pattern if pattern is not None else ArrayPressPattern(cal), temperature=temperature,
                         thermal_per_C=thermal_per_C, eeprom_file=eeprom_file)
        self.array, self.spec_name = cal, spec_name
        self.chip_error_taxel, self.chip_error_every = chip_error_taxel, int(chip_error_every)
        self.hash16 = calibration_hash or cal.calibrations[0].short_hash
        self.info_line = encode_info_line(spec_name, self.hash16, _build.GAIN_SEL, _build.RESOLUTION, _build.OSR,
                                          _build.DIG_FILT, self.n)
        self._recovered_taxel = [False] * self.n
        self._reload()

    def _reload(self) -> bool:
        """As the single taxel's, the info line keeping the number of taxels (an array record's hash when valid)."""
        data = bytes(self.eeprom)
        valid = super()._reload()
        if not hasattr(self, "hash16"):  # the single taxel's __init__ loading an eeprom_file: ours reloads after it
            return valid
        sha16 = eeprom.unpack_header(data)["sha16"] if eeprom.check(data) else self.hash16
        self.info_line = encode_info_line(self.spec_name, sha16, _build.GAIN_SEL, _build.RESOLUTION, _build.OSR,
                                          _build.DIG_FILT, self.n)
        return valid

    def place_weight(self, grams: float, taxel: int = 0) -> None:
        """Put a weight on one taxel of the simulated array (an :class:`ArrayRestTip` pattern only)."""
        place = getattr(self.pattern, "place_weight", None)
        if place is None:
            raise ValueError("this simulated array runs a press pattern; a weight needs pattern=ArrayRestTip(...)")
        place(grams, taxel)

    def _sample_bytes(self, c: int) -> bytes:
        """Cycle ``c``'s bytes: its cycle frame (every chip in taxel order), or a field line per chip in text mode."""
        fields = self.pattern.fields(c / self.rate_Hz)
        seq = c & 0xFF
        readings = [self._reading(c, k, fields[k]) for k in range(self.n)]
        if self.text:
            nan = (math.nan, math.nan, math.nan)
            return b"".join(
                encode_field_line(k, seq, t_us, status, nan, None, word) if status & STATUS_CHIP_ERROR else
                encode_field_line(k, seq, t_us, status, (counts[0] * _LSB[0], counts[1] * _LSB[1], counts[2] * _LSB[2]),
                                  temperature_C(word) if _build.TEMPERATURE_ENABLED else None)
                for k, (t_us, status, counts, word) in enumerate(readings))
        t0 = readings[0][0]
        frame = encode_cycle_frame(seq, t0, [(status, t_us - t0, counts, word)
                                             for t_us, status, counts, word in readings])
        if self.corrupt_fraction and self._faults.random() < self.corrupt_fraction:
            at = self._faults.randrange(2, len(frame))
            frame = frame[:at] + bytes([frame[at] ^ (1 << self._faults.randrange(8))]) + frame[at + 1:]
        return frame

    def _reading(self, c: int, k: int, B: Sequence[float]) -> Tuple[int, int, Tuple[int, int, int], int]:
        """Chip ``k``'s reading in cycle ``c``: (its read time, status, counts, temperature word; on a chip error the
        fault word and zero counts)."""
        t_us = (c * self.period_us + k * (self.period_us // (2 * self.n))) & 0xFFFFFFFF
        status = STATUS_RECOVERED if self._recovered_taxel[k] else 0
        self._recovered_taxel[k] = False
        if (self.chip_error_every and k == self.chip_error_taxel
                and c % self.chip_error_every == self.chip_error_every - 1):
            self._recovered_taxel[k] = True
            return t_us, status | STATUS_CHIP_ERROR, (0, 0, 0), SIMULATED_FAULT
        T = self.temperature(t_us / 1e6)  # every chip and magnet at the same temperature, the field following it
        B = self._at_temperature(B, T)
        counts = (_clamp16(B[0] / _LSB[0] + self._noise.gauss(0.0, self.noise_lsb)),
                  _clamp16(B[1] / _LSB[1] + self._noise.gauss(0.0, self.noise_lsb)),
                  _clamp16(B[2] / _LSB[2] + self._noise.gauss(0.0, self.noise_lsb)))
        if max(abs(x) for x in counts) >= _build.FULL_SCALE_COUNTS:
            status |= STATUS_FULL_SCALE
        return t_us, status, counts, _temperature_raw(T)
