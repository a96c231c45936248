"""The merge refuses a reference log that is the recording's own forces in disguise (resampled, shifted in time,
scaled, tared, rounded, a little noise) and a dead or constant one, each in one line naming what it found, and
passes an independent reference of the spec's resolution (docs/bundle.md section 1, "The guards"). The
recording is a press pattern as the simulated board plays it: an accurate sensor (its forces the true force
plus its chip's noise, 0.2-0.6 mN), read by the host in batches."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from magfab.errors import ScanError
from magfab.formats.scan_csv import Recording, Reference, Scan
from magfab.models import scan_guards as G

T0, PERIOD_S, SECONDS = 1.7e9, 0.00184, 6.0
NOISE_N = np.array([0.17e-3, 0.14e-3, 0.6e-3])  # the simulated MagOne's force noise per axis
RESOLUTION_MN = 6.25  # the spec's default reference (ATI Nano17)
NO_SHRINK = [Phase.explicit, Phase.reuse, Phase.generate]  # a merge takes ~0.3 s: shrinking would take minutes


def true_force(t: np.ndarray) -> np.ndarray:
    """Presses of 1.5 s after 1 s at rest, each in another direction (N, 3), N."""
    period = 2.5
    k, tau = np.floor(t / period), np.mod(t, period)
    s = np.where(tau > 1.0, np.sin(np.pi * (tau - 1.0) / 1.5) ** 2, 0.0)
    angle = 2.39996 * k
    return np.column_stack([0.25 * s * np.cos(angle), 0.25 * s * np.sin(angle), (0.9 - 0.1 * (k % 3)) * s])


def recording(seed: int = 0) -> Recording:
    """The sensor's recording: device time, host time (read in batches of 64, 1 ms late), a field that follows the
    force, and its own forces (the true force plus its noise, 6 decimals as the readout writes them)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, SECONDS, PERIOD_S)
    F = true_force(t)
    own = np.round(F + rng.normal(0.0, 1.0, F.shape) * NOISE_N, 6)
    B = np.column_stack([300.0 * F[:, 0], 300.0 * F[:, 1], 18760.0 + 900.0 * F[:, 2] + 40.0 * F[:, 2] ** 2])
    last = np.minimum((np.arange(len(t)) // 64 + 1) * 64 - 1, len(t) - 1)
    host = T0 + 1.0002 * t[last] + 1e-3
    return Recording(Scan(t, B, own, None, "rec.csv", ""), host, np.arange(len(t)) + 2)


REC = recording()
H = G.host_clock(REC)


def at(times: np.ndarray, F: np.ndarray, lag_s: float = 0.0) -> np.ndarray:
    """``F`` on the recording's host clock, interpolated at ``times`` - ``lag_s``."""
    return np.column_stack([np.interp(times - lag_s, H, F[:, k]) for k in range(3)])


def reference(times: np.ndarray, F: np.ndarray) -> Reference:
    return Reference(times, np.round(F, 6), np.arange(len(times)) + 2, "ref.csv", "")


def rounded(F: np.ndarray, step_N: float) -> np.ndarray:
    return np.round(F / step_N) * step_N


def log_times(rate_Hz: float) -> np.ndarray:
    return np.arange(H[0] - 0.3, H[-1] + 0.3, 1.0 / rate_Hz)


def refused(ref: Reference, *words: str) -> str:
    with pytest.raises(ScanError) as info:
        G.merge_reference(REC, ref)
    message = str(info.value)
    assert "\n" not in message
    for w in words:
        assert w in message, (w, message)
    return message


# ---- the adversarial pass's examples ------------------------------------------------------------------------------

@pytest.mark.parametrize("case", ["resampled", "tared", "scaled by 1.01", "rounded to 1 mN"])
def test_the_recordings_own_forces_as_the_reference_are_refused(case):
    times = log_times(1000.0)
    own = at(times, REC.scan.F_N)
    F = {"resampled": own, "tared": own + np.array([0.012, -0.03, 0.25]), "scaled by 1.01": 1.01 * own,
         "rounded to 1 mN": rounded(own, 1e-3)}[case]
    refused(reference(times, F), "copy of rec.csv's own forces", "Fz_sensor_N", "mN RMS",
            "calibration.reference_resolution_mN")


def test_a_reference_that_logs_zero_throughout_is_refused():
    times = log_times(1000.0)
    refused(reference(times, np.zeros((len(times), 3))), "never moves during the scan", "Fz_N 0 N",
            "dead, unplugged or constant")


def test_a_dead_channel_is_refused():
    times = log_times(1000.0)
    F = at(times, true_force(REC.scan.time_s))
    F[:, 2] = 0.0
    refused(reference(times, F), "Fz_N never moves", "Fz_sensor_N moves by")


# ---- generators ---------------------------------------------------------------------------------------------------

#: How many cases a generator draws: a sample in the default run (each merge takes about half a second), many more
#: with -m slow.
EXAMPLES = [pytest.param(6, id="sampled"), pytest.param(60, id="exhaustive", marks=pytest.mark.slow)]


def _drawn(examples: int, **strategies):
    """``@given(**strategies)`` with ``examples`` cases, unshrunk (a failing case is reported as drawn)."""
    return lambda test: settings(max_examples=examples, deadline=None, phases=NO_SHRINK,
                                 suppress_health_check=[HealthCheck.too_slow])(given(**strategies)(test))


def _disguised_copy(rate, lag, gain, tare, step_mN, noise_mN, seed):
    rng = np.random.default_rng(seed)
    times = log_times(rate)
    F = gain * at(times, REC.scan.F_N, lag) + np.array(tare) + rng.normal(0.0, noise_mN / 1000.0, (len(times), 3))
    if step_mN:
        F = rounded(F, step_mN / 1000.0)
    refused(reference(times, F), "copy of rec.csv's own forces")


@pytest.mark.parametrize("examples", EXAMPLES)
def test_disguised_copies_of_the_sensors_forces_are_refused(examples):
    """The sensor's forces resampled at another rate and lag, through a gain and a tare, with a little noise (well
    under the sensor's own), rounded to 0.1 mN up to the stated resolution (6.25 mN) or not."""
    _drawn(examples, rate=st.floats(200.0, 2000.0), lag=st.floats(-0.5, 0.5), gain=st.floats(0.9, 1.1),
           tare=st.tuples(*[st.floats(-0.5, 0.5)] * 3),
           step_mN=st.one_of(st.just(0.0), st.floats(0.1, RESOLUTION_MN), st.just(RESOLUTION_MN)),
           noise_mN=st.floats(0.0, 0.05), seed=st.integers(0, 2**16))(_disguised_copy)()


@pytest.mark.parametrize("step_mN", [1.0, 3.0, RESOLUTION_MN])
def test_a_noisy_copy_resting_at_a_steps_edge_is_refused(step_mN):
    """The copy's rest level a hair from a rounding step's edge: its added noise (0.05 mN) flips whole steps there,
    about a mN RMS, which the rounding residual alone let through (CI, seed 1803); it still lies inside the steps
    but for its noise."""
    q = step_mN / 1000.0
    tare = (np.array([40.0, -17.0, 65.0]) + 0.5) * q + np.array([0.06e-3, -0.04e-3, 0.02e-3])
    _disguised_copy(799.0, 0.0039, 0.99999, tuple(tare), step_mN, 0.05, 1803)


def _independent(rate, offset, tare, resolution_mN, seed):
    rng = np.random.default_rng(seed)
    times = log_times(rate)
    q = resolution_mN / 1000.0
    F = at(times, true_force(REC.scan.time_s), offset) + np.array(tare)
    F = rounded(F + rng.normal(0.0, q / math.sqrt(12.0), F.shape), q)
    merged = G.merge_reference(REC, reference(times, F), resolution_mN)
    assert merged.rows > 0.5 * REC.scan.rows


@pytest.mark.parametrize("examples", EXAMPLES)
def test_independent_references_are_accepted(examples):
    """The true force as a reference of the stated resolution logs it (its noise, resolution / sqrt 12, and its
    quantisation), its clock off by up to 0.2 s, tared anywhere: the accurate sensor's forces agree with it to its
    noise and the reference's resolution, never closer."""
    _drawn(examples, rate=st.floats(200.0, 2000.0), offset=st.floats(-0.2, 0.2),
           tare=st.tuples(*[st.floats(-0.5, 0.5)] * 3), resolution_mN=st.floats(1.0, 10.0),
           seed=st.integers(0, 2**16))(_independent)()


@settings(max_examples=25, deadline=None, phases=NO_SHRINK)
@given(level=st.tuples(*[st.floats(-5.0, 5.0)] * 3), wobble_mN=st.floats(0.0, 10.0), seed=st.integers(0, 2**16))
def test_constant_references_are_refused(level, wobble_mN, seed):
    """A reference at any level that never leaves it by more than a few resolutions (noise up to 10 mN peak to
    peak against 4 x 6.25 mN)."""
    rng = np.random.default_rng(seed)
    times = log_times(1000.0)
    F = np.array(level) + rng.uniform(-0.5, 0.5, (len(times), 3)) * wobble_mN / 1000.0
    refused(reference(times, F), "never moves during the scan")
