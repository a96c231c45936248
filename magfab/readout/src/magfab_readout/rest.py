"""The rest level while the taxel is unloaded, tracked through a stream or a recording, and its drift.

The samples are taken in windows of :data:`WINDOW_S`. A window is *at rest* when its normal force is quiet (its
standard deviation at most :data:`QUIET_SIGMAS` times the force noise) and its mean within :data:`CAPTURE_SIGMAS`
times the force noise of the last rest level, or, for the first, anywhere (start the stream with nothing touching
the tip). The force noise is the chip's predicted field noise (acceptance.json ``measurement.noise_z_uT``; one count
without it) through this calibration's force per field at the rest field: the resolution. A press changes the
force far faster than the noise and fails the quiet test; a drift moves the level a little from window to window
and is followed. A steady touch lighter than the capture (a few tens of mN) is taken for rest: the summary's figure
is the drift only while nothing touches the tip.

The summary gives the change of the rest level from the first window at rest to the last (mN) and, when the chip's
temperature moved by at least :data:`MIN_SPAN_C`, the least-squares slope of the rest level over the temperature
(mN/C): what the temperature correction leaves (or, without it, the magnet's drift through the calibration).
"""

from __future__ import annotations

import math
from typing import List, Optional, Tuple

from . import _build

__all__ = ["RestTracker", "slope_mN_per_uT", "WINDOW_S", "QUIET_SIGMAS", "CAPTURE_SIGMAS", "MIN_SPAN_C"]

#: Length of a window, s of device time.
WINDOW_S = 0.25
#: A window is quiet when its normal force's standard deviation is at most this many times the force noise.
QUIET_SIGMAS = 2.0
#: ... and at rest when its mean is within this many times the force noise of the last rest level.
CAPTURE_SIGMAS = 20.0
#: Least span of the chip's temperature over the windows at rest for a per-degree figure, C.
MIN_SPAN_C = 0.5


def slope_mN_per_uT(calibration, B_uT, temperature_C=None) -> float:
    """|dFz/dBz| of ``calibration`` at the field ``B_uT`` (uT) and ``temperature_C``, mN/uT (a central difference
    over a few counts)."""
    bx, by, bz = B_uT
    h = 4.0 * _build.LSB_Z_UT
    up, down = (calibration.evaluate(bx, by, bz + s, method="poly", temperature_C=temperature_C)[2] for s in (h, -h))
    return abs(up - down) / (2.0 * h) * 1000.0


class RestTracker:
    """Feed it every sample (:meth:`add`); :meth:`summary` says how the rest level moved. ``noise_uT`` is the
    field noise on z (uT) that, through the calibration at the first good sample, sets the force noise."""

    def __init__(self, calibration, noise_uT: float, rate_Hz: float = _build.SAMPLE_RATE_HZ) -> None:
        self.calibration = calibration
        self.noise_uT = float(noise_uT)
        self.size = max(2, round(WINDOW_S * rate_Hz))
        self.noise_mN: Optional[float] = None
        self.level: Optional[float] = None
        self.points: List[Tuple[float, float, Optional[float]]] = []  # (time s, rest Fz mN, temperature C)
        self._window: List[Tuple[float, float, Optional[float]]] = []

    def add(self, sample) -> None:
        """One sample; chip errors and non-finite forces break the window."""
        fz = sample.force_N[2] if sample.force_N else math.nan
        if sample.chip_error or not math.isfinite(fz):
            self._window = []
            return
        if self.noise_mN is None:
            self.noise_mN = max(self.noise_uT * slope_mN_per_uT(self.calibration, sample.B_uT, sample.temperature_C),
                                1e-6)
        self._window.append((sample.time_s, 1000.0 * fz, sample.temperature_C))
        if len(self._window) >= self.size:
            self._close(self._window)
            self._window = []

    def _close(self, window) -> None:
        noise_mN = self.noise_mN
        assert noise_mN is not None, "add() sets the noise before it closes a window"
        forces = [f for _, f, _ in window]
        mean = sum(forces) / len(forces)
        spread = math.sqrt(sum((f - mean) ** 2 for f in forces) / (len(forces) - 1))
        if spread > QUIET_SIGMAS * noise_mN:
            return
        if self.level is not None and abs(mean - self.level) > CAPTURE_SIGMAS * noise_mN:
            return
        temps = [t for _, _, t in window]
        temperature = sum(temps) / len(temps) if all(t is not None for t in temps) else None
        self.level = mean
        self.points.append(((window[0][0] + window[-1][0]) / 2.0, mean, temperature))

    def per_C(self) -> Optional[Tuple[float, float]]:
        """(least-squares slope of the rest level over the temperature in mN/C, the temperature span in C), or
        None without temperatures or with a span under :data:`MIN_SPAN_C`."""
        pairs = [(t, f) for _, f, t in self.points if t is not None]
        if len(pairs) < 2:
            return None
        ts = [t for t, _ in pairs]
        span = max(ts) - min(ts)
        if span < MIN_SPAN_C:
            return None
        mt, mf = sum(ts) / len(ts), sum(f for _, f in pairs) / len(pairs)
        slope = sum((t - mt) * (f - mf) for t, f in pairs) / sum((t - mt) ** 2 for t in ts)
        return slope, span

    def summary(self) -> str:
        """One line: the rest level's drift, or why there is none."""
        if len(self.points) < 2:
            return "rest level: {} window{} of {:g} s at rest - too few to see a drift".format(
                len(self.points), "" if len(self.points) == 1 else "s", WINDOW_S)
        (t0, f0, c0), (t1, f1, c1) = self.points[0], self.points[-1]
        text = (f"rest level: {len(self.points)} windows at rest over {t1 - t0:.1f} s, Fz {f0:+.1f} -> {f1:+.1f} mN "
                f"(drift {f1 - f0:+.1f} mN")
        if c0 is not None and c1 is not None:
            text += f", chip {c0:.1f} -> {c1:.1f} C"
        fit = self.per_C()
        if fit is not None:
            text += "; {:+.2f} mN/C over {:.1f} C".format(*fit)
        return text + f"; force noise {self.noise_mN:.2f} mN)"
