"""An array build's readout package (the host side): the package of a 1x5 strip (alternating, 14 mm)
imported from its rendered folder, its simulated array streaming every taxel, a press on taxel 2 computed with
magfab's exact field model read on taxel 2 and not on its neighbours, a chip error flagging only its taxel, and the
command line's stream, record (the taxel column, read back by magfab's own recording reader) and info."""

from __future__ import annotations

import csv
import dataclasses
import importlib
import io
import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from readout_support import PKG, imported

from magfab.design import derive
from magfab.export.readout import render
from magfab.models import taxels
from magfab.models.predict import predict
from magfab.models.scan import scan_track
from magfab.spec import parse_spec

STRIP = '[array]\nrows = 1\ncols = 5\npitch_mm = 14.0\npolarity = "alternating"\n'


@pytest.fixture(scope="module")
def strip():
    """The strip's design, prediction, array.json and every taxel's calibration (fitted to its simulated scan)."""
    design = derive(parse_spec(STRIP, "strip"))
    pred = predict(design)
    arrayed = taxels.calibrate_taxels(design, pred, dynamic=True)
    return design, pred, arrayed.as_json(design), [f.calibration.to_json() for f in arrayed.fits]


@pytest.fixture(scope="module")
def rendered(strip):
    design, _, doc, cals = strip
    return render(design, cals[0], None, doc, tuple(cals))


@pytest.fixture(scope="module")
def folder(rendered, tmp_path_factory):
    return tmp_path_factory.mktemp("array-readout")


@pytest.fixture(scope="module")
def pkg(rendered, folder):
    with imported(rendered, folder) as module:
        yield module


@pytest.fixture(scope="module")
def array(pkg):
    return pkg.ArrayCalibration.embedded()


class Exact:
    """Every chip's field from magfab's exact model (magpylib's kernel), every magnet at rest until ``t_press``,
    then magnet ``taxel`` moved by ``motion`` (mm, board frame)."""

    def __init__(self, design, taxel=2, motion=(0.0, 0.0, 0.0), t_press=0.1):
        self.rest = taxels.field_at_chips(design).sum(axis=1)
        centres = taxels._magnet_centres(design).copy()
        centres[taxel] += motion
        self.pressed = taxels.field_at_chips(design, centres).sum(axis=1)
        self.t_press = t_press

    def fields(self, t_s):
        return (self.pressed if t_s >= self.t_press else self.rest).tolist()


def _press_points(design, pred):
    """(magnet motion, force) at three points of the scan track: straight down at half and most of the depth, and
    sideways near the bottom (the calibration scan's own model: the magnet shifts y and travels u down)."""
    y, delta = scan_track(design, pred)
    nominal = pred.curves["nominal"]
    k_s = pred.shear.stiffness_N_per_mm["nominal"]
    out = []
    for depth, lateral in ((0.5, 0.0), (0.9, 0.0), (0.8, 0.8)):
        d = depth * delta.max()
        yy = lateral * np.abs(y).max()
        u = float(np.interp(d, nominal.indentation_mm, nominal.magnet_displacement_mm))
        fz = float(np.interp(d, nominal.indentation_mm, nominal.force_N))
        out.append(((0.0, yy, -u), (0.0, k_s * yy, fz)))
    return out


def _pressed(pkg, array, design, motion, **options):
    """Cycles of the simulated array fed the exact fields: zeroed at rest, then the press; the pressed cycles."""
    sim = pkg.SimulatedArray(array, realtime=False, noise_lsb=0.0, chunk=8,
                             pattern=Exact(design, motion=motion, t_press=0.1), **options)
    with pkg.Device(transport=sim) as device:
        reader = pkg.ArrayReader(device, array)
        reader.zero(10)
        cycles = [c for c in reader.read(40) if c.time_s > 0.1 + 0.01]
    return cycles[:4], reader


def test_the_package_ships_the_array_and_reads_it(pkg, array, rendered, strip):
    design, _, doc, cals = strip
    for name in ("array.json", "array_json.py", "taxels.py", "array_sim.py", "array_cli.py",
                 *(f"taxel_{k:02d}.json" for k in range(5))):
        assert f"{PKG}/{name}" in rendered
    readme = rendered["readout/README.md"].decode()
    assert "## An array of 5 taxels" in readme and "--taxel K" in readme
    assert array.taxels == 5 and array.addresses == (0x0C, 0x0D, 0x0E, 0x0F, 0x10) and array.dynamic
    assert [c.sha256 for c in array.calibrations] == [pkg.Calibration(c).sha256 for c in cals]
    # at rest every chip reads its own magnet plus its neighbours', and the compensation gives back its own
    rest = taxels.field_at_chips(design).sum(axis=1)
    np.testing.assert_allclose(array.rest_readings, rest, atol=1e-3)
    own = np.array(array.own_fields(rest.tolist()))
    np.testing.assert_allclose(own, np.array(doc["rest_uT"]), atol=1.0)


def _samples(pkg, cycles, drop=()):
    """Field samples of ``cycles`` [(seq, [B per taxel])], leaving out (cycle, taxel) pairs in ``drop``."""
    return [pkg.Sample(seq, 1000 * seq + 10 * k, 0, tuple(B), (math.nan,) * 3, 25.0, "binary", taxel=k,
                       time_s=seq * 1e-3 + k * 1e-5)
            for c, (seq, fields) in enumerate(cycles) for k, B in enumerate(fields) if (c, k) not in drop]


def test_cycles_are_grouped_by_sequence_and_taxel_order(pkg, array):
    rest = [list(b) for b in array.rest_readings]
    stream = _samples(pkg, [(s, rest) for s in (7, 8, 9, 10)], drop={(1, 2), (2, 4)})
    assembler = pkg.CycleAssembler(5)
    groups = [g for s in stream for g in assembler.feed(s)] + assembler.flush()
    assert [[s.seq if s else None for s in g] for g in groups] == [
        [7] * 5, [8, 8, None, 8, 8], [9, 9, 9, 9, None], [10] * 5]
    # a repeated taxel starts the next cycle, even under the same sequence number (a wrapped counter)
    again = pkg.CycleAssembler(5)
    twice = _samples(pkg, [(3, rest[:2]), (3, rest[:2])])
    assert [len([s for s in g if s]) for s in twice for g in again.feed(s)] + [len(g) for g in again.flush()] == [2, 5]
    evaluator = pkg.ArrayEvaluator(array)
    cycles = [evaluator.cycle(g) for g in groups]
    assert [c.complete for c in cycles] == [True, False, False, True]
    assert cycles[1][2].missing and cycles[1][2].flags == "----M" and all(map(math.isnan, cycles[1][2].force_N))
    assert cycles[1].held == (2,) and all(cycles[1][k].ok and abs(cycles[1][k].force_N[2]) < 0.02 for k in (0, 1, 3, 4))


def test_a_chip_error_flags_only_its_taxel(pkg, array):
    sim = pkg.SimulatedArray(array, realtime=False, chip_error_taxel=3, chip_error_every=4, chunk=8)
    with pkg.Device(transport=sim) as device:
        cycles = pkg.ArrayReader(device, array).read(16)
    assert [len(c) for c in cycles] == [5] * 16 and [c.seq for c in cycles] == list(range(16))
    for c in cycles:
        failed = c.seq % 4 == 3
        assert c[3].chip_error == failed and c.held == ((3,) if failed else ())
        assert ("E" in c[3].flags) == failed and c[3].fault_name == ("nack at read" if failed else None)
        assert all(math.isnan(f) for f in c[3].force_N) == failed
        for k in (0, 1, 2, 4):
            assert c[k].ok and c[k].flags == "-----" and abs(c[k].force_N[2]) < 0.02, (c.seq, k, c[k])
    assert [c.seq for c in cycles if "R" in c[3].flags] == [4, 8, 12]


def test_a_press_on_taxel_2_reads_on_taxel_2_only(pkg, array, strip):
    """Fields from the exact model with magnet 2 pressed (and slid) along its scan track: taxel 2 reads the press's
    force within its calibration's held-out error, taxels 1 and 3 change by less than the resolution; without the
    neighbours' motion removed (array.json's ``dynamic`` false) they would not."""
    design, pred, doc, cals = strip
    errors = cals[2]["errors"]
    tolerance = (errors["Fr_N"]["max_holdout"], errors["Fr_N"]["max_holdout"], errors["Fz_N"]["max_holdout"])
    resolution = (pred.shear.resolution_mN / 1e3,) * 2 + (pred.normal.resolution_mN / 1e3,)
    static = pkg.ArrayCalibration(dict(doc, dynamic=False), cals)
    worst_static = 0.0
    for motion, force in _press_points(design, pred):
        cycles, _reader = _pressed(pkg, array, design, motion)
        assert cycles and all(c.complete for c in cycles)
        for c in cycles:
            got = c[2].force_N
            assert all(abs(g - f) < t for g, f, t in zip(got, force, tolerance)), (motion, got, force, tolerance)
            for k in (1, 3):
                assert all(abs(x) < r for x, r in zip(c[k].force_N, resolution)), (motion, k, c[k].force_N)
        # the same fields with only the neighbours' field at rest removed
        readings = Exact(design, motion=motion).pressed.tolist()
        rest = static.forces(Exact(design).rest.tolist())
        moved = static.forces(readings)
        worst_static = max(worst_static,
                           *(abs(moved[k][a] - rest[k][a]) / resolution[a] for k in (1, 3) for a in range(3)))
    assert worst_static > 1.0


def test_a_missing_neighbour_is_held_in_the_compensation(pkg, array, strip):
    """Taxel 3 pressed and slid, its frames lost for two cycles: it reads NaN, and taxel 2 beside it still reads
    nothing of the press (taxel 3's slot took its last good reading); with nothing held (its rest field in the
    slot) taxel 2 would misread the press."""
    design, pred, _, _ = strip
    resolution = (pred.shear.resolution_mN / 1e3,) * 2 + (pred.normal.resolution_mN / 1e3,)
    motion, _ = _press_points(design, pred)[2]
    exact = Exact(design, taxel=3, motion=motion, t_press=0.0)
    rest = pkg.ArrayEvaluator(array).cycle(_samples(pkg, [(0, Exact(design).rest.tolist())]))[2].force_N
    rows = [(s, exact.fields(0.0)) for s in range(4)]
    groups = []
    assembler = pkg.CycleAssembler(5)
    for sample in _samples(pkg, rows, drop={(2, 3), (3, 3)}):
        groups += assembler.feed(sample)
    evaluator = pkg.ArrayEvaluator(array)
    cycles = [evaluator.cycle(g) for g in groups + assembler.flush()]
    assert [c.held for c in cycles] == [(), (), (3,), (3,)]
    assert all(math.isnan(x) for x in cycles[2][3].force_N) and cycles[2][3].flags == "----M"
    for c in cycles:
        assert all(abs(a - b) < r for a, b, r in zip(c[2].force_N, rest, resolution)), (c.seq, c[2].force_N, rest)
    stale = pkg.ArrayEvaluator(array, hold_s=0.0)
    stale.cycle(groups[1])
    misread = stale.cycle(groups[2])[2].force_N
    assert max(abs(a - b) / r for a, b, r in zip(misread, rest, resolution)) > 1.0


def test_a_single_taxels_firmware_is_refused(pkg, array):
    single = pkg.SimulatedDevice(array.calibrations[0], realtime=False, chunk=20)
    with pkg.Device(transport=single) as device, \
            pytest.raises(pkg.WrongFirmware, match="sends a single taxel's force frames"):
        pkg.ArrayReader(device, array).read(1)
    array_sensor = importlib.import_module("magfab_readout.array_sensor")
    with pkg.Device(transport=pkg.SimulatedDevice(array.calibrations[0], realtime=False)) as device, \
            pytest.raises(pkg.WrongFirmware, match="reads 1 chip but this readout package is for an array of 5"):
        array_sensor.checked_info(device, array)


def _rows(stdout):
    return [line.split() for line in stdout.splitlines() if line and not line.startswith("#")]


def test_stream_prints_every_taxel_of_every_cycle(pkg, capsys):
    cli = importlib.import_module("magfab_readout.cli")
    assert cli.main(["stream", "--simulate", "--count", "12", "--zero", "10", "--raw"]) == 0
    out, err = capsys.readouterr()
    assert "array of 5 taxels (0x0C 0x0D 0x0E 0x0F 0x10)" in out
    assert sum(line.startswith("# zero: taxel ") for line in out.splitlines()) == 5
    assert "# t_s seq taxel Fx_N Fy_N Fz_N Bx_uT By_uT Bz_uT T_C flags fault Bx_lsb By_lsb Bz_lsb T_raw" in out
    rows = _rows(out)
    assert len(rows) == 60 and [int(r[2]) for r in rows] == list(range(5)) * 12
    assert all(len({r[1] for r in rows[5 * c:5 * c + 5]}) == 1 for c in range(12))  # one sequence per cycle
    assert max(abs(float(x)) for r in rows for x in r[3:6]) < 0.02 and {r[10] for r in rows} == {"-----"}
    # the rate the cycles came at, from their device time, against the chips' (the simulated board's: the serial link
    # carries 250 cycles of 5 field frames a second at 250000 baud)
    rate = re.search(r"12 cycles of 5 taxels; ([0-9.]+) cycles/s over ([0-9.]+) s of device time, against the chip's "
                     r"([0-9.]+) conversions/s \(([0-9.]+)%\); 0 incomplete", err)
    assert rate, err
    expected = importlib.import_module("magfab_readout.array_sim").cycle_rate_Hz(5)
    assert float(rate[1]) == pytest.approx(expected, rel=0.01)
    assert float(rate[2]) == pytest.approx(11 / expected, abs=0.005)  # printed to 10 ms
    assert float(rate[4]) == pytest.approx(100 * expected / float(rate[3]), abs=0.1)
    assert cli.main(["stream", "--simulate", "--count", "1", "--check"]) == 2
    assert "an array's firmware sends only fields" in capsys.readouterr().err


def test_stream_in_text_mode_through_the_installed_command(rendered, folder):
    env = dict(os.environ, PYTHONPATH=str(folder / "readout" / "src"))
    proc = subprocess.run([sys.executable, "-m", "magfab_readout", "stream", "--simulate", "--text", "--count", "4"],
                          capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 0, proc.stderr
    rows = _rows(proc.stdout)
    assert [int(r[2]) for r in rows] == list(range(5)) * 4 and "0 CRC errors, 0 bad lines" in proc.stderr


def test_record_writes_a_taxel_column_magfab_calibrate_reads(pkg, capsys, tmp_path):
    from magfab.formats.scan_csv import read_recording

    cli = importlib.import_module("magfab_readout.cli")
    out = tmp_path / "strip.csv"
    assert cli.main(["record", str(out), "--simulate", "--seconds", "0.06"]) == 0
    text = out.read_text()
    assert "# array: array of 5 taxels" in text and "# taxel 4 calibration_sha256: " in text
    rows = list(csv.DictReader(io.StringIO("\n".join(line for line in text.splitlines() if not line.startswith("#")))))
    assert list(rows[0])[:3] == ["time_s", "host_time_s", "taxel"] and "Fz_sensor_N" in rows[0]
    assert [int(r["taxel"]) for r in rows] == list(range(5)) * (len(rows) // 5) and len(rows) >= 50
    for k in (0, 2):
        recording = read_recording(out, taxel=k)
        mine = [r for r in rows if r["taxel"] == str(k)]
        assert len(recording.scan.B_uT) == len(mine)
        assert recording.scan.B_uT[0][2] == pytest.approx(float(mine[0]["Bz_uT"]))
    assert f"wrote {len(rows)} rows" in capsys.readouterr().err


def test_info_lists_the_array(pkg, capsys):
    cli = importlib.import_module("magfab_readout.cli")
    assert cli.main(["info", "--simulate"]) == 0
    out = capsys.readouterr().out
    assert "I,magfab,strip," in out and out.rstrip().endswith("calibration: match") and "5 taxel(s)" in out
    lines = [line for line in out.splitlines() if line.startswith("  taxel ")]
    assert len(lines) == 5 and "address 0x10  option code 012" in lines[4] and "magnet north down" in lines[1]
    assert cli.main(["check", "--simulate", "--yes"]) == 2  # rendered here without the build's bands and budget
    assert "carries no acceptance.json" in capsys.readouterr().err


def test_upload_writes_the_array_record(pkg, array, capsys, tmp_path):
    """``upload`` writes the array's record (version 3: the settings and every chip's address, no calibration) and
    the board then reports its chips; a calibration file is refused (an array's board holds none)."""
    cli = importlib.import_module("magfab_readout.cli")
    eeprom = importlib.import_module("magfab_readout.eeprom")
    assert cli.main(["upload", "--simulate"]) == 0
    out = capsys.readouterr().out
    assert "read back equal; the board reads 5 chips" in out and array.calibrations[0].short_hash in out
    sim = pkg.SimulatedArray(array, realtime=False)
    with pkg.Device(transport=sim) as device:
        record = eeprom.pack_array(array.addresses, array.calibrations[0].short_hash, {
            **importlib.import_module("magfab_readout._build").IMAGE_SETTINGS})
        device.eeprom_write(0, record)
        assert eeprom.addresses(bytes(sim.eeprom)) == list(array.addresses) and device.info().taxels == 5
    path = tmp_path / "taxel.json"
    path.write_text("{}")
    assert cli.main(["upload", str(path), "--simulate"]) == 2
    assert "an array's board holds no calibration" in capsys.readouterr().err


def test_a_warming_array_is_corrected_taxel_by_taxel(pkg, array, strip):
    """Every chip and magnet warming from 25 to 35 C at rest (the fields from the exact model, falling by the
    calibrations' -0.12 %/C): each taxel, corrected with its own chip's temperature, stays within the resolution of
    zero; the same readings through calibrations without their thermal block drift by about the single taxel's
    uncorrected rest figure (drift.py) on every taxel."""
    design, pred, doc, cals = strip
    resolution = (pred.shear.resolution_mN / 1e3,) * 2 + (pred.normal.resolution_mN / 1e3,)
    a = cals[0]["thermal"]["coefficient_per_C"]["Bz_uT"]
    ramp = pkg.TemperatureRamp(25.0, 35.0, duration_s=0.4, delay_s=0.05)

    def warmed(calibration):
        sim = pkg.SimulatedArray(calibration, realtime=False, noise_lsb=0.0, chunk=8, pattern=Exact(design),
                                 temperature=ramp, thermal_per_C=a)
        with pkg.Device(transport=sim) as device:
            reader = pkg.ArrayReader(device, calibration)
            reader.zero(10)
            return [c for c in reader.read(300) if c.time_s > 0.5]

    hot = warmed(array)
    assert len(hot) > 20 and all(c.complete for c in hot)
    assert all(abs(c[k].temperature_C - 35.0) < 0.1 for c in hot for k in range(5))
    for c in hot:
        for k in range(5):
            assert all(abs(f) < r for f, r in zip(c[k].force_N, resolution)), (k, c[k].force_N, resolution)
    bare = pkg.ArrayCalibration(doc, [{key: v for key, v in cal.items() if key != "thermal"} for cal in cals])
    drift = [warmed(bare)[-1][k].force_N[2] for k in range(5)]
    assert all(abs(fz) > 5 * resolution[2] for fz in drift), drift
    worst = max(abs(c[k].force_N[2]) for c in hot for k in range(5))
    print(f"after +10 C: corrected |Fz| <= {1e3 * worst:.2f} mN, "
          f"uncorrected Fz {[round(1e3 * fz, 1) for fz in drift]} mN")


def test_a_taxel_at_full_scale_reads_no_force_and_is_held_in_the_compensation(pkg, array, strip):
    """Taxel 3 pressed and slid, its chip at full scale for two cycles (its field clipped there): it reads NaN force
    with its field kept and the fault named, and taxel 2 beside it still reads nothing of the press (taxel 3's slot
    holds its last good reading, not the clipped one)."""
    design, pred, _, _ = strip
    resolution = (pred.shear.resolution_mN / 1e3,) * 2 + (pred.normal.resolution_mN / 1e3,)
    motion, _ = _press_points(design, pred)[2]
    exact = Exact(design, taxel=3, motion=motion, t_press=0.0)
    rest = pkg.ArrayEvaluator(array).cycle(_samples(pkg, [(0, Exact(design).rest.tolist())]))[2].force_N
    full_z = pkg._build.FULL_SCALE_COUNTS * pkg._build.LSB_Z_UT
    samples = _samples(pkg, [(s, exact.fields(0.0)) for s in range(4)])
    for i, s in enumerate(samples):
        if s.taxel == 3 and s.seq in (2, 3):
            samples[i] = dataclasses.replace(s, status=0x04, B_uT=(*s.B_uT[:2], full_z))
    assembler = pkg.CycleAssembler(5)
    groups = [g for s in samples for g in assembler.feed(s)] + assembler.flush()
    evaluator = pkg.ArrayEvaluator(array)
    cycles = [evaluator.cycle(g) for g in groups]
    assert [c.held for c in cycles] == [(), (), (3,), (3,)]
    for c in cycles[2:]:
        t = c[3]
        assert all(math.isnan(x) for x in t.force_N) and not t.ok and t.flags == "--S--"
        assert t.B_uT[2] == full_z and t.fault_name == "full scale"
    for c in cycles:
        assert all(abs(a - b) < r for a, b, r in zip(c[2].force_N, rest, resolution)), (c.seq, c[2].force_N, rest)
