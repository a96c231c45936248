"""The sensor as features of a LeRobot dataset, recorded beside a robot's other streams at their own rates (README.md,
"Into a LeRobot dataset").

A LeRobotDataset has one frame rate (its ``fps``: a camera's 30, say), and the sensor sends 543 frames a second.
:class:`TactileFeed` reads the board in a thread of its own and, for each dataset frame, gives:

* ``observation.tactile.force``: every taxel's newest force at the frame's time (Fx, Fy, Fz in N, taxel after taxel),
  what a policy reads at the dataset's rate;
* ``observation.tactile.window``: every sample since the frame before, newest last, ``window`` rows of the same
  columns, NaN before the first (so the chip's full rate is kept, not only its value at the frame);
* ``observation.tactile.count``: how many rows of the window are samples, and how many samples since the frame
  before did not fit in it (a frame later than the window: the newest are kept). Two numbers, not one: LeRobot
  0.4.4 stores a feature of shape (1,) as a scalar, which it cannot convert under numpy 2.

A sample's time is the host's clock mapped from the board's (:func:`magfab_readout.clock.clock_map` over the last
samples, as ``record``'s Parquet and MCAP files), so the serial link's buffering does not move it. A sample with a
chip error, a missing frame or an axis at full scale has NaN force, as everywhere in this package.

Needs numpy (which LeRobot brings; nothing else of this package imports this module, so the base install stays
pyserial-only); nothing here imports LeRobot, so the feed can be tried without it.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from typing import Any, Deque, Dict, List, Optional, Tuple

import numpy as np

from . import _build
from .array_sim import SimulatedArray
from .clock import clock_map
from .device import Device
from .taxels import ArrayCalibration, ArrayReader

__all__ = ["COUNT", "FORCE", "WINDOW", "TactileFeed", "open_device"]

FORCE = "observation.tactile.force"
WINDOW = "observation.tactile.window"
COUNT = "observation.tactile.count"
#: Samples the clock map is fitted to (about 7 s at the chip's rate), and how often it is fitted again at least, s.
CLOCK_SAMPLES, CLOCK_EVERY_S = 4096, 0.5


def open_device(port: Optional[str] = None, simulate: bool = False) -> Device:
    """This package's board (``port`` as the commands find it), or with ``simulate`` its simulated board: a single
    taxel's, or an array's, as the package is."""
    array = ArrayCalibration.embedded()
    if array is None:
        return Device(port, text=False, simulate=simulate)
    transport = SimulatedArray(array) if simulate else None
    return Device(port, text=False, calibration=array.calibrations[0], transport=transport)


class TactileFeed:
    """The board read in a thread of its own; :meth:`frame` at each dataset frame (module doc).

    ``device`` is an open :class:`~magfab_readout.Device`; for an array, ``reader`` its
    :class:`~magfab_readout.ArrayReader`. ``fps`` is the dataset's frame rate, ``rate_Hz`` the sensor's;
    the window holds ``rate_Hz / fps`` samples and a margin."""

    def __init__(self, device, fps: float, rate_Hz: float, reader=None, taxels: int = 1) -> None:
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number of frames a second; instead received {fps!r}")
        self.device, self.reader, self.taxels = device, reader, int(taxels)
        # a frame late by the scheduler's jitter still fits; a later one keeps the newest samples
        self.window = math.ceil(rate_Hz / fps) + 4
        self._samples: Deque[Tuple[float, float, Tuple[float, ...]]] = collections.deque()  # device t, host, force
        self._clock: Deque[Tuple[float, float]] = collections.deque(maxlen=CLOCK_SAMPLES)
        self._map = (0.0, 0.0, 1.0)
        self._mapped_at = -math.inf
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.error: Optional[BaseException] = None
        self._newest: Tuple[float, ...] = (math.nan,) * (3 * self.taxels)  # the force a frame without samples keeps

    @classmethod
    def of(cls, device, fps: float) -> TactileFeed:
        """The feed of this package's sensor on ``device`` (from :func:`open_device`): a single taxel's samples, or
        an array's cycles read with this package's calibration."""
        array = ArrayCalibration.embedded()
        if array is None:
            return cls(device, fps, _build.SAMPLE_RATE_HZ)
        return cls(device, fps, _build.SAMPLE_RATE_HZ, reader=ArrayReader(device, array), taxels=array.taxels)

    def features(self) -> Dict[str, Dict[str, Any]]:
        """The three features, as LeRobotDataset.create's ``features`` takes them."""
        names = [f"taxel{k}.{axis}" for k in range(self.taxels) for axis in ("Fx", "Fy", "Fz")]
        return {FORCE: {"dtype": "float32", "shape": (3 * self.taxels,), "names": names},
                WINDOW: {"dtype": "float32", "shape": (self.window, 3 * self.taxels), "names": ["sample", "force"]},
                COUNT: {"dtype": "int64", "shape": (2,), "names": ["samples", "dropped"]}}

    def _read(self) -> None:
        try:
            if self.reader is not None:
                source = ((c.time_s, tuple(f for t in c.taxels for f in t.force_N)) for c in self.reader.cycles(
                    keep_up=True))
            else:
                source = ((s.time_s, tuple(s.force_N)) for s in self.device.samples())
            for time_s, force in source:
                self.add(time_s, time.time(), force)
                if self._stop.is_set():
                    return
        except BaseException as exc:  # the frame that asks next raises it
            self.error = exc

    def add(self, time_s: Optional[float], host: float, force) -> None:
        """One sample (what the reading thread does with each): its device time, the host's time when it was read,
        its force columns."""
        with self._lock:
            if time_s is not None:
                self._clock.append((time_s, host))
                # fitted again on a read the line passes above (read sooner than the map says: the map was late), and
                # every CLOCK_EVERY_S for the clocks' drift
                if host < self._host(time_s, host) or host - self._mapped_at > CLOCK_EVERY_S:
                    self._map = clock_map([c[0] for c in self._clock], [c[1] for c in self._clock])
                    self._mapped_at = host
            self._samples.append((time_s if time_s is not None else math.nan, host, tuple(force)))

    def _host(self, time_s: float, read: float) -> float:
        t0, h0, slope = self._map
        return h0 + slope * (time_s - t0) if math.isfinite(time_s) else read

    def frame(self, at: Optional[float] = None) -> Dict[str, Any]:
        """The features at host time ``at`` (default: now): the newest force at or before it, the samples since the
        frame before. Raises what stopped the board's reading, if anything did."""
        if self.error is not None:
            raise self.error
        at = time.time() if at is None else at
        columns = 3 * self.taxels
        with self._lock:
            ready: List[Tuple[float, Tuple[float, ...]]] = []
            while self._samples:
                t, read, force = self._samples[0]
                host = self._host(t, read)
                if host > at:
                    break
                self._samples.popleft()
                ready.append((host, force))
        window = np.full((self.window, columns), np.nan, dtype=np.float32)
        rows = ready[-self.window:]
        if rows:
            window[self.window - len(rows):] = np.array([r[1] for r in rows], dtype=np.float32)
        if ready:
            self._newest = ready[-1][1]
        return {FORCE: np.array(self._newest, dtype=np.float32), WINDOW: window,
                COUNT: np.array([len(rows), len(ready) - len(rows)], dtype=np.int64)}

    def __enter__(self) -> TactileFeed:
        self._thread = threading.Thread(target=self._read, name="tactile", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
