"""What the single taxel's commands (:mod:`.cli`) and an array's (:mod:`.array_cli`) share: the columns and number
formats of ``stream`` and ``record``, ``record``'s header and its Ctrl-C, and the retry at the fallback baud."""

from __future__ import annotations

import argparse
import json
import math
import signal
from typing import Any, List, Optional, Sequence

from . import _build, eeprom
from .device import NoData
from .usage import UsageError

__all__ = ["FAILED", "CSV_COLUMNS", "Interrupt", "Span", "UsageError", "at_fallback_baud", "format_csv",
           "format_number", "record_header"]

#: ``record``'s columns (docs/bundle.md section 1): host_time_s ties the recording to a reference sensor's log.
CSV_COLUMNS = ("time_s", "host_time_s", "Bx_uT", "By_uT", "Bz_uT", "temperature_C", "Fx_sensor_N", "Fy_sensor_N",
               "Fz_sensor_N", "status", "seq")


#: ``check``'s exit status when the sensor failed a step (its verdict, not an error: 1 is kept for a bug of ours).
FAILED = 3


def check_link(args: argparse.Namespace) -> None:
    """:class:`UsageError` (one line) for a ``--timeout`` that is not a positive number of seconds or a
    ``--simulate-corrupt`` that is not a fraction from 0 to 1 (argparse takes any float, nan and inf included)."""
    timeout = getattr(args, "timeout", None)
    if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
        raise UsageError(f"--timeout {timeout}: must be a positive number of seconds")
    corrupt = getattr(args, "simulate_corrupt", None)
    if corrupt is not None and not 0.0 <= corrupt <= 1.0:
        raise UsageError(f"--simulate-corrupt {corrupt}: must be a fraction from 0 to 1")


def format_number(x: Optional[float], width: int, decimals: int, sign: bool = True) -> str:
    if x is None or math.isnan(x):
        return "nan".rjust(width)
    return "{:{}{}.{}f}".format(x, "+" if sign else "", width, decimals)


def format_csv(x: Optional[float], decimals: int) -> str:
    return "{:.{}f}".format(x, decimals)


class Interrupt:
    """SIGINT while recording: KeyboardInterrupt while waiting for the device, held back while a row is written."""

    requested = writing = False
    _previous: Any = None  # the handler to restore (a function, an int or None)

    def __call__(self, signum, frame) -> None:
        self.requested = True
        if not self.writing:
            raise KeyboardInterrupt

    def __enter__(self) -> Interrupt:
        try:
            self._previous = signal.signal(signal.SIGINT, self)
        except ValueError:  # not the main thread: Ctrl-C stays a KeyboardInterrupt, ended here
            self._previous = None
        return self

    def __exit__(self, kind, value, traceback) -> bool:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return kind is KeyboardInterrupt


class Span:
    """The device time the frames of a stream or recording span, and how many there were (``add`` each one's time:
    a sample's, or an array cycle's)."""

    def __init__(self) -> None:
        self.first: Optional[float] = None
        self.last: Optional[float] = None
        self.n = 0
        self.timed = 0

    def add(self, time_s: Optional[float]) -> None:
        self.n += 1
        if time_s is not None:
            self.first = time_s if self.first is None else self.first
            self.last = time_s
            self.timed += 1

    def rate(self, what: str = "frames") -> str:
        """'; R <what>/s over S s of device time, against the chip's C conversions/s (P)', or '' with too few."""
        if self.timed < 2 or self.first is None or self.last is None or not self.last > self.first:
            return ""
        seconds = self.last - self.first
        rate = (self.timed - 1) / seconds
        chip = _build.SAMPLE_RATE_HZ
        measured = (f"; the image delivered {_build.MEASURED_RATE_HZ:.0f} frames/s at the busiest field of its "
                    "calibrated region on a simulated bus" if _build.MEASURED_RATE_HZ else "")  # None for an array
        return (f"; {rate:.1f} {what}/s over {seconds:.2f} s of device time, against the chip's {chip:.1f} "
                f"conversions/s ({rate / chip:.1%}){measured}")


def record_header(f, device, info, columns: List[str], extra: Sequence[str] = ()) -> None:
    f.write(f"# magfab-readout {_build.VERSION} record\n")
    f.write(f"# spec: {json.dumps(_build.SPEC_NAME)}\n")
    f.write(f"# calibration_sha256: {device.calibration.sha256}\n")
    f.write(f"# device: {json.dumps(info.line)}\n")
    f.write(f"# chip: gain_sel={_build.GAIN_SEL} resolution={_build.RESOLUTION} osr={_build.OSR} "
            f"dig_filt={_build.DIG_FILT} lsb_xy_uT={_build.LSB_XY_UT!r} lsb_z_uT={_build.LSB_Z_UT!r}\n")
    f.write("# time_s: the device's clock; host_time_s: this computer's clock (Unix time, s) when the sample was "
            "read\n")
    f.write("# Fx_sensor_N, Fy_sensor_N, Fz_sensor_N: this sensor's own calibrated force, not a reference; to "
            "calibrate, log a reference force sensor during the scan with time_s on this computer's clock (Unix "
            "time, s) and Fx_N, Fy_N, Fz_N, and pass it: magfab calibrate THIS.csv --reference REFERENCE.csv\n")
    f.write("".join(line + "\n" for line in extra) + ",".join(columns) + "\n")


def at_fallback_baud(args: argparse.Namespace, out, open_device, action):
    """``action(device)`` on the board, and when nothing answers again at the fallback baud, which a board without a
    valid record speaks (docs/bundle.md section 4)."""
    try:
        with open_device(args) as device:
            return action(device)
    except NoData:
        if args.simulate or args.baud == eeprom.FALLBACK_BAUD:
            raise
        out.write(f"no answer at {args.baud} baud; trying {eeprom.FALLBACK_BAUD} baud (a board without a "
                  "calibration)\n")
        with open_device(argparse.Namespace(**{**vars(args), "baud": eeprom.FALLBACK_BAUD})) as device:
            return action(device)
