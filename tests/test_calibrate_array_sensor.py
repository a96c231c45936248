"""``magfab calibrate REC --reference REF --sensor ID --taxel K`` on an array build, end to end:
the strip_1x5 example's record made by ``magfab sensor add``, each taxel calibrated in turn from a recording of the
whole array (its ``taxel`` column, as ``magfab-readout record`` writes it) merged with a reference log; each event
names its taxel, the build folder is left byte for byte, and the record ends with one current calibration per
taxel. The guards on the way: a taxel's rows whose field at rest is another taxel's (the wrong taxel named), a
missing --taxel, a taxel the array does not have."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from calibrate_support import tree
from click.testing import CliRunner

from magfab.cli import main
from magfab.formats import sensor_records as records
from magfab.formats.calibration_json import calibration_sha256
from magfab.formats.scan_csv import read_scan_csv

T0 = 1_764_000_000.0  # host clock of the recording's first row (Unix time, s)
COLUMNS = "time_s,host_time_s,taxel,Bx_uT,By_uT,Bz_uT,Fx_sensor_N,Fy_sensor_N,Fz_sensor_N,status,seq"


def recording(build, pressed: int) -> tuple[str, str]:
    """(recording CSV, reference log CSV): every taxel read each cycle while taxel ``pressed`` is scanned, its field
    from its simulated scan and every other taxel's from its own simulated scan (rows the fit must leave out); the
    reference sensor logs the scanned taxel's force on the same host clock."""
    scans = [read_scan_csv(build / "calibration" / f"scan_simulated_taxel_{k:02d}.csv") for k in range(5)]
    scan = scans[pressed]
    rows = [COLUMNS]
    for r, t in enumerate(scan.time_s.tolist()):
        for k, other in enumerate(scans):
            b = other.B_uT[min(r, other.rows - 1)]
            rows.append(f"{t + 1e-4 * k:.6f},{T0 + t + 1e-4 * k + 1e-3:.6f},{k},{b[0]:.4f},{b[1]:.4f},{b[2]:.4f},"
                        f"0,0,0,0,{r % 256}")
    ref = ["time_s,Fx_N,Fy_N,Fz_N"] + [f"{T0 + t:.6f},{f[0]!r},{f[1]!r},{f[2]!r}"
                                       for t, f in zip(scan.time_s.tolist(), scan.F_N.tolist())]
    return "\n".join(rows) + "\n", "\n".join(ref) + "\n"


@pytest.fixture
def bench(array_builds, tmp_path, monkeypatch):
    """A copy of the strip's build (the working folder, as on the bench) and strip-01's record beside it."""
    project = tmp_path / "project"
    out = project / "build" / "strip_1x5"
    shutil.copytree(array_builds["strip_1x5"].out_dir, out)
    monkeypatch.chdir(out)
    monkeypatch.delenv(records.ROOT_ENV, raising=False)

    def run(*args: str):
        return CliRunner().invoke(main, [*args])

    result = run("sensor", "add", "strip-01", "--sensors", str(project / "sensors"), "--date", "2026-11-20")
    assert result.exit_code == 0, result.output
    return out, records.open_sensor(project / "sensors", "strip-01"), run


def _calibrate(out, run, k: int, *extra: str):
    text, ref = recording(out, k)
    (out / f"rec_{k}.csv").write_text(text)
    (out / f"ref_{k}.csv").write_text(ref)
    return run("calibrate", f"rec_{k}.csv", "--reference", f"ref_{k}.csv", "--sensor", "strip-01", *extra)


def test_each_taxel_is_calibrated_into_the_record_and_the_build_is_left(bench):
    out, sensor, run = bench
    added = sensor.events()[0]
    assert added["taxels"] == 5 and set(added["files"]) >= {"spec.json", "design.json", "array.json"}
    for k in (2, 0, 4, 1, 3):  # in any order
        text, ref = recording(out, k)
        (out / f"rec_{k}.csv").write_text(text)
        (out / f"ref_{k}.csv").write_text(ref)
        before = tree(out)
        result = run("calibrate", f"rec_{k}.csv", "--reference", f"ref_{k}.csv", "--sensor", "strip-01", "--taxel",
                     str(k), "--date", f"2026-11-2{k}")
        assert result.exit_code == 0, result.output
        assert f"calibrated sensor strip-01 (taxel {k}) from rec_{k}.csv + ref_{k}.csv" in result.output
        assert tree(out) == before  # the build keeps its provisional calibrations and scans
        event, cal = sensor.current_calibration(taxel=k)
        assert event["taxel"] == k and event["provisional"] is False and event["date"] == f"2026-11-2{k}T00:00:00Z"
        assert event["calibration_sha256"] == calibration_sha256(cal)
        assert sensor.file(event["files"]["scan.csv"]) == text.encode()
        assert sensor.file(event["files"]["reference.csv"]) == ref.encode()
        assert "scan_merged.csv" in event["files"]
        # the taxel's own rows: its rest field is its chip's (its magnet plus its neighbours' at rest), read where
        # its scan pressed least
        own = read_scan_csv(out / "calibration" / f"scan_simulated_taxel_{k:02d}.csv")
        force = np.linalg.norm(own.F_N, axis=1)
        at_rest = float(np.mean(own.B_uT[force <= 0.02 * force.max(), 2]))
        assert event["rest_field_uT"][2] == pytest.approx(at_rest, rel=0.01)
        assert event["sensitivity_normal_uT_per_N"] > 0 and event["range_normal_N"] > 0
    current = [sensor.current_calibration(taxel=k)[0]["number"] for k in range(5)]
    assert sorted(current) == list(range(2, 7))  # one calibration per taxel, none replaced
    with pytest.raises(records.RecordError, match="no calibration yet"):
        sensor.current_calibration()  # an array's record has no single-taxel calibration
    shown = run("sensor", "show", "strip-01", "--sensors", str(sensor.root))
    assert shown.exit_code == 0 and all(f" {k} " in shown.output for k in range(5)), shown.output


def test_a_taxel_named_wrongly_or_not_at_all_writes_nothing(bench):
    out, sensor, run = bench
    events = sensor.events()
    for extra, words in ((("--taxel", "5"), "must be 0 to 4"), ((), "give the taxel the scan pressed")):
        result = _calibrate(out, run, 2, *extra)
        assert result.exit_code == 2 and words in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    assert sensor.events() == events


def test_sensor_add_adopts_a_taxel_calibration_measured_into_the_array_build(array_builds, tmp_path, monkeypatch):
    """A taxel calibrated into the build folder before the sensor had a record (``magfab calibrate --taxel 3``
    without --sensor): ``sensor add`` keeps it as taxel 3's calibration, with its scan, and no other taxel's."""
    import json

    out = tmp_path / "build" / "strip_1x5"
    shutil.copytree(array_builds["strip_1x5"].out_dir, out)
    cal = json.loads((out / "calibration" / "taxel_03.json").read_text())
    cal["scan"]["source"] = "rec.csv + ref.csv"  # as a measured calibration names its recording and reference log
    (out / "calibration" / "taxel_03.json").write_text(json.dumps(cal, indent=1))
    shutil.copy(out / "calibration" / "scan_simulated_taxel_03.csv", out / "calibration" / "scan_taxel_03.csv")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(records.ROOT_ENV, raising=False)
    result = CliRunner().invoke(main, ["sensor", "add", "strip-02", "--build", str(out), "--sensors", "sensors"])
    assert result.exit_code == 0, result.output
    sensor = records.open_sensor(tmp_path / "sensors", "strip-02")
    adopted = [e for e in sensor.events() if e["kind"] == "calibration"]
    assert [e["taxel"] for e in adopted] == [3] and adopted[0]["calibration_sha256"] == calibration_sha256(cal)
    assert sensor.info["taxels"] == 5 and "scan_merged.csv" in adopted[0]["files"]
