"""A simulated device: the firmware's serial output from a synthetic press pattern, for trying the readout
without hardware.

The field is not computed from physics: the pattern moves (Bz, Br) inside the calibration's valid region,
from a rest point (the field where the calibration reads no force, near the axis: so the board reads zero at
rest without a tare, as a real one right after its calibration) towards each corner of the region in turn and
back, while the lateral direction of the field turns. The chip's quantisation and a
little Gaussian noise are added, and the forces are the embedded calibration's global polynomial evaluated
at the quantised field, exactly what the firmware would send for that field. The frames are byte-for-byte the firmware's
format, and the simulator answers the commands 'b', 't' and 'i'.

For the acceptance test (``magfab-readout check``) the device runs a :class:`RestTip` instead: the fingertip at
rest with the field magfab predicted (acceptance.json), and a weight placed on it with :meth:`SimulatedDevice.
place_weight` raising Bz by the predicted nominal rise. ``scale`` stands for another magnet grade (the field is
proportional to the remanence) and ``flipped`` for a magnet put in upside down (every component changes sign).
:meth:`SimulatedDevice.turn` turns the sensor over in an Earth's field (its own weight reversed; ``loose_mm`` a
magnet loose in its pocket), :meth:`SimulatedDevice.warm` warms the chip.

Temperature: the chip reads 25 C with a slow +/-0.5 C wander unless ``temperature`` gives another course (a
:class:`TemperatureRamp` or any ``t_s -> degC``); the field scales by (1 + a (T - T0)) per axis, a the
calibration's own ``thermal`` coefficients (or ``thermal_per_C``), and the forces are what the firmware sends:
the calibration at the field read, corrected with the temperature read when the calibration carries ``thermal``.
"""

from __future__ import annotations

import math
import os
import random
import time
from typing import Optional, Tuple

from . import _build, eeprom
from .calibration import Calibration
from .frames import (
    STATUS_CHIP_ERROR,
    STATUS_FULL_SCALE,
    STATUS_OUTSIDE_REGION,
    STATUS_RECOVERED,
    encode_frame,
    encode_info_line,
    encode_text_line,
    line_checksum,
    temperature_C,
)

__all__ = ["PressPattern", "RestTip", "SimulatedDevice", "TemperatureRamp", "WeighedTip"]

#: The fault word of the simulated device's error samples: a NACK while reading (frames.FAULTS, FAULT_STAGES).
SIMULATED_FAULT = 1 << 8 | 1

REST_MARGIN_SIGMAS = 3.0  # the press pattern's rest point lies this many noise sigmas inside the valid region
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))  # turns the press direction evenly round the circle
#: How fast :meth:`SimulatedDevice.warm` warms the chip, C/s: fast, so a simulated warm-up takes seconds (a hand on
#: a board warms it by a few C a minute).
WARM_RATE_C_PER_S = 5.0


class PressPattern:
    """A repeating press: ``rest_s`` at rest, then a raised-cosine press of ``press_s`` towards the next corner
    of the valid region (``reach`` of the way from the rest point), the lateral direction turning with the
    press and coming back at rest, so the field is continuous.

    The rest point is the field where the calibration reads no force, as a real sensor reads at rest right after
    its calibration (whose scan started from rest at zero force): near the axis (the lateral field below the
    calibration's ``direction_min_uT``, where the firmware gives no lateral force), Bz where the calibrated Fz
    crosses zero, at least ``margin_uT`` inside the valid region so the noise at rest stays inside it."""

    def __init__(self, calibration: Calibration, rest_s: float = 1.0, press_s: float = 1.5, reach: float = 0.9,
                 margin_uT: float = 0.0) -> None:
        self.calibration = calibration
        self.rest_s = float(rest_s)
        self.press_s = float(press_s)
        self.margin_uT = max(0.0, float(margin_uT))
        self.rest = self._rest_point()
        self.targets = self._targets(reach)

    def _force(self, Bz: float, Br: float) -> float:
        """|F| (N) the firmware gives for a field (Bz, Br): the global polynomial, no lateral force below
        ``direction_min_uT``."""
        return math.sqrt(sum(f * f for f in self.calibration.evaluate(Br, 0.0, Bz, method="poly")))

    def _inside(self, Bz: float, Br: float, margin: float) -> bool:
        """(Bz, Br) and the points ``margin`` from it along each axis all in the valid region."""
        return all(self.calibration.in_region(z, r) for z, r in (
            (Bz, Br), (Bz - margin, Br), (Bz + margin, Br), (Bz, max(0.0, Br - margin)), (Bz, Br + margin)))

    def _candidates(self) -> list:
        """(|F|, Bz, Br) along lines of constant Br near the axis: a grid over the region's Bz, and each root of
        Fz between grid points (bisection) with a fine ladder of points either side of it (for a root just
        outside the region); least force first."""
        cal = self.calibration
        (zlo, zhi), (rlo, rhi) = cal.box
        step = max(cal.to_dict()["direction_min_uT"], 1e-3 * (rhi - rlo)) / 4.0
        rung = max(self.margin_uT, step, 1e-4 * (zhi - zlo)) / 4.0
        out = []
        n = 200
        for k in range(12):  # Br from 0 to 2.75 direction_min_uT: the axis, and just off it
            Br = max(rlo, 0.0) + k * step
            zs = [zlo + (zhi - zlo) * a / n for a in range(n + 1)]
            fz = [cal.model(z, Br, method="poly")[0] for z in zs]
            out += [(self._force(z, Br), z, Br) for z in zs]
            for a in range(n):
                if (fz[a] < 0.0) != (fz[a + 1] < 0.0):
                    root = self._root(Br, zs[a], zs[a + 1])
                    out += [(self._force(z, Br), z, Br) for z in (root + j * rung for j in range(-40, 41))]
        return sorted(out)

    def _root(self, Br: float, lo: float, hi: float) -> float:
        """Bz between ``lo`` and ``hi`` where the calibrated Fz at ``Br`` changes sign (bisection)."""
        below = self.calibration.model(lo, Br, method="poly")[0] < 0.0
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            if (self.calibration.model(mid, Br, method="poly")[0] < 0.0) == below:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)

    def _rest_point(self) -> Tuple[float, float]:
        """(Bz, Br) at rest: the candidate with the least force at least ``margin_uT`` inside the region (then
        any inside it); the region's grid point of least force when no candidate near the axis is inside."""
        candidates = self._candidates()
        for margin in (self.margin_uT, 0.0):
            for _, Bz, Br in candidates:
                if self._inside(Bz, Br, margin):
                    return Bz, Br
        return self._least_force_point()

    def _least_force_point(self) -> Tuple[float, float]:
        """The grid point of the valid region (kept off its edges) where the firmware's |F| is smallest: for a
        region away from the axis."""
        cal = self.calibration
        hull = cal.hull
        centre = (sum(p[0] for p in hull) / len(hull), sum(p[1] for p in hull) / len(hull))
        (zlo, zhi), (rlo, rhi) = cal.box
        zlo, zhi = max(zlo, min(p[0] for p in hull)), min(zhi, max(p[0] for p in hull))
        rlo, rhi = max(rlo, min(p[1] for p in hull)), min(rhi, max(p[1] for p in hull))
        best, best_norm = None, math.inf
        n = 40
        for a in range(n + 1):
            for b in range(n + 1):
                point = (zlo + (zhi - zlo) * a / n, rlo + (rhi - rlo) * b / n)
                inner = (centre[0] + 0.98 * (point[0] - centre[0]), centre[1] + 0.98 * (point[1] - centre[1]))
                if not (cal.in_region(*point) and cal.in_region(*inner)):
                    continue
                norm = self._force(*inner)
                if norm < best_norm:
                    best, best_norm = inner, norm
        return best if best is not None else centre

    def _targets(self, reach: float) -> list:
        """The corners of the region pulled towards the rest point, strongest calibrated force first; corners
        with less than a quarter of the strongest force (the rest side of the region) are left out."""
        cal = self.calibration
        points = [self._pull_inside(corner, reach) for corner in cal.hull]
        strength = [math.hypot(*cal.model(*p, method="poly")) for p in points]
        strongest = max(strength)
        ranked = sorted(range(len(points)), key=lambda k: (-strength[k], k))
        return [points[k] for k in ranked if strength[k] >= 0.25 * strongest]

    def _pull_inside(self, corner: Tuple[float, float], reach: float) -> Tuple[float, float]:
        rest, cal = self.rest, self.calibration
        s = reach
        while s > 1e-3:
            point = (rest[0] + s * (corner[0] - rest[0]), rest[1] + s * (corner[1] - rest[1]))
            if cal.in_region(*point):
                return point
            s *= 0.8
        return rest

    def field(self, t_s: float) -> Tuple[float, float, float]:
        """(Bx, By, Bz) in microtesla at time ``t_s``, without noise."""
        period = self.rest_s + self.press_s
        cycle = int(t_s // period)
        tau = t_s - cycle * period
        s = math.sin(math.pi * (tau - self.rest_s) / self.press_s) ** 2 if tau > self.rest_s else 0.0
        target = self.targets[cycle % len(self.targets)]
        Bz = self.rest[0] + s * (target[0] - self.rest[0])
        Br = self.rest[1] + s * (target[1] - self.rest[1])
        phi = s * GOLDEN_ANGLE * (cycle + 1)
        return Br * math.cos(phi), Br * math.sin(phi), Bz


class RestTip:
    """The fingertip at rest, as magfab predicted it, with an optional weight on it.

    ``rest_Bz_uT`` is the field at rest on the axis (Bx = By = 0); ``force_N`` and ``delta_Bz_uT`` tabulate
    the rise of Bz against the force on the tip (acceptance.json ``weight.table``: the nominal column), so a
    weight of W grams raises Bz by the rise at W * ``G0`` / 1000 N (linear interpolation). ``scale`` multiplies
    the whole field (another magnet grade: remanence ratio); ``flipped`` reverses its sign (magnet upside down).
    """

    G0 = 9.80665  # m/s^2

    def __init__(self, rest_Bz_uT: float, force_N=(0.0,), delta_Bz_uT=(0.0,), *, scale: float = 1.0,
                 flipped: bool = False) -> None:
        force, delta = [float(f) for f in force_N], [float(d) for d in delta_Bz_uT]
        if len(force) != len(delta) or not force or any(b <= a for a, b in zip(force, force[1:])):
            raise ValueError("force_N must be increasing and as long as delta_Bz_uT")
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"scale must be a positive number; instead received {scale!r}")
        self.rest_Bz_uT = float(rest_Bz_uT)
        self.force_N = force
        self.delta_Bz_uT = delta
        self.scale = float(scale)
        self.flipped = bool(flipped)
        self.load_g = 0.0
        #: Turned upside down (:meth:`turn`): the Earth's field changes by ``earth_change_uT`` (Bx, By, Bz), the
        #: fingertip's own weight of ``own_weight_g`` pulls instead of pressing, and a loose magnet moves the field
        #: on the axis by ``loose_uT`` more (negative: it slides away from the chip).
        self.turned = False
        self.earth_change_uT: Tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.own_weight_g = 0.0
        self.loose_uT = 0.0

    @classmethod
    def from_acceptance(cls, data: dict, *, scale: float = 1.0, flipped: bool = False,
                        loose_mm: float = 0.0) -> RestTip:
        """The nominal sensor of an acceptance.json (format magfab-acceptance/1). With its ``rotation`` section,
        turned over (:meth:`turn`) in an Earth's field of the middle of its band, inclined 60 deg (a mid-latitude
        place; the turn is about the chip's x axis, across the field's horizontal part), with the fingertip's own
        weight reversed; ``loose_mm``: the magnet slides that far away from the chip when the sensor is turned."""
        table = data["weight"]["table"]
        tip = cls(data["rest"]["Bz_uT"]["nominal"], table["force_N"], table["delta_Bz_nominal_uT"], scale=scale,
                  flipped=flipped)
        rotation = data.get("rotation")
        if rotation is not None:
            low, high = rotation.get("earth_field_band_uT", (0.0, 0.0))
            earth, incline = (low + high) / 2.0, math.radians(60.0)
            # upright (0, E cos I, -E sin I); turned about x: (0, -E cos I, E sin I)
            tip.earth_change_uT = (0.0, -2.0 * earth * math.cos(incline), 2.0 * earth * math.sin(incline))
            tip.own_weight_g = rotation["self_weight_mN"] / 2.0 / cls.G0
            tip.loose_uT = -abs(float(loose_mm)) * rotation["gradient_uT_per_mm"]
        return tip

    def turn(self, over: bool) -> None:
        """Turn the sensor upside down (``over``) or back upright."""
        self.turned = bool(over)

    def rise_uT(self, grams: float) -> float:
        """The nominal rise of Bz (uT, before ``scale`` and ``flipped``) under a weight of ``grams``."""
        f = max(0.0, float(grams)) * self.G0 / 1000.0
        xs, ys = self.force_N, self.delta_Bz_uT
        if f >= xs[-1]:
            if len(xs) == 1:
                return ys[0]
            return ys[-1] + (ys[-1] - ys[-2]) * (f - xs[-1]) / (xs[-1] - xs[-2])
        for k in range(1, len(xs)):
            if f <= xs[k]:
                return ys[k - 1] + (ys[k] - ys[k - 1]) * (f - xs[k - 1]) / (xs[k] - xs[k - 1])
        return ys[0]

    def place_weight(self, grams: float) -> None:
        """Put a weight of ``grams`` on the tip (0: take it off)."""
        if not (math.isfinite(grams) and grams >= 0):
            raise ValueError(f"grams must be a non-negative number; instead received {grams!r}")
        self.load_g = float(grams)

    def field(self, t_s: float) -> Tuple[float, float, float]:
        """(Bx, By, Bz) in microtesla, without noise: constant until the load changes."""
        sign = -1.0 if self.flipped else 1.0
        bz = self.rest_Bz_uT + self.rise_uT(self.load_g)
        if not self.turned:
            return 0.0, 0.0, sign * self.scale * bz
        bz += -2.0 * self.rise_uT(self.own_weight_g) + self.loose_uT
        ex, ey, ez = self.earth_change_uT
        return ex, ey, sign * self.scale * bz + ez


class WeighedTip:
    """The tip under the weight jig, for ``magfab-readout weigh``: the nominal sensor's field under a mass on the tip
    with the board on the stand at an angle, interpolated linearly in the mass from the weight plan's ``nominal``
    tables (one per angle: ``angle_deg``, ``mass_g`` rising, ``field_uT`` (Bx, By, Bz) rows)."""

    def __init__(self, nominal) -> None:
        self.tables = {float(t["angle_deg"]): ([float(m) for m in t["mass_g"]],
                                               [tuple(float(v) for v in row) for row in t["field_uT"]])
                       for t in nominal}
        if not self.tables or any(len(m) < 2 or len(m) != len(b) for m, b in self.tables.values()):
            raise ValueError("each angle's table needs two or more masses, one field row each")
        for masses, rows in self.tables.values():
            rising = all(math.isfinite(m) for m in masses) and all(a < b for a, b in zip(masses, masses[1:]))
            if not rising or not all(len(row) == 3 and all(math.isfinite(v) for v in row) for row in rows):
                raise ValueError("each angle's masses must rise and each field row be three finite numbers")
        self.mass_g, self.angle_deg = 0.0, min(self.tables)

    def place_load(self, mass_g: float, angle_deg: float) -> None:
        """The board on the stand at ``angle_deg`` (one of the tables') with ``mass_g`` on the tip."""
        if float(angle_deg) not in self.tables:
            raise ValueError(f"no table for {angle_deg!r} deg; the plan's angles are {sorted(self.tables)}")
        if not (math.isfinite(mass_g) and mass_g >= 0):
            raise ValueError(f"mass_g must be a non-negative number; instead received {mass_g!r}")
        self.mass_g, self.angle_deg = float(mass_g), float(angle_deg)

    def field(self, t_s: float) -> Tuple[float, float, float]:
        """(Bx, By, Bz) in microtesla, without noise: constant until the load changes (held at the table's ends)."""
        masses, fields = self.tables[self.angle_deg]
        m = min(max(self.mass_g, masses[0]), masses[-1])
        k = next(i for i in range(1, len(masses)) if masses[i] >= m)
        w = (m - masses[k - 1]) / (masses[k] - masses[k - 1])
        return tuple(a + w * (b - a) for a, b in zip(fields[k - 1], fields[k]))  # type: ignore[return-value]


class TemperatureRamp:
    """The chip's temperature: ``start_C`` until ``delay_s``, then rising linearly to ``end_C`` over
    ``duration_s``, then held (a warm-up)."""

    def __init__(self, start_C: float, end_C: float, duration_s: float, delay_s: float = 0.0) -> None:
        if not (duration_s > 0 and delay_s >= 0):
            raise ValueError("duration_s must be positive and delay_s at least 0; instead received "
                             f"{duration_s!r}, {delay_s!r}")
        self.start_C, self.end_C = float(start_C), float(end_C)
        self.duration_s, self.delay_s = float(duration_s), float(delay_s)

    def __call__(self, t_s: float) -> float:
        x = min(1.0, max(0.0, (t_s - self.delay_s) / self.duration_s))
        return self.start_C + x * (self.end_C - self.start_C)


def _wander(t_s: float) -> float:
    """The default course: 25 C with a +/-0.5 C wander over a minute."""
    return 25.0 + 0.5 * math.sin(2 * math.pi * t_s / 60.0)


def _temperature_raw(T: float) -> int:
    """The chip's temperature word for ``T`` degC (0 when the build reads no temperature)."""
    if not _build.TEMPERATURE_ENABLED:
        return 0
    return max(0, min(0xFFFF, round(_build.TEMPERATURE_RAW_25C + _build.TEMPERATURE_LSB_PER_C * (T - 25.0))))


def _clamp16(x: float) -> int:
    return max(-32768, min(32767, round(x)))


class SimulatedDevice:
    """Stands in for a serial port with the firmware behind it: ``read``, ``write`` and ``close``.

    ``realtime`` paces the samples at ``rate_Hz`` by the wall clock (as a real device); otherwise every read
    returns the next ``chunk`` samples at once. Faults for testing: ``corrupt_fraction`` of the frames get one
    bit flipped after the CRC was computed, and every ``chip_error_every``-th sample reports a chip error
    (NaN forces) followed by a recovered flag. ``spec_name`` and ``calibration_hash`` set what the info line
    reports (by default what this package embeds). ``pattern`` is what moves the field (anything with
    ``field(t_s) -> (Bx, By, Bz)`` in uT): by default a :class:`PressPattern` over the calibrated region; a
    :class:`RestTip` for the acceptance test. ``temperature`` (``t_s -> degC``, e.g. a :class:`TemperatureRamp`)
    is the chip's temperature and ``thermal_per_C`` (one value or (x, y, z), 1/degC) how the field follows it,
    from the calibration's ``reference_C`` (default: the calibration's own coefficients, none without ``thermal``).
    ``eeprom_file`` keeps the board's EEPROM between runs (``--simulate-eeprom``): read at the start, written after
    every 'w' command, as a board keeps it between commands.
    """

    port = "the simulated device"

    def __init__(self, calibration: Optional[Calibration] = None, *, seed: int = 0,
                 rate_Hz: float = _build.SAMPLE_RATE_HZ, realtime: bool = True, text: Optional[bool] = None,
                 noise_lsb: float = 0.7, corrupt_fraction: float = 0.0, chip_error_every: int = 0,
                 chunk: int = 64, spec_name: str = _build.SPEC_NAME, calibration_hash: Optional[str] = None,
                 pattern=None, temperature=None, thermal_per_C=None, eeprom_file: Optional[str] = None) -> None:
        if not rate_Hz > 0:
            raise ValueError(f"rate_Hz must be positive; instead received {rate_Hz!r}")
        if not 0.0 <= corrupt_fraction <= 1.0:
            raise ValueError(f"corrupt_fraction must be in [0, 1]; instead received {corrupt_fraction!r}")
        self.calibration = calibration if calibration is not None else Calibration.embedded()
        if not (math.isfinite(noise_lsb) and noise_lsb >= 0):
            raise ValueError(f"noise_lsb must be a non-negative number; instead received {noise_lsb!r}")
        # the rest point 3 sigma of the noise inside the region: its readings stay inside it
        margin = REST_MARGIN_SIGMAS * noise_lsb * max(_build.LSB_XY_UT, _build.LSB_Z_UT)
        self.pattern = pattern if pattern is not None else PressPattern(self.calibration, margin_uT=margin)
        self.rate_Hz = float(rate_Hz)
        self.temperature = temperature if temperature is not None else _wander
        thermal = self.calibration.thermal
        self.reference_C = thermal.reference_C if thermal is not None else 25.0
        if thermal_per_C is None:
            thermal_per_C = thermal.coefficient_per_C if thermal is not None else 0.0
        self.thermal_per_C = tuple(float(a) for a in (
            thermal_per_C if isinstance(thermal_per_C, (tuple, list)) else (thermal_per_C,) * 3))
        self.period_us = round(1e6 / self.rate_Hz)
        self.realtime = realtime
        self.text = (_build.OUTPUT == "text") if text is None else bool(text)
        self.noise_lsb = float(noise_lsb)
        self.corrupt_fraction = float(corrupt_fraction)
        self.chip_error_every = int(chip_error_every)
        self.chunk = int(chunk)
        self.info_line = encode_info_line(spec_name, calibration_hash or self.calibration.short_hash,
                                          _build.GAIN_SEL, _build.RESOLUTION, _build.OSR, _build.DIG_FILT)
        self._noise = random.Random(seed)
        self._faults = random.Random(seed + 1)
        self._k = 0
        self._recovered = False
        self._pending = b""
        self._start: Optional[float] = None
        self.closed = False
        self._command = b""
        #: The board's EEPROM as the simulated firmware sees it: erased (or as ``eeprom_file`` keeps it from an
        #: earlier run), then written by 'w' commands (``magfab-readout upload``); the info line's hash follows a
        #: valid record there.
        self.eeprom = bytearray(b"\xff" * eeprom.SIZE)
        self.eeprom_file = eeprom_file
        self._load_eeprom()

    # --- the serial port's interface ---------------------------------------------------------------------

    def _eeprom_command(self) -> None:
        """Answer a complete 'w' / 'r' command as the firmware does (docs/bundle.md section 4)."""
        cmd = self._command
        address, n = cmd[1] | cmd[2] << 8, cmd[3]
        if cmd[:1] == b"r":
            body = f"R,{address},{bytes(self.eeprom[address:address + min(n, 32)]).hex().upper()}"
        else:
            crc = cmd[4 + n] | cmd[5 + n] << 8
            status = 1 if eeprom.crc16(cmd[:4 + n]) != crc else (2 if address + n > eeprom.SIZE else 0)
            if status == 0:
                self.eeprom[address:address + n] = cmd[4:4 + n]
                self._save_eeprom()
            body = f"W,{address},{n},{status},{0 if self._reload() else 10}"
        self._pending += body.encode("ascii") + line_checksum(body.encode("ascii")) + b"\n"
        self._command = b""

    def _reload(self) -> bool:
        """Whether the EEPROM holds a valid record for this build's chip settings; the info line's hash follows it."""
        settings = (_build.GAIN_SEL, _build.RESOLUTION, _build.OSR, _build.DIG_FILT)
        valid = eeprom.check(bytes(self.eeprom)) and eeprom.unpack_header(bytes(self.eeprom))["settings"] == settings
        if valid:
            head = eeprom.unpack_header(bytes(self.eeprom))
            self.info_line = encode_info_line(self.info_line.decode().split(",")[2], head["sha16"], *settings)
        return valid

    def _load_eeprom(self) -> None:
        """The EEPROM as ``eeprom_file`` keeps it (erased when the file does not exist yet)."""
        if self.eeprom_file is None or not os.path.exists(self.eeprom_file):
            return
        with open(self.eeprom_file, "rb") as f:
            data = f.read(eeprom.SIZE)
        self.eeprom[:len(data)] = data
        self._reload()

    def _save_eeprom(self) -> None:
        if self.eeprom_file is not None:
            with open(self.eeprom_file, "wb") as f:
                f.write(bytes(self.eeprom))

    def write(self, data: bytes) -> int:
        """Commands from the host: 'b' binary frames, 't' text lines, 'i' one info line, and the EEPROM commands
        'w' and 'r'; others are ignored."""
        for byte in bytes(data):
            if self._command:
                self._command += bytes((byte,))
                if len(self._command) >= 4 and (self._command[:1] == b"r"
                                                or len(self._command) == 6 + self._command[3]):
                    self._eeprom_command()
                continue
            if byte in (ord("w"), ord("r")):
                self._command = bytes((byte,))
            elif byte == ord("b"):
                self.text = False
            elif byte == ord("t"):
                self.text = True
            elif byte == ord("i"):
                self._pending += self.info_line
        return len(data)

    def read(self, size: int = 4096, timeout_s: float = 0.05) -> bytes:
        """Up to ``size`` bytes: pending output, then the samples that are due (waiting up to ``timeout_s``)."""
        if self.closed:
            raise OSError("the simulated device is closed")
        if self.realtime:
            now = time.monotonic()
            if self._start is None:
                self._start = now
            due = int((now - self._start) * self.rate_Hz) + 1
            if due <= self._k and not self._pending:
                wait = (self._k / self.rate_Hz) - (now - self._start)
                time.sleep(max(0.0, min(wait, timeout_s)))
                due = int((time.monotonic() - self._start) * self.rate_Hz) + 1
        else:
            due = self._k + self.chunk
        out = [self._pending]
        self._pending = b""
        length = len(out[0])
        while self._k < due and length < size:
            wire = self._sample_bytes(self._k)
            out.append(wire)
            length += len(wire)
            self._k += 1
        data = b"".join(out)
        self._pending = data[size:]
        return data[:size]

    def close(self) -> None:
        """Stop the device; further reads fail as on a closed port."""
        self.closed = True

    def turn(self, over: bool) -> None:
        """Turn the simulated sensor upside down (``over``) or back (a :class:`RestTip` pattern only)."""
        turn = getattr(self.pattern, "turn", None)
        if turn is None:
            raise ValueError("this simulated device runs a press pattern; turning it needs pattern=RestTip(...)")
        turn(over)

    def warm(self, by_C: float, rate_C_per_s: float = WARM_RATE_C_PER_S) -> None:
        """Warm the chip by ``by_C`` from the next sample on, at ``rate_C_per_s`` (a :class:`TemperatureRamp`)."""
        now_s = self._k / self.rate_Hz
        start = self.temperature(now_s)
        self.temperature = TemperatureRamp(start, start + by_C, duration_s=max(abs(by_C), 1e-3) / rate_C_per_s,
                                           delay_s=now_s)

    def place_weight(self, grams: float) -> None:
        """Put a weight on the simulated tip (a :class:`RestTip` pattern only): later samples carry its field."""
        place = getattr(self.pattern, "place_weight", None)
        if place is None:
            raise ValueError("this simulated device runs a press pattern; a weight needs pattern=RestTip(...)")
        place(grams)

    # --- what the firmware would send -------------------------------------------------------------------

    def _at_temperature(self, B, T: float) -> Tuple[float, float, float]:
        """The field ``B`` (uT) with the magnet at ``T`` degC: (1 + a (T - T0)) per axis."""
        return tuple(b * (1.0 + a * (T - self.reference_C)) for b, a in zip(B, self.thermal_per_C))

    def _sample_bytes(self, k: int) -> bytes:
        """The wire bytes of sample ``k`` in the current mode; called once per sample, in order (noise, faults)."""
        t_s = k / self.rate_Hz
        t_us = (k * self.period_us) & 0xFFFFFFFF
        seq = k & 0xFF
        status = STATUS_RECOVERED if self._recovered else 0
        self._recovered = False
        if self.chip_error_every and k % self.chip_error_every == self.chip_error_every - 1:
            self._recovered = True
            nan = float("nan")
            status |= STATUS_CHIP_ERROR
            if self.text:
                return encode_text_line(seq, t_us, status, (nan, nan, nan), (nan, nan, nan), None, SIMULATED_FAULT)
            return encode_frame(seq, t_us, status, (0, 0, 0), SIMULATED_FAULT, (nan, nan, nan))
        T = self.temperature(t_s)
        Bx, By, Bz = self._at_temperature(self.pattern.field(t_s), T)
        lsb_xy, lsb_z = _build.LSB_XY_UT, _build.LSB_Z_UT
        counts = (_clamp16(Bx / lsb_xy + self._noise.gauss(0.0, self.noise_lsb)),
                  _clamp16(By / lsb_xy + self._noise.gauss(0.0, self.noise_lsb)),
                  _clamp16(Bz / lsb_z + self._noise.gauss(0.0, self.noise_lsb)))
        if max(abs(c) for c in counts) >= _build.FULL_SCALE_COUNTS:
            status |= STATUS_FULL_SCALE
        B = (counts[0] * lsb_xy, counts[1] * lsb_xy, counts[2] * lsb_z)
        t_raw = _temperature_raw(T)
        read_C = temperature_C(t_raw) if _build.TEMPERATURE_ENABLED else None
        if not self.calibration.in_region_B(*self.calibration.corrected(*B, temperature_C=read_C)):
            status |= STATUS_OUTSIDE_REGION
        force = self.calibration.evaluate(*B, method="poly", temperature_C=read_C)  # what the firmware computes
        if self.text:
            temp = temperature_C(t_raw) if _build.TEMPERATURE_ENABLED else None
            return encode_text_line(seq, t_us, status, force, B, temp)
        frame = encode_frame(seq, t_us, status, counts, t_raw, force)
        if self.corrupt_fraction and self._faults.random() < self.corrupt_fraction:
            position = self._faults.randrange(2, len(frame))
            frame = (frame[:position] + bytes([frame[position] ^ (1 << self._faults.randrange(8))])
                     + frame[position + 1:])
        return frame
