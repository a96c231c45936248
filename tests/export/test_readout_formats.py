"""``magfab-readout record --format``: Parquet and MCAP recordings read back by their own libraries (pyarrow; mcap
with its ROS 2 decoder), every value against the CSV the same recording streams; the clock map under every read;
a missing library refused before the board is opened. Runs the default and the strip build's readout packages as
``python -m magfab_readout`` on the simulated board."""

from __future__ import annotations

import csv
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.readout.src.magfab_readout import record_formats
from magfab.readout.src.magfab_readout.clock import clock_map


def readout(build, cwd: Path, *args, timeout=120):
    env_path = str(build.out_dir / "readout" / "src")
    return subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, {env_path!r}); "
                           "from magfab_readout.cli import main; sys.exit(main())", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=cwd)


def _csv(path: Path) -> tuple[list[str], list[dict]]:
    with open(path, encoding="utf-8", newline="") as f:
        lines = [line for line in f if not line.startswith("#")]
    rows = list(csv.DictReader(lines))
    return list(rows[0]), rows


def _parquet(path: Path):
    import pyarrow.parquet as pq

    return pq.read_table(path)


def _mcap(path: Path) -> dict:
    """{topic: [(schema name, log time ns, decoded message)]} of an MCAP file, and its metadata under None."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: dict = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, ros in reader.iter_decoded_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append((schema.name, message.log_time, ros))
        out[None] = {m.name: m.metadata for m in reader.iter_metadata()}
        assert reader.get_header().profile == "ros2"
    return out


@pytest.fixture(scope="module")
def recorded(default_build, tmp_path_factory):
    """One simulated recording as CSV, and the same rows converted to Parquet and MCAP by the readout's own
    converter, as ``record --format`` converts them."""
    folder = tmp_path_factory.mktemp("rec")
    proc = readout(default_build, folder, "record", "rec.csv", "--simulate", "--seconds", "0.4")
    assert proc.returncode == 0, proc.stderr
    cal = json.loads((default_build.out_dir / "calibration" / "calibration.json").read_text())
    for fmt in ("parquet", "mcap"):
        shutil.copy(folder / "rec.csv", folder / f"partial.{fmt}.csv")
        record_formats.convert(str(folder / f"partial.{fmt}.csv"), str(folder / f"rec.{fmt}"), fmt, cal)
        assert not (folder / f"partial.{fmt}.csv").exists()
    return folder, cal


def test_parquet_holds_every_value_with_its_unit_and_the_calibration(recorded):
    folder, cal = recorded
    columns, rows = _csv(folder / "rec.csv")
    table = _parquet(folder / "rec.parquet")
    assert table.column_names == [*columns, "stamp_s"] and table.num_rows == len(rows) > 100
    for name in columns:
        got = table.column(name).to_pylist()
        want = [int(r[name]) if name in ("status", "seq") else float(r[name]) for r in rows]
        assert got == want, name
        assert table.schema.field(name).metadata[b"unit"].decode() == record_formats.UNITS[name]
    t0, h0, slope = clock_map([float(r["time_s"]) for r in rows], [float(r["host_time_s"]) for r in rows])
    stamps = table.column("stamp_s").to_pylist()
    assert stamps == [h0 + slope * (float(r["time_s"]) - t0) for r in rows]
    assert all(s <= float(r["host_time_s"]) + 1e-6 for s, r in zip(stamps, rows))  # never after it was read
    meta = table.schema.metadata
    assert json.loads(meta[b"magfab.calibration"]) == cal
    header = json.loads(meta[b"magfab"])["header"]
    assert header[0].endswith(" record") and header[1] == 'spec: "magone"'


def test_mcap_holds_every_value_as_ros2_messages(recorded):
    folder, cal = recorded
    _, rows = _csv(folder / "rec.csv")
    topics = _mcap(folder / "rec.mcap")
    stamps = _parquet(folder / "rec.parquet").column("stamp_s").to_pylist()
    wrench, field, temp = (topics[f"/magfab/{t}"] for t in ("wrench", "magnetic_field", "temperature"))
    assert len(wrench) == len(field) == len(temp) == len(rows)
    assert {w[0] for w in wrench} == {"geometry_msgs/msg/WrenchStamped"}
    assert {f[0] for f in field} == {"sensor_msgs/msg/MagneticField"}
    for row, stamp, (_, log_ns, w), (_, _, b), (_, _, t) in zip(rows, stamps, wrench, field, temp):
        ns = round(stamp * 1e9)
        assert log_ns == ns and w.header.stamp.sec * 1_000_000_000 + w.header.stamp.nanosec == ns
        assert w.header.frame_id == "magfab_magone" == b.header.frame_id
        assert (w.wrench.force.x, w.wrench.force.y, w.wrench.force.z) == tuple(
            float(row[f"F{k}_sensor_N"]) for k in "xyz")
        assert (w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z) == (0.0, 0.0, 0.0)
        assert (b.magnetic_field.x, b.magnetic_field.y, b.magnetic_field.z) == tuple(
            1e-6 * float(row[f"B{k}_uT"]) for k in "xyz")
        assert t.temperature == float(row["temperature_C"])
    meta = topics[None]["magfab"]
    assert json.loads(meta["calibration.json"]) == cal and json.loads(meta["recording"])["units"]["Fz_sensor_N"] == "N"


def test_record_writes_each_format_whole_and_leaves_no_partial(default_build, tmp_path):
    """``record OUT.parquet`` and ``record OUT.mcap`` (the format from the suffix, or --format) end with OUT and no
    ``.partial.csv`` beside it; a format whose library is missing is refused before the board is opened, one line,
    exit 2, nothing written."""
    for name, args in (("a.parquet", ()), ("b.mcap", ()), ("c.bin", ("--format", "mcap"))):
        proc = readout(default_build, tmp_path, "record", name, "--simulate", "--seconds", "0.2", *args)
        assert proc.returncode == 0, proc.stderr
        assert "wrote" in proc.stderr and not (tmp_path / (name + ".partial.csv")).exists()
    assert _parquet(tmp_path / "a.parquet").num_rows > 50
    assert len(_mcap(tmp_path / "c.bin")["/magfab/wrench"]) > 50
    hidden = tmp_path / "hide"
    hidden.mkdir()
    (hidden / "pyarrow.py").write_text("raise ImportError('not installed')\n")  # shadows the installed one
    src = str(default_build.out_dir / "readout" / "src")
    proc = subprocess.run([sys.executable, "-c", f"import sys; sys.path[:0] = [{str(hidden)!r}, {src!r}]; "
                           "from magfab_readout.cli import main; sys.exit(main())", "record", "d.parquet",
                           "--simulate", "--seconds", "0.2"], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "--format parquet needs pyarrow: pip install pyarrow (the readout package's extra 'parquet')" in proc.stderr
    assert not (tmp_path / "d.parquet").exists() and not (tmp_path / "d.parquet.partial.csv").exists()


def test_an_arrays_recording_has_a_topic_per_taxel(array_builds, tmp_path):
    build = array_builds["strip_1x5"]
    proc = readout(build, tmp_path, "record", "strip.mcap", "--simulate", "--seconds", "0.2")
    assert proc.returncode == 0, proc.stderr
    topics = _mcap(tmp_path / "strip.mcap")
    wrenches = sorted(t for t in topics if t and t.endswith("/wrench"))
    assert wrenches == [f"/magfab/taxel_{k}/wrench" for k in range(5)]
    assert {m[2].header.frame_id for m in topics["/magfab/taxel_3/wrench"]} == {"magfab_strip_1x5_taxel_3"}
    assert set(json.loads(topics[None]["magfab"]["calibration.json"])) == {str(k) for k in range(5)}


@settings(max_examples=200, deadline=None)
@given(n=st.integers(2, 400), period=st.floats(1e-4, 0.1), rate=st.floats(-0.01, 0.01),
       latency=st.floats(1e-3, 0.1), seed=st.integers(0, 2**32 - 1), offset=st.floats(0.0, 2e9))
def test_the_clock_map_lies_under_every_read_and_over_the_true_clock_at_the_middle(n, period, rate, latency, seed,
                                                                                   offset):
    """Drawn recordings: device times a period apart, a host clock running fast or slow by up to 1 % at any Unix
    offset, each read late by a drawn delay (a few of them nearly on time): the map never puts a sample after it was
    read, and at the recording's mean time it is no earlier than the true clock (the hull's edge there is the highest
    line under every read)."""
    import random

    rng = random.Random(seed)
    t = [k * period for k in range(n)]
    true = [offset + (1.0 + rate) * x for x in t]
    h = [v + latency * rng.random() ** 3 for v in true]
    t0, h0, slope = clock_map(t, h)
    mapped = [h0 + slope * (x - t0) for x in t]
    eps = 1e-14 * max(1.0, offset) + 1e-12  # a few of the float64 ulps at the offset
    assert all(m <= v + eps for m, v in zip(mapped, h))
    mean = sum(t) / n
    assert h0 + slope * (mean - t0) >= offset + (1.0 + rate) * mean - eps
    assert math.isfinite(slope)


@pytest.mark.parametrize("which, command", [("default", ("stream",)), ("default", ("stream", "--text", "--check")),
                                            ("default", ("record", "ctrl_c.mcap")), ("strip_1x5", ("stream",))])
def test_ctrl_c_ends_on_a_whole_line_and_the_summary_follows(default_build, array_builds, tmp_path, which,
                                                             command):
    """Ctrl-C, the documented way to stop ``stream`` and ``record``: the output ends on a whole row, the summary of
    samples, losses and rate is printed, the exit status is 0, and a Parquet or MCAP recording is converted."""
    import signal

    build = default_build if which == "default" else array_builds[which]
    src = str(build.out_dir / "readout" / "src")
    proc = subprocess.Popen([sys.executable, "-c", f"import sys; sys.path.insert(0, {src!r}); "
                             "from magfab_readout.cli import main; sys.exit(main())", *command, "--simulate"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    assert proc.stdout is not None and proc.stderr is not None
    seen = ""
    if command[0] == "stream":
        for _ in range(40):  # rows are coming
            seen += proc.stdout.readline()
    else:
        import time

        deadline = time.monotonic() + 60
        partial = tmp_path / "ctrl_c.mcap.partial.csv"
        while time.monotonic() < deadline and (not partial.exists() or partial.stat().st_size < 5000):
            time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    out = seen + proc.stdout.read()  # what the reader's own buffer holds too (communicate would read past it)
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 0, err
    assert "lost (sequence gaps)" in err and "Traceback" not in err, err
    if command[0] == "stream":
        assert out.endswith("\n") and len(out.splitlines()[-1].split()) >= 11, out[-500:]
        assert ("host vs firmware force: max |dF|" in err) == ("--check" in command), err
    else:
        assert "(Ctrl-C)" in err and len(_mcap(tmp_path / "ctrl_c.mcap")["/magfab/wrench"]) > 10
        assert not (tmp_path / "ctrl_c.mcap.partial.csv").exists()
