"""A recording of the sensor's own forces is never calibrated on (guard A by the column names,
guard B by the numbers), a scan past the predicted range is flagged (guard C), and a recording merged with a
reference sensor's log on the host clock makes the scan (docs/bundle.md section 1). The recording is made by the
build's own readout package, Ctrl-C included."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest

from magfab.formats.scan_csv import (
    FORCE_COLUMNS,
    SENSOR_FORCE_COLUMNS,
    ScanError,
    read_recording,
    read_scan_csv,
)
from magfab.models import scan_guards as G
from magfab.models.calibration import Calibration

#: The build's readout CLI with a simulated board that sends samples as fast as they are read (not paced by
#: the wall clock), so a few presses of its pattern take a second.
DRIVER = """
import sys
import magfab_readout.cli as cli

class Fast(cli.SimulatedDevice):
    def __init__(self, *args, **kwargs):
        kwargs["realtime"] = False
        super().__init__(*args, **kwargs)

cli.SimulatedDevice = Fast
sys.exit(cli.main(sys.argv[1:]))
"""
ROWS = 3300  # 6 s of device time: two presses of the simulated pattern (1 s rest, 1.5 s press), so a 2-D scan


@pytest.fixture(scope="module")
def build_dir(default_build):
    return default_build.out_dir


@pytest.fixture(scope="module")
def calibration(build_dir):
    return Calibration.from_json(json.loads((build_dir / "calibration" / "calibration.json").read_text()))


@pytest.fixture(scope="module")
def simulated(build_dir):
    return read_scan_csv(build_dir / "calibration" / "scan_simulated.csv")


@pytest.fixture(scope="module")
def recorded(build_dir, tmp_path_factory):
    """``magfab-readout record OUT.csv`` with no limit, ended by SIGINT once ROWS rows are in the file:
    (the completed process, the file, the wall-clock times before start and after the end)."""
    out = tmp_path_factory.mktemp("record") / "recording.csv"
    env = {**os.environ, "PYTHONPATH": str(build_dir / "readout" / "src")}
    before = time.time()
    proc = subprocess.Popen([sys.executable, "-c", DRIVER, "record", str(out), "--simulate"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and proc.poll() is None:
        if out.exists() and out.read_bytes().count(b"\n") > ROWS + 10:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=30)
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr), out, before, time.time()


def _rows(path):
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    return lines[0].split(","), [line.split(",") for line in lines[1:]]


def test_record_writes_the_sensors_own_forces_and_host_time_until_ctrl_c(recorded):
    proc, path, before, after = recorded
    assert proc.returncode == 0, proc.stderr
    header, rows = _rows(path)
    assert header == ["time_s", "host_time_s", "Bx_uT", "By_uT", "Bz_uT", "temperature_C", *SENSOR_FORCE_COLUMNS,
                      "status", "seq"]
    assert not set(FORCE_COLUMNS) & set(header)
    assert len(rows) > ROWS and f"wrote {len(rows)} rows to" in proc.stderr
    assert path.read_text().endswith("\n") and all(len(r) == len(header) for r in rows)  # the last row whole
    host = np.array([float(r[1]) for r in rows])
    assert before <= host[0] and host[-1] <= after and np.all(np.diff(host) >= 0)  # time.time() at each read
    comments = [line for line in path.read_text().splitlines() if line.startswith("#")]
    note = next(c for c in comments if c.startswith("# Fx_sensor_N"))
    assert "own calibrated force" in note and "--reference" in note and "Fx_N, Fy_N, Fz_N" in note


def test_guard_a_refuses_the_recording_by_its_column_names(recorded):
    _, path, _, _ = recorded
    with pytest.raises(ScanError) as info:
        read_scan_csv(path)
    message = str(info.value)
    assert "\n" not in message and path.name in message
    for part in ("Fx_sensor_N", "own calibrated forces", "--reference"):
        assert part in message, message
    # the sensor's forces copied into the reference's columns beside them are refused too
    header, rows = _rows(path)
    text = ",".join(header + list(FORCE_COLUMNS)) + "\n" + "".join(",".join(r + r[6:9]) + "\n" for r in rows)
    with pytest.raises(ScanError, match="repeat Fx_sensor_N"):
        read_scan_csv(text.encode())


def _renamed(path) -> bytes:
    """The recording with its sensor columns renamed to the reference's: what guard A cannot see."""
    text = path.read_text()
    for own, ref in zip(SENSOR_FORCE_COLUMNS, FORCE_COLUMNS):
        text = text.replace(own, ref)
    return text.encode()


def test_guard_b_refuses_a_renamed_recording(recorded, calibration, default_build):
    resolution = default_build.design.spec.calibration.reference_resolution_mN
    scan = read_scan_csv(_renamed(recorded[1]))  # a 2-D scan under the reference's names: guard A passes it
    assert G.self_calibration_rms_N(scan, calibration) < 1e-5  # float32 on the board, 6 decimals in the file
    with pytest.raises(ScanError) as info:
        G.reject_self_calibrated(scan, calibration, resolution)
    assert "own calibrated forces" in str(info.value) and "--reference" in str(info.value)
    tared = replace(scan, F_N=scan.F_N - np.array([0.01, -0.02, 0.037]))  # a tare does not hide it
    with pytest.raises(ScanError):
        G.reject_self_calibrated(tared, calibration, resolution)


def test_guard_b_passes_genuine_scans(recorded, simulated, calibration, default_build):
    """The build's simulated scan (the reference's quantisation on the true force), and the recording's own forces
    read through a reference of the spec's resolution, are never refused: both sit at least the quantisation's
    RMS (resolution / sqrt 12) from the calibration, a hundred times the guard's limit."""
    resolution = default_build.design.spec.calibration.reference_resolution_mN
    limit = max(G.SELF_FRACTION * resolution / 1000.0, G.SELF_FLOOR_N)
    G.reject_self_calibrated(simulated, calibration, resolution)
    assert G.self_calibration_rms_N(simulated, calibration) > 10 * limit
    scan = read_scan_csv(_renamed(recorded[1]))
    step = resolution / 1000.0
    quantised = replace(scan, F_N=np.round(scan.F_N / step) * step)
    G.reject_self_calibrated(quantised, calibration, resolution)
    assert G.self_calibration_rms_N(quantised, calibration) > 0.1 * step / math.sqrt(12.0)


def test_guard_c_flags_a_scan_past_the_predicted_ranges(simulated, build_dir, pred):
    """By the field for the normal range (how far the magnet went, whatever the silicone or magnet), by the
    stiffest silicone's force for the shear range."""
    doc = json.loads((build_dir / "predictions.json").read_text())
    normal, shear = doc["normal"], doc["shear"]
    # the simulated scan runs to the nominal silicone's end of range: past the softest's range in force, but
    # its field says the magnet stayed within it
    assert simulated.F_N[:, 2].max() > normal["range_N"]
    assert G.scan_depth_warnings(simulated, doc) == [] == G.scan_depth_warnings(simulated, pred)
    # a stronger magnet reads more field everywhere: still within
    assert G.scan_depth_warnings(replace(simulated, B_uT=simulated.B_uT * 1.1), doc) == []
    # the deep rows' field 30 % higher: the magnet went further than the range's end
    B = simulated.B_uT.copy()
    deep = simulated.F_N[:, 2] > 0.8 * simulated.F_N[:, 2].max()
    B[deep, 2] *= 1.3
    (fz,) = G.scan_depth_warnings(replace(simulated, B_uT=B), doc)
    assert f"past the predicted normal range (ends at: {normal['range_limit']})" in fz and "\n" not in fz
    assert f"of {simulated.rows} rows" in fz and "keep the scan within the range" in fz
    # lateral force past the stiffest silicone's shear range
    stiff = max(shear["range_by_material_N"].values())
    F = simulated.F_N.copy()
    F[:, 1] *= 1.1 * stiff / simulated.Fr_N.max()
    (fr,) = G.scan_depth_warnings(replace(simulated, F_N=F), doc)
    assert f"shear range of even the stiff silicone, {stiff:.3g} N" in fr
    # no rest reading in the scan: the normal range by the stiffest silicone's force
    F = simulated.F_N.copy()
    F[:, 2] += 3.0 * max(normal["range_by_material_N"].values())
    assert any("beyond the predicted normal range of even the stiff" in w for w in G.scan_depth_warnings(
        replace(simulated, F_N=F), doc))


# ---- merging a reference sensor's log ------------------------------------------------------------------------

T0 = 1.7e9  # a host clock reading (Unix time, s)


def _true_force(t: np.ndarray) -> np.ndarray:
    """A smooth reference force against host time, N (N, 3)."""
    return np.column_stack([0.05 * np.sin(t), 0.2 * np.cos(0.7 * t), 0.6 + 0.4 * np.sin(1.3 * t)])


def _recording(scan, batch: int = 64, drift: float = 1.0002):
    """``scan``'s field and device time as a recording: the host reads the samples in batches of ``batch`` (each
    read when its batch's last sample arrived, plus 1 ms), its clock ``drift`` times the device's; returns the CSV
    bytes and each sample's true host time."""
    true = T0 + drift * scan.time_s
    k = np.arange(scan.rows)
    last = np.minimum((k // batch + 1) * batch - 1, scan.rows - 1)
    read = true[last] + 1e-3
    rows = ["time_s,host_time_s,Bx_uT,By_uT,Bz_uT,Fx_sensor_N,Fy_sensor_N,Fz_sensor_N"]
    rows += [f"{t!r},{h:.6f},{b[0]!r},{b[1]!r},{b[2]!r},0,0,0"
             for t, h, b in zip(scan.time_s.tolist(), read.tolist(), scan.B_uT.tolist())]
    return ("\n".join(rows) + "\n").encode(), true


def _reference(t: np.ndarray) -> bytes:
    rows = ["time_s,Fx_N,Fy_N,Fz_N,extra"] + [f"{x:.6f},{f[0]!r},{f[1]!r},{f[2]!r},1"
                                              for x, f in zip(t.tolist(), _true_force(t).tolist())]
    return ("\n".join(rows) + "\n").encode()


def test_merge_interpolates_the_reference_at_each_sample_on_the_host_clock(simulated):
    rec, true = _recording(simulated)
    ref_t = np.arange(true[0] - 0.5, true[-1] + 0.5, 1e-3)  # a 1 kHz reference through the whole scan
    merged = G.merge_reference(rec, _reference(ref_t))
    assert merged.rows == simulated.rows and np.array_equal(merged.B_uT, simulated.B_uT)
    # the batches' read delay (up to 64 samples, 0.12 s) is undone: the force at each sample's true time
    assert np.max(np.abs(merged.F_N - _true_force(true))) < 1e-3  # the 1 ms floor of the delay
    naive = _true_force(read_recording(rec).host_time_s)
    assert np.max(np.abs(naive - _true_force(true))) > 1e-2  # what reading times alone would have given
    assert merged.source == "scan + scan" and len(merged.sha256) == 64
    back = read_scan_csv(G.merged_csv(merged))
    assert np.array_equal(back.F_N, merged.F_N) and np.array_equal(back.time_s, merged.time_s)


def test_merge_drops_the_rows_outside_the_reference(simulated):
    rec, true = _recording(simulated)
    cut = true[0] + 0.2 * (true[-1] - true[0])
    merged = G.merge_reference(rec, _reference(np.arange(cut, true[-1] + 0.5, 1e-3)))
    h = G.host_clock(read_recording(rec))
    assert merged.rows == int(np.count_nonzero(h >= cut)) < simulated.rows
    assert np.array_equal(merged.time_s, simulated.time_s[h >= cut])


@pytest.mark.parametrize("case, words", [
    ("an hour later", ["do not overlap", "the same computer's clock"]),
    ("relative clock", ["do not overlap", "0.000 to"]),
    ("a third", ["only", "of the {rows} rows", "at least 50 %"]),
    ("a gap", ["a gap of 0.3", "line", "every 18.4 ms"]),
])
def test_merge_refuses_what_cannot_be_merged(simulated, case, words):
    rec, true = _recording(simulated)
    t = np.arange(true[0] - 0.5, true[-1] + 0.5, 1e-3)
    t = {"an hour later": t + 3600.0, "relative clock": t - t[0],
         "a third": t[t < true[0] + (true[-1] - true[0]) / 3.0],
         "a gap": t[(t < true[0] + 1.0) | (t > true[0] + 1.3)]}[case]
    with pytest.raises(ScanError) as info:
        G.merge_reference(rec, _reference(t))
    message = str(info.value)
    assert "\n" not in message
    for w in words:
        assert w.format(rows=simulated.rows) in message, (w, message)


def test_a_recording_merged_with_its_own_forces_is_refused_by_the_merge(recorded, default_build):
    """The real recording and a reference log on its host clock made of the sensor's own forces, as they are or
    rounded to the spec's reference resolution: the merge refuses both as copies of the recording (guard B, which
    sees only the merged numbers, passes the rounded one: tests/models/test_reference_guards.py has the rest)."""
    resolution = default_build.design.spec.calibration.reference_resolution_mN
    recording = read_recording(recorded[1])
    h = G.host_clock(recording)
    own = recording.scan.F_N
    step = resolution / 1000.0
    for forces in (np.round(own / step) * step, own):
        rows = ["time_s,Fx_N,Fy_N,Fz_N"] + [f"{t!r},{f[0]!r},{f[1]!r},{f[2]!r}"
                                             for t, f in zip(h.tolist(), forces.tolist())]
        with pytest.raises(ScanError, match=r"copy of .* own forces"):
            G.merge_reference(recording, ("\n".join(rows) + "\n").encode(), resolution)
