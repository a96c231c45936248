"""The device's clock mapped onto this computer's: the one implementation, for ``record``'s Parquet and MCAP files
and for magfab's merge of a reference log (``magfab.models.scan_guards.host_clock``).

Each recorded sample has the device's time (``time_s``, spaced exactly by the board's clock) and the host's time
when it was read (``host_time_s``, late by the serial link's buffering: a batch of samples read at once, up to tens
of ms). The map is the line under every (time_s, host_time_s) pair that hugs them closest, the least total gap: the
edge of their lower convex hull over the mean time_s, as in network clock-skew estimation. Its slope takes the two
clocks' rate difference (a ceramic resonator's 0.5 %) and it passes through the least-delayed reads.

Standard library only (the readout runs on Python 3.8 with pyserial alone).
"""

from __future__ import annotations

import bisect
from array import array
from typing import List, Sequence, Tuple

__all__ = ["clock_map", "lower_hull"]


def clock_map(time_s: Sequence[float], host_s: Sequence[float]) -> Tuple[float, float, float]:
    """(t0, h0, slope): a sample at device time t was on the host clock at ``h0 + slope * (t - t0)``. A recording
    of fewer than two samples, or whose device time does not advance, maps by its first host time at slope 1 (t0 the
    first device time), which keeps a lone sample's own host time."""
    n = len(time_s)
    if n < 2 or not time_s[-1] - time_s[0] > 0.0:
        return (float(time_s[0]), float(host_s[0]), 1.0) if n else (0.0, 0.0, 1.0)
    t0, h0 = float(time_s[0]), float(host_s[0])
    # small numbers: Unix time's 1.7e9 would eat the cross products' precision; doubles, 8 bytes a sample
    x = array("d", (float(t) - t0 for t in time_s))
    y = array("d", (float(h) - h0 for h in host_s))
    hull = lower_hull(x, y)
    mean = sum(x) / n
    k = min(bisect.bisect_left([x[i] for i in hull], mean), len(hull) - 1)
    i, j = hull[max(k - 1, 0)], hull[max(k, 1)]
    slope = (y[j] - y[i]) / (x[j] - x[i])
    return t0 + x[i], h0 + y[i], slope


def lower_hull(x: Sequence[float], y: Sequence[float]) -> List[int]:
    """Indices of the lower convex hull of the points (x, y), x non-decreasing, from left to right (Andrew's
    monotone chain; of points with equal x only the lowest can be on it)."""
    hull: List[int] = []
    for k in range(len(x)):
        if hull and x[hull[-1]] == x[k]:
            if y[k] >= y[hull[-1]]:
                continue
            hull.pop()
        while len(hull) >= 2:
            i, j = hull[-2], hull[-1]
            if (x[j] - x[i]) * (y[k] - y[i]) - (y[j] - y[i]) * (x[k] - x[i]) > 0:
                break
            hull.pop()
        hull.append(k)
    return hull
