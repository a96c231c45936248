"""Guards on a calibration scan, and the merge that makes one from a recording and a reference sensor's log
(docs/bundle.md section 1).

The readout's ``record`` writes the sensor's own calibrated force (``Fx_sensor_N``...), which a calibration must
never take for the reference: fitted to them, it reports a held-out error near 0 and calibrates nothing.

- Guard A (the names) is in the reader, :func:`magfab.formats.scan_csv.read_scan_csv`.
- Guard B (the numbers), :func:`reject_self_calibrated`: force columns that reproduce a calibration's own
  output from the scan's field, far below the reference's resolution, are a recording whose columns were
  renamed. A genuine reference differs from any smooth fit by at least its quantisation (resolution / sqrt 12).
- Guard C (a flag), :func:`scan_depth_warnings`: a scan whose force goes past the predicted range.
- :func:`merge_reference`: the reference's force interpolated at each recorded sample's time on the host clock.

Units: force N, field uT, time s.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ScanError
from ..formats import bounded
from ..formats.scan_csv import (
    FORCE_COLUMNS,
    MIN_ROWS,
    SENSOR_FORCE_COLUMNS,
    Recording,
    Reference,
    Scan,
    check_calibration_scan,
    read_recording,
    read_reference,
    scan_csv,
)
from ..readout.src.magfab_readout.clock import clock_map
from ..spec import Calibration as CalibrationSpec
from .calibration import Calibration

if TYPE_CHECKING:
    import os

    from .calibration import Calibration
    from .predict import Prediction

__all__ = ["MERGED", "SELF_FRACTION", "SELF_FLOOR_N", "GAP_PERIODS", "MIN_OVERLAP", "self_calibration_rms_N",
           "reject_self_calibrated", "scan_depth_warnings", "host_clock", "merge_reference", "merged_csv",
           "sensor_noise_N", "agreement_floor_N", "copy_residual_N", "reject_copied_reference", "reject_dead_reference"]

#: Guard B refuses force columns within this fraction of the reference's resolution (RMS) of the calibration's
#: output: a genuine reference differs from any smooth fit by at least its quantisation, resolution / sqrt(12)
#: (29 % of it), while a recording matches to its last written decimal (1e-6 N) and float32 (about 1e-6 N).
SELF_FRACTION = 0.01
#: ... and never less than this, N (a spec may give a reference resolution of 0).
SELF_FLOOR_N = 1e-5
#: A reference log's gap longer than this many of the recording's sample periods is refused.
GAP_PERIODS = 10.0
#: What joins a merged scan's two sources in its name ("scan.csv + reference.csv").
MERGED = " + "
#: The least fraction of the recording's rows the reference's time span must cover.
MIN_OVERLAP = 0.5

#: What the points past each range limit (predict's labels) do.
_BEYOND = {
    "d_min": "bring the magnet closer to the chip than sensor.d_min_mm",
    "chip full scale": "drive the chip's output past its full scale, where readings clip",
    "stretch": "stretch the silicone past predict.max_stretch, your own limit for it",
    "material data": "stretch the silicone past the material law's data, where the model extrapolates",
    "scan depth": "lie deeper than the mechanics model was solved (calibration.scan_z_mm)",
    "model": "lie where the mechanics model stopped", "invertibility": "lie where two forces give one field",
    "lateral travel = magnet radius": "move the magnet sideways by more than its radius"}


# ---------------------------------------------------------------------------------------------------
# Guard B: force columns that are the calibration's own output


def self_calibration_rms_N(scan: Scan, calibration: Calibration) -> float:
    """RMS difference, N, over the rows and the three axes, between the scan's force columns and the global
    polynomial of ``calibration`` (what the firmware sends) evaluated at the scan's field and temperature, each axis's
    mean difference removed first (so a tare does not hide a copy). NaN when no row evaluates to a finite force."""
    if scan.F_N is None:
        raise ScanError(f"scan {scan.source}: no force columns to compare with the calibration")
    own, _ = calibration.evaluate(scan.B_uT, "poly", temperature_C=scan.temperature_C)  # as the board corrects
    d = scan.F_N - own
    d = d[np.isfinite(d).all(axis=1)]
    if not len(d):
        return math.nan
    d = d - d.mean(axis=0)
    return float(np.sqrt(np.mean(d * d)))


def reject_self_calibrated(scan: Scan, calibration: Calibration, reference_resolution_mN: float) -> None:
    """:class:`ScanError` (one line) when ``scan``'s force columns reproduce ``calibration``'s own output from its
    field (:func:`self_calibration_rms_N` at most ``SELF_FRACTION`` of ``reference_resolution_mN``, the spec's
    ``calibration.reference_resolution_mN``, or :data:`SELF_FLOOR_N`, whichever is larger): a
    recording of the sensor's own forces under the reference's column names. ``calibration`` is the one the
    sensor ran while recording (the build's calibration.json, as uploaded)."""
    limit_N = max(SELF_FRACTION * reference_resolution_mN / 1000.0, SELF_FLOOR_N)
    rms = self_calibration_rms_N(scan, calibration)
    if rms <= limit_N:
        raise ScanError(
            f"scan {scan.source}: its force columns are this sensor's own calibrated forces: they match the current "
            f"calibration evaluated at the scan's field to {rms * 1e6:.2g} uN RMS, far below the reference's "
            f"resolution ({reference_resolution_mN:g} mN, calibration.reference_resolution_mN), and a fit to them "
            "only gives the calibration back; log a reference force sensor during the scan and merge its log with "
            "--reference (docs/bundle.md section 1)")


# ---------------------------------------------------------------------------------------------------
# Guard C: a scan past the predicted range


def _as_json(prediction: Prediction | Mapping[str, object]) -> Mapping[str, Any]:
    """predictions.json's content (JSON values: read by key, their shape is the file format's)."""
    return prediction.as_json() if hasattr(prediction, "as_json") else prediction


def scan_depth_warnings(scan: Scan, prediction: Prediction | Mapping[str, object]) -> list[str]:
    """Warning lines (none when the scan stays in range) for a scan that went past the predicted ranges.
    ``prediction``: a :class:`~magfab.models.predict.Prediction` or predictions.json's dict.

    Normal: judged by the field, which says how far the magnet travelled whatever the silicone and the magnet
    (:func:`_travel`): past the range's end when |Bz| rose above its value at rest by more than it does at the
    end of the range. (Judged by force, a scan of a nominal silicone to its own range's end would pass the
    softest silicone's range, which ``normal.range_N`` quotes.) Without a rest reading in the scan, by force:
    past the stiffest silicone's range. Shear: by force, past the stiffest silicone's range."""
    if scan.F_N is None:
        return []
    doc = _as_json(prediction)
    out = []
    travel = _travel(scan, doc)
    normal, shear = doc["normal"], doc["shear"]
    if travel is not None:
        ratio, end, beyond = travel
        if beyond:
            out.append(f"scan goes past the predicted normal range (ends at: {normal['range_limit']}): |Bz| rises to "
                       f"{ratio:.3g} x its value at rest, beyond the {end:.3g} x at the range's end whatever the "
                       f"magnet and the silicone; the points beyond it ({beyond} of {scan.rows} rows) "
                       f"{_BEYOND.get(str(normal['range_limit']), 'lie outside the predicted range')}")
    else:
        out += _past_stiffest(scan.F_N[:, 2], "Fz", "normal", normal, scan.rows)
    out += _past_stiffest(scan.Fr_N, "Fr", "shear", shear, scan.rows)
    return [line + "; the fit uses them, but the design is not rated there: keep the scan within the range"
            for line in out]


def _past_stiffest(force: np.ndarray, axis: str, key: str, figures: Mapping[str, Any], rows: int) -> list[str]:
    """A line when ``force`` passes the range of even the stiffest silicone of the band."""
    ranges = {str(k): float(v) for k, v in figures.get("range_by_material_N", {}).items()} or \
        {"predicted": float(figures["range_N"])}
    name, limit_N = max(ranges.items(), key=lambda kv: kv[1])
    beyond = int(np.count_nonzero(force > limit_N))
    if not beyond:
        return []
    ends = str(figures["range_limit"])
    return [f"scan reaches {axis} {float(force.max()):.3g} N, beyond the predicted {key} range of even the "
            f"{name} silicone, {limit_N:.3g} N (ends at: {ends}): the points beyond it ({beyond} of {rows} rows) "
            + _BEYOND.get(ends, "lie outside the predicted range")]


def _travel(scan: Scan, doc: Mapping[str, Any]) -> tuple[float, float, int] | None:
    """(|Bz| at its highest over |Bz| at rest in the scan, the same ratio at the end of the normal range, rows
    past it), or None without a rest reading (rows with no force) or the prediction's field at the range's end.
    The ratio does not depend on the magnet's strength (the field scales with its remanence) nor on the
    silicone (the travel at the range's end is the same for every modulus of a neo-Hookean band)."""
    field = doc.get("field", {})
    end_G, rest_G = field.get("Bz_range_end_strongest_G"), field.get("Bz_rest_G")
    remanence = field.get("remanence_T", {})
    if end_G is None or not rest_G or not remanence.get("nominal") or scan.F_N is None:
        return None
    end = float(end_G) / (float(rest_G) * float(remanence["high"]) / float(remanence["nominal"]))
    quiet = (np.abs(scan.F_N[:, 2]) <= 0.02 * max(float(np.max(np.abs(scan.F_N[:, 2]))), 1e-9)) & \
        (scan.Fr_N <= 0.02 * max(float(np.max(scan.Fr_N)), 1e-9))
    if not np.any(quiet):
        return None
    rest = float(np.median(scan.B_uT[quiet, 2]))
    if abs(rest) < 1.0:
        return None
    ratios = scan.B_uT[:, 2] / rest
    return float(ratios.max()), end, int(np.count_nonzero(ratios > end))


# ---------------------------------------------------------------------------------------------------
# Merging a reference sensor's log


def host_clock(recording: Recording) -> np.ndarray:
    """The host-clock time (Unix time, s) of each recorded sample, (N,): the device's time_s mapped onto the host
    clock by the readout's :func:`~magfab.readout.src.magfab_readout.clock.clock_map` (the line under every
    (time_s, host_time_s) pair that hugs them closest: the edge of their lower convex hull over the mean time_s).
    A recording whose device time does not advance keeps host_time_s."""
    t, h = recording.scan.time_s, recording.host_time_s
    if len(t) < 2 or not float(t[-1] - t[0]) > 0.0:
        return h.copy()
    t0, h0, slope = clock_map(t.tolist(), h.tolist())
    return h0 + slope * (t - t0)


def _period(recording: Recording) -> float:
    """The recording's sample period, s: the median step of the device's time (of host_time_s if it has none)."""
    for t in (recording.scan.time_s, recording.host_time_s):
        steps = np.diff(t)
        steps = steps[steps > 0]
        if steps.size:
            return float(np.median(steps))
    return 0.0


def _check_host_time(recording: Recording) -> None:
    back = np.flatnonzero(np.diff(recording.host_time_s) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise ScanError(f"{recording.scan.source}: line {int(recording.lines[k])}, column 'host_time_s': "
                        f"{float(recording.host_time_s[k])!r} is less than on the row before; host_time_s must be "
                        "non-decreasing (was the computer's clock set back during the recording?)")


def _overlap(h: np.ndarray, rec: Recording, ref: Reference) -> np.ndarray:
    """The recorded rows inside the reference's time span, (N,) bool; ScanError unless at least
    :data:`MIN_OVERLAP` of them are."""
    t0, t1 = float(ref.time_s[0]), float(ref.time_s[-1])
    inside = (h >= t0) & (h <= t1)
    spans = (f"the reference's time_s runs {t0:.3f} to {t1:.3f} s, the recording's host time "
             f"{float(h[0]):.3f} to {float(h[-1]):.3f} s")
    if not inside.any():
        raise ScanError(f"{ref.source} and {rec.scan.source} do not overlap in time: {spans}; both must be the "
                        "same computer's clock (Unix time, s), logged during the same scan")
    if inside.sum() < MIN_OVERLAP * len(h):
        raise ScanError(f"only {int(inside.sum())} of the {len(h)} rows of {rec.scan.source} "
                        f"({100.0 * inside.sum() / len(h):.0f} %) fall within the time span of {ref.source} "
                        f"({spans}); at least {100 * MIN_OVERLAP:.0f} % must: log the reference through the whole scan")
    return inside


def _check_gaps(h: np.ndarray, ref: Reference, period_s: float) -> None:
    """ScanError for a step of the reference's time longer than :data:`GAP_PERIODS` recording periods with
    recorded samples inside it (where its force would be interpolated across the gap)."""
    limit = GAP_PERIODS * period_s
    steps = np.diff(ref.time_s)
    for k in np.flatnonzero(steps > limit):
        a, b = float(ref.time_s[k]), float(ref.time_s[k + 1])
        within = int(np.searchsorted(h, b, "left") - np.searchsorted(h, a, "right"))
        if within:
            raise ScanError(f"{ref.source}: line {int(ref.lines[k + 1])}: a gap of {b - a:.3g} s in time_s after "
                            f"line {int(ref.lines[k])}, over {within} recorded samples; the reference must be logged "
                            f"at least every {1000.0 * limit:.3g} ms through the scan ({GAP_PERIODS:g} of the "
                            f"recording's sample periods of {1000.0 * period_s:.3g} ms) to be interpolated at "
                            "each sample")


# ---------------------------------------------------------------------------------------------------
# Guards on the merged reference: a copy of the recording's own forces, a dead reference

#: A reference is refused as a copy of the sensor's own forces when, at the lag and cubic map (per axis) that
#: bring them closest, they differ by less than this fraction of what two independent sensors differ by at
#: least (:func:`agreement_floor_N`).
COPY_FRACTION = 0.5
#: A rounded reference is refused as a copy, too, when the sensor's force through the map that puts the most of it
#: inside the reference's rounding intervals lies outside them by less than this fraction (RMS) of what the
#: sensor's own noise alone would carry outside them (:func:`copy_residual_N`): a copy lies outside by its added
#: noise only, 0.001-0.08 of it with noise up to 0.05 mN; an independent reference of 1-10 mN, 1.1-14 times it.
INTERVAL_FRACTION = 0.3
#: The share of a reference's quantisation variance (resolution^2 / 12) that stays between it and the sensor's
#: forces rounded as it is (:func:`agreement_floor_N`).
QUANTISATION_SHARE = 0.25
#: The share of white noise's variance that linear interpolation between its samples keeps.
INTERPOLATED_SHARE = 2.0 / 3.0
#: A reference whose force spans at most this many of its resolutions on every axis over the scan is dead.
DEAD_RESOLUTIONS = 4.0
#: An axis the sensor's own forces move on by this many reference resolutions (and at least
#: :data:`LIVE_FLOOR_N`) must move in the reference too.
LIVE_RESOLUTIONS, LIVE_FLOOR_N = 20.0, 0.05
#: The file's last decimal (1e-6 N) and the floor of every force threshold, N.
FORCE_FLOOR_N = 1e-5
#: The lag is refined around the cross-correlation's in this many passes of this many steps, each a tenth as
#: wide as the last (from +-2 sample periods to 2e-4 of one: a copy matches only at its own lag, to its noise).
_ZOOMS, _FINE_STEPS = 4, 21


def sensor_noise_N(own_N: np.ndarray) -> np.ndarray:
    """The sensor's own force noise per axis, N (3,): from the second differences of its forces, which a smooth
    press leaves near zero while white noise gives them 6 sigma^2 (the chip's noise through the calibration)."""
    if len(own_N) < 3:
        return np.zeros(own_N.shape[1])
    d2 = np.diff(own_N, 2, axis=0)
    return np.sqrt(np.mean(d2 * d2, axis=0) / 6.0)


def agreement_floor_N(noise_N: np.ndarray, reference_resolution_mN: float) -> float:
    """The least RMS difference (N, over the axes of ``noise_N``) that a reference which measured the force
    itself keeps from the sensor's forces interpolated at its times, even after the best lag and cubic map and
    after rounding them as the reference is rounded: the two sensors' errors are independent, so their
    variances add. The sensor's white noise (``noise_N`` per axis), linearly interpolated between its samples,
    keeps 2/3 of its variance, and neither a calibration error of the sensor nor a perfect reference takes the
    difference below it. A reference of the stated resolution q adds its quantisation: q^2 / 12 while the force
    moves, and compared with the sensor's force rounded to the same steps, a step wherever the two sensors'
    difference crosses one; :data:`QUANTISATION_SHARE` of q^2 / 12 is what that leaves in the simulated bench
    with the sensor's noise well under q (a MagOne: 0.2-0.6 mN against 6.25 mN: 0.6-1.1 mN RMS)."""
    q = reference_resolution_mN / 1000.0
    return float(np.sqrt(INTERPOLATED_SHARE * np.mean(noise_N ** 2) + QUANTISATION_SHARE * q * q / 12.0))


def _grid(values: np.ndarray) -> tuple[float, float] | None:
    """(step, origin), N, when every value lies on a grid origin + k step of a step above FORCE_FLOOR_N (a
    rounded log), else None."""
    u = np.unique(np.round(values, 7))
    steps = np.diff(u)
    if not len(steps):
        return None
    q = float(steps.min())
    if q <= FORCE_FLOOR_N:
        return None
    q = float(np.median(steps[steps < 1.5 * q]))  # the step as the file's decimals (1e-6 N) let it be read
    k = np.round((u - u[0]) / q)
    if k[-1] > 0:
        q = float(np.dot(k, u - u[0]) / np.dot(k, k))  # the step fitted over the whole span
    if np.max(np.abs(u - u[0] - k * q)) > 2e-6:
        return None
    return q, float(u[0])


def _cubic(x: np.ndarray, y: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
    """The least-squares cubic of y in x (scaled), evaluated at x; rows weighted by ``weight``."""
    s = (x - x.mean()) / (x.std() or 1.0)
    A = np.column_stack([np.ones_like(s), s, s * s, s * s * s])
    w = np.ones_like(s) if weight is None else np.sqrt(weight)
    coef, *_ = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)
    return A @ coef


def _axis_residual(ref: np.ndarray, own: np.ndarray, grid: tuple[float, float] | None) -> float:
    """RMS of the reference less the best cubic map of the sensor's force, N; for a rounded reference the lesser
    of that and the same with the map rounded as the reference is."""
    fit = _cubic(own, ref)
    r = float(np.sqrt(np.mean((ref - fit) ** 2)))
    if grid is not None:
        q, origin = grid
        # each rounded level weighs the same: the rows resting on one level share one rounding error, which
        # would pull the map's gain and offset off by a fraction of a step
        _, level, count = np.unique(np.round((ref - origin) / q), return_inverse=True, return_counts=True)
        fit = _cubic(own, ref, 1.0 / count[level])
        # the least-squares offset is off by up to half a step where the force rests on one step (the rounding's
        # error there is a constant): the map's offset is searched over a step
        for shift in q * np.linspace(-0.5, 0.5, 21):
            rounded = origin + q * np.round((fit + shift - origin) / q)
            r = min(r, float(np.sqrt(np.mean((ref - rounded) ** 2))))
    return r


def _outside_expected(ref: np.ndarray, mapped: np.ndarray, q: float, sigma: float) -> np.ndarray:
    """Per row, the mean square distance (N^2) by which white noise of ``sigma`` would carry a force from inside
    its rounding interval (ref +- q / 2, at the point of it nearest ``mapped``) outside it: sigma^2 (g(a) + g(b)),
    a and b the distances to its two ends in sigma, g(a) = E[(Z - a)+^2] = (1 + a^2) Phi(-a) - a phi(a)."""
    from scipy.special import ndtr  # lazy: as in _interval_residual
    if sigma <= 0.0:
        return np.zeros_like(ref)
    c = np.clip(mapped, ref - q / 2.0, ref + q / 2.0)
    total = np.zeros_like(ref)
    for a in ((ref + q / 2.0 - c) / sigma, (c - ref + q / 2.0) / sigma):
        total += (1.0 + a * a) * ndtr(-a) - a * np.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi)
    return sigma * sigma * total


def _interval_residual(ref: np.ndarray, own: np.ndarray, grid: tuple[float, float],
                       sigma: float) -> tuple[float, float, float]:
    """For a rounded reference, the sensor's force through the cubic map that puts the most of it inside the
    reference's rounding intervals (ref +- step / 2; the least total distance outside them, a linear programme):
    (RMS of the reference less that map rounded as the reference is, N; the mean square distance outside the
    intervals and what the sensor's interpolated noise ``sigma`` alone would leave, :func:`_outside_expected`,
    N^2). A rounded copy has a map with nothing outside but its added noise, which a least-squares fit to the
    levels misses by a fraction of a step (the rows on one level pull it as much as those that cross to the next);
    where the force rests at a step's edge, noise added before the rounding flips whole steps: only the distance
    outside stays small."""
    from scipy import sparse  # lazy: scipy is slow to import and only the merge's guard needs it
    from scipy.optimize import linprog  # lazy: as above

    q, origin = grid
    s = (own - own.mean()) / (own.std() or 1.0)
    A = sparse.csr_matrix(np.column_stack([np.ones_like(s), s, s * s, s * s * s]))
    n = len(s)
    out = -sparse.identity(n, format="csr")  # the distance outside the interval, one per row
    result = linprog(np.concatenate([np.zeros(4), np.ones(n)]),
                     A_ub=sparse.vstack([sparse.hstack([A, out]), sparse.hstack([-A, out])]),
                     b_ub=np.concatenate([ref + q / 2.0, q / 2.0 - ref]),
                     bounds=[(None, None)] * 4 + [(0.0, None)] * n, method="highs")
    if result.status != 0:
        return math.inf, math.inf, 0.0
    mapped, outside = A @ result.x[:4], result.x[4:]
    rounded = origin + q * np.round((mapped - origin) / q)
    return (float(np.sqrt(np.mean((ref - rounded) ** 2))), float(np.mean(outside * outside)),
            float(np.mean(_outside_expected(ref, mapped, q, sigma))))


def _best_lag(t: np.ndarray, ref: np.ndarray, h: np.ndarray, own: np.ndarray, period_s: float) -> float:
    """The time shift, s, that best lines the sensor's force up with the reference's: the least mean square
    difference of the two (each scaled to unit variance) on a grid of the recording's period, over every shift
    that leaves half of them overlapping (the correlation by FFT, the overlaps' sums of squares by cumulative sums)."""
    grid = np.arange(max(t[0], h[0]), min(t[-1], h[-1]), period_s)
    n = len(grid)
    if n < 8:
        return 0.0
    a, b = np.interp(grid, t, ref), np.interp(grid, h, own)
    a, b = (a - a.mean()) / (a.std() or 1.0), (b - b.mean()) / (b.std() or 1.0)
    size = 1 << int(2 * n - 1).bit_length()
    c = np.fft.irfft(np.fft.rfft(a, size) * np.conj(np.fft.rfft(b, size)), size)  # c[k] = sum_i a[i + k] b[i]
    ca, cb = np.concatenate([[0.0], np.cumsum(a * a)]), np.concatenate([[0.0], np.cumsum(b * b)])
    lags = np.arange(-(n // 2), n // 2 + 1)
    m = n - np.abs(lags)
    sa = np.where(lags >= 0, ca[n] - ca[np.maximum(lags, 0)], ca[m])
    sb = np.where(lags >= 0, cb[m], cb[n] - cb[np.maximum(-lags, 0)])
    msd = (sa + sb - 2.0 * c[lags % size]) / m
    return float(lags[int(np.argmin(msd))] * period_s)


def copy_residual_N(h: np.ndarray, own: np.ndarray, ref_t: np.ndarray, ref_F: np.ndarray, axes: list[int],
                    period_s: float, noise_N: np.ndarray) -> tuple[np.ndarray, float, tuple[float, float]]:
    """(RMS difference per axis of ``axes``, N; the lag, s; over the axes the reference rounds, the RMS distance
    outside its rounding intervals and what the sensor's noise alone would leave, N) between the reference's
    force at its own times and the sensor's forces interpolated there linearly (as the merge interpolates),
    shifted by the lag and mapped by a cubic per axis (a gain, a tare, a mild bend), at the lag that brings them
    closest. ``noise_N`` is the sensor's noise per axis (:func:`sensor_noise_N`), which interpolation leaves 2/3
    of in variance (:func:`agreement_floor_N`)."""
    inside = (ref_t >= h[0]) & (ref_t <= h[-1])
    t, F = ref_t[inside], ref_F[inside]
    total = np.sum([own[:, k] / (own[:, k].std() or 1.0) for k in axes], axis=0)
    rtotal = np.sum([F[:, k] / (F[:, k].std() or 1.0) for k in axes], axis=0)
    coarse = _best_lag(t, rtotal, h, total, period_s)
    grids = [_grid(F[:, k]) for k in axes]
    best: tuple[np.ndarray, float] = (np.full(len(axes), math.inf), coarse)
    width = 2.0 * period_s
    for _ in range(_ZOOMS):  # each pass around the best so far, a tenth as wide
        for lag in best[1] + width * np.linspace(-1.0, 1.0, _FINE_STEPS):
            ok = (t - lag >= h[0]) & (t - lag <= h[-1])
            if ok.sum() < MIN_ROWS:
                continue
            r = np.array([_axis_residual(F[ok, k], np.interp(t[ok] - lag, h, own[:, k]), g)
                          for k, g in zip(axes, grids)])
            if np.sum(r * r) < np.sum(best[0] ** 2):
                best = (r, float(lag))
        width /= 10.0
    r, lag = best
    ok = (t - lag >= h[0]) & (t - lag <= h[-1])
    outside, expected = 0.0, 0.0
    if ok.sum() >= MIN_ROWS:  # at the best lag, a rounded reference's map as its rounding intervals give it
        r = r.copy()
        for i, (k, g) in enumerate(zip(axes, grids)):
            if g is not None:
                ri, out, exp = _interval_residual(F[ok, k], np.interp(t[ok] - lag, h, own[:, k]), g,
                                                  math.sqrt(INTERPOLATED_SHARE) * float(noise_N[k]))
                r[i], outside, expected = min(r[i], ri), outside + out, expected + exp
    return r, lag, (math.sqrt(outside), math.sqrt(expected))


def reject_copied_reference(recording: Recording, reference: Reference, reference_resolution_mN: float) -> None:
    """ScanError (one line) when the reference's force is the recording's own (``Fx_sensor_N``...) resampled,
    shifted in time, scaled, tared, bent or rounded: closer to it, at the best lag and cubic map per axis
    (:func:`copy_residual_N`), than :data:`COPY_FRACTION` of :func:`agreement_floor_N` (RMS over the axes the
    sensor's force moves on; the sensor's noise measured from its own forces, :func:`sensor_noise_N`), or, for a
    rounded reference, inside its rounding steps but for :data:`INTERVAL_FRACTION` of the sensor's noise. Skipped
    without the sensor's forces or when they do not move."""
    own = recording.scan.F_N
    if own is None or not np.isfinite(own).all():
        return
    h = host_clock(recording)
    noise = sensor_noise_N(own)
    q = reference_resolution_mN / 1000.0
    axes = [k for k in range(3) if np.ptp(own[:, k]) > max(DEAD_RESOLUTIONS * q, 20.0 * noise[k], FORCE_FLOOR_N)]
    if not axes:
        return
    r, lag, (outside, expected) = copy_residual_N(h, own, reference.time_s, reference.F_N, axes,
                                                  _period(recording), noise)
    floor = agreement_floor_N(noise[axes], reference_resolution_mN)
    rms, limit = float(np.sqrt(np.mean(r * r))), max(COPY_FRACTION * floor, FORCE_FLOOR_N)
    names = ", ".join(FORCE_COLUMNS[k] for k in axes)
    head = (f"{reference.source} is a copy of {recording.scan.source}'s own forces, not a reference sensor's: its "
            f"{names} follow the recording's {', '.join(SENSOR_FORCE_COLUMNS[k] for k in axes)} (shifted "
            f"{1000.0 * lag:.3g} ms, through a gain, a tare and a rounding)")
    resolution = f"{reference_resolution_mN:g} mN, calibration.reference_resolution_mN"
    tail = "; log a reference force sensor during the scan (docs/bundle.md section 1)"
    if rms < limit:
        raise ScanError(f"{head} to {1000.0 * rms:.2g} mN RMS, under the {1000.0 * limit:.2g} mN that two "
                        "independent sensors differ by at least (this sensor's noise and the reference's resolution, "
                        f"{resolution}){tail}")
    if expected > 0.0 and outside < INTERVAL_FRACTION * expected:
        raise ScanError(f"{head}: it lies outside the reference's rounding steps ({resolution}) by "
                        f"{1000.0 * outside:.2g} mN RMS, under {INTERVAL_FRACTION:g} x the {1000.0 * expected:.2g} mN "
                        f"that this sensor's own noise alone puts outside them{tail}")


def reject_dead_reference(recording: Recording, reference: Reference, inside: np.ndarray,
                          reference_resolution_mN: float) -> None:
    """ScanError (one line) for a reference whose force over the scan never moves by more than
    :data:`DEAD_RESOLUTIONS` of its resolution on any axis (a dead, unplugged or constant log), or that stays
    that still on an axis where the sensor's own force moves by :data:`LIVE_RESOLUTIONS` of them."""
    h = host_clock(recording)
    span = (float(h[inside][0]), float(h[inside][-1]))
    during = (reference.time_s >= span[0]) & (reference.time_s <= span[1])
    F = reference.F_N[during] if during.sum() >= 2 else reference.F_N
    q = reference_resolution_mN / 1000.0
    still = max(DEAD_RESOLUTIONS * q, FORCE_FLOOR_N)
    ptp = np.ptp(F, axis=0)
    where = f"{reference.source}: its force "
    if np.all(ptp <= still):
        levels = ", ".join(f"{c} {float(np.median(F[:, k])):.4g} N" for k, c in enumerate(FORCE_COLUMNS))
        raise ScanError(
            f"{where}never moves during the scan: it stays within {1000.0 * float(ptp.max()):.3g} mN of "
            f"({levels}), under {DEAD_RESOLUTIONS:g} x its resolution ({reference_resolution_mN:g} mN, "
            "calibration.reference_resolution_mN); a dead, unplugged or constant reference calibrates nothing: "
            "check its cable and that it logs the force (docs/bundle.md section 1)")
    own = recording.scan.F_N
    if own is None or not np.isfinite(own).all():
        return
    moving = np.ptp(own[inside], axis=0)
    for k in range(3):
        if ptp[k] <= still and moving[k] > max(LIVE_RESOLUTIONS * q, LIVE_FLOOR_N):
            raise ScanError(
                f"{where}{FORCE_COLUMNS[k]} never moves during the scan (within {1000.0 * float(ptp[k]):.3g} mN "
                f"of {float(np.median(F[:, k])):.4g} N) while the sensor's own {SENSOR_FORCE_COLUMNS[k]} moves by "
                f"{1000.0 * float(moving[k]):.3g} mN: that channel of the reference is dead or unplugged "
                "(docs/bundle.md section 1)")


def merge_reference(recording: Recording | str | os.PathLike[str] | bytes,
                    reference: Reference | str | os.PathLike[str] | bytes,
                    reference_resolution_mN: float | None = None) -> Scan:
    """A calibration scan (force columns ``Fx_N``...) from a ``magfab-readout record`` recording and a reference
    force sensor's log (each a parsed value or a path, CSV text or bytes; docs/bundle.md section 1): the
    reference's force interpolated linearly at each recorded sample's host-clock time (:func:`host_clock`),
    the recording's rows outside the reference's time span dropped. ScanError (one line) when the two do not
    overlap, when under :data:`MIN_OVERLAP` of the recording does, when the reference has a gap longer than
    :data:`GAP_PERIODS` sample periods of the recording over recorded samples, and for a merged scan a
    calibration cannot use (:func:`~magfab.formats.scan_csv.check_calibration_scan`, fewer than MIN_ROWS rows).
    ``source`` is "RECORDING + REFERENCE"; ``sha256`` that of :func:`~magfab.formats.scan_csv.scan_csv` of it."""
    rec = recording if isinstance(recording, Recording) else read_recording(recording)
    ref = reference if isinstance(reference, Reference) else read_reference(reference)
    _check_host_time(rec)
    h = host_clock(rec)
    inside = _overlap(h, rec, ref)
    _check_gaps(h, ref, _period(rec))
    if reference_resolution_mN is None:  # the spec's default
        reference_resolution_mN = float(CalibrationSpec.model_fields["reference_resolution_mN"].default)
    reject_dead_reference(rec, ref, inside, reference_resolution_mN)
    reject_copied_reference(rec, ref, reference_resolution_mN)
    force = np.column_stack([np.interp(h[inside], ref.time_s, ref.F_N[:, k]) for k in range(3)])
    s = rec.scan
    temperature = None if s.temperature_C is None else s.temperature_C[inside]
    merged = Scan(s.time_s[inside], s.B_uT[inside], force, temperature, f"{s.source}{MERGED}{ref.source}", "")
    merged = replace(merged, sha256=hashlib.sha256(scan_csv(merged).encode("utf-8")).hexdigest())
    if merged.rows < MIN_ROWS:
        raise ScanError(f"{merged.source}: {merged.rows} rows overlap in time; a calibration needs at least {MIN_ROWS}")
    check_calibration_scan(merged)
    return merged


def merged_csv(scan: Scan) -> bytes:
    """The merged scan as scan CSV bytes (docs/bundle.md section 1), naming its sources in a comment."""
    return scan_csv(scan, [f"merged by magfab: {scan.source} (force: the reference, interpolated on the host "
                           "clock)"]).encode("utf-8")


def reject_self_calibrated_file(scan: Scan, path: str | os.PathLike[str], reference_resolution_mN: float) -> None:
    """Guard B against the calibration.json at ``path`` (a build's present one); skipped when that file has gone
    bad: the rebuild replaces it, and there is nothing to compare with."""

    try:  # bounded: a file nested past json's recursion limit has gone bad too (InputFileError is a ValueError)
        calibration = Calibration.from_json(bounded.loads_json(bounded.read_bytes(path, "calibration.json"),
                                                               "calibration.json", path))
    except ValueError:
        return
    reject_self_calibrated(scan, calibration, reference_resolution_mN)
