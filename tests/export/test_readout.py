"""The readout package: its source tree (magfab/readout/) plus a build's data, pip-installed into
a fresh venv, checked against independent implementations written here (CRC, frame layout, the calibration's
evaluation, the region test), and its command line run against the simulated board and through a real
pseudo-terminal."""

from __future__ import annotations

import csv
import hashlib
import importlib
import io
import itertools
import json
import math
import os
import random
import re
import select
import subprocess
import sys
import threading
import time
import tomllib
import types
from contextlib import contextmanager, suppress
from pathlib import Path

import pytest
from readout_support import (
    PKG,
    assert_reads_zero_at_rest,
    f32,
    imported,
    install,
    make_calibration,
    ref_crc,
    ref_decode,
    ref_distance_to_hull,
    ref_forces,
    ref_frame,
    ref_inside,
)

from magfab import SpecError, derive, load_spec
from magfab.export.firmware import measured_rate
from magfab.export.readout import calibration_sha256, render

# --- fixtures -------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def design():
    return derive(load_spec(None))


@pytest.fixture(scope="module")
def calibration():
    return make_calibration()


@pytest.fixture(scope="module")
def rendered(design, calibration):
    return render(design, calibration)


@pytest.fixture(scope="module")
def pkg(rendered, tmp_path_factory):
    """The generated package imported in this process from its source tree."""
    with imported(rendered, tmp_path_factory.mktemp("readout-src")) as module:
        yield module


@pytest.fixture(scope="module")
def installed(rendered, tmp_path_factory):
    """The package pip-installed (with its dependencies) into a fresh virtual environment."""
    return install(rendered, tmp_path_factory.mktemp("readout-venv"))


def cli(installed, *args, timeout=60, port_variable=None):
    """The installed command; ``MAGFAB_READOUT_PORT`` is ``port_variable`` (unset when None)."""
    env = {k: v for k, v in os.environ.items() if k != "MAGFAB_READOUT_PORT"}
    if port_variable is not None:
        env["MAGFAB_READOUT_PORT"] = port_variable
    return subprocess.run([str(installed.script), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          env=env)


# --- rendering --------------------------------------------------------------------------------------------

def test_render_is_complete_deterministic_and_embeds_the_calibration(design, calibration, rendered):
    assert render(design, calibration) == rendered
    assert list(rendered) == sorted(rendered)
    expected = {"readout/pyproject.toml", "readout/README.md"} | {
        f"{PKG}/{name}" for name in ("__init__.py", "__main__.py", "_build.py", "acceptance_json.py", "build.json",
                                     "calibration.py", "calibration.json", "calibration_json.py", "check.py", "cli.py",
                                     "device.py", "eeprom.py", "frames.py", "json_checks.py", "rest.py", "simulate.py",
                                     "taxels.py", "array_sim.py", "array_cli.py", "array_json.py",
                                     "cli_shared.py", "identity.py", "records.py", "board_sensor.py", "bounded.py",
                                     "array_check.py", "array_sensor.py", "float32_bound.py", "readings.py",
                                     "weigh.py", "clock.py", "record_formats.py", "coins.py", "usage.py", "view.py",
                                     "view.html", "lerobot.py")}
    assert set(rendered) == expected and "## An array" not in rendered["readout/README.md"].decode()
    for path, data in rendered.items():
        assert isinstance(data, bytes) and not Path(path).is_absolute()
        if path.endswith(".py"):
            compile(data, path, "exec")
    project = tomllib.loads(rendered["readout/pyproject.toml"].decode())
    assert project["project"]["name"] == "magfab-readout"
    assert project["project"]["scripts"] == {"magfab-readout": "magfab_readout.cli:main"}
    assert [d.split(">")[0] for d in project["project"]["dependencies"]] == ["pyserial"]
    # a backend that builds out of tree: setuptools wrote readout/build/ and *.egg-info into the build folder
    assert project["build-system"]["build-backend"] == "flit_core.buildapi" and \
        "setuptools" not in project.get("tool", {})
    assert project["tool"]["flit"]["module"]["name"] == "magfab_readout"
    assert json.loads(rendered[f"{PKG}/calibration.json"]) == calibration
    sha = hashlib.sha256(json.dumps(calibration, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    assert calibration_sha256(calibration) == sha
    build = json.loads(rendered[f"{PKG}/build.json"])
    assert build["calibration_sha256"] == sha and build["spec_name"] == "magone"
    assert (build["gain_sel"], build["resolution"], build["baud"]) == (0, 2, 250000)
    assert build["lsb_xy_uT"] == pytest.approx(0.751 * 4) and build["lsb_z_uT"] == pytest.approx(1.21 * 4)


def test_spec_name_with_quotes_backslashes_and_newlines_renders_valid_python(design, calibration):
    name = 'a"b\\c\nd \'e\' """ {{ x }} {% y %} \u00e9\u2028'
    odd = derive(design.spec.model_copy(update={"name": name}))
    files = render(odd, calibration)
    for path, data in files.items():
        if path.endswith(".py"):
            compile(data, path, "exec")
    assert json.loads(files[f"{PKG}/build.json"])["spec_name"] == name
    assert json.dumps(name) in files["readout/README.md"].decode()


@pytest.mark.parametrize("change, key", [
    (lambda c: c.update(format="magfab-calibration/2"), "calibration.json:format"),
    (lambda c: c.update(method="spline"), "calibration.json:method"),
    (lambda c: c["monomials"].reverse(), "calibration.json:monomials"),
    (lambda c: c["coefficients"]["Fz_N"].pop(), "calibration.json:coefficients.Fz_N"),
    (lambda c: c["coefficients"]["Fr_N"].__setitem__(3, float("nan")), "calibration.json:coefficients.Fr_N[3]"),
    (lambda c: c["scaling"]["Br_uT"].update(scale=0.0), "calibration.json:scaling.Br_uT.scale"),
    (lambda c: c.update(shear_sign=0.5), "calibration.json:shear_sign"),
    (lambda c: c.pop("tare_N"), "calibration.json:tare_N.Fz_N"),
    (lambda c: c["valid_region"]["hull"].reverse(), "calibration.json:valid_region.hull"),
    (lambda c: c["valid_region"]["hull"].insert(2, [20000.0, 2000.0]), "calibration.json:valid_region.hull"),
    (lambda c: c["valid_region"].update(Bz_uT=[3.0, 1.0]), "calibration.json:valid_region.Bz_uT"),
])
def test_a_calibration_the_readout_cannot_evaluate_is_refused_by_key(design, change, key):
    bad = make_calibration()
    change(bad)
    with pytest.raises(SpecError) as err:
        render(design, bad)
    assert err.value.key == key, err.value.message


# --- the calibration in Python ---------------------------------------------------------------------------------

def test_evaluation_equals_an_independent_float64_implementation(pkg):
    cal = make_calibration(order=5, seed=7, tare=(0.31, -0.12))
    calibration = pkg.Calibration(cal)
    rng = random.Random(3)
    points = [(0.0, 0.0, 15000.0), (10.0, -20.0, 21000.0), (29.9, 0.0, 12000.0), (30.0, 0.0, 12000.0)]
    points += [(rng.uniform(-6000, 6000), rng.uniform(-6000, 6000), rng.uniform(10000, 32000)) for _ in range(500)]
    for B in points:
        got, want = calibration.evaluate(*B), ref_forces(cal, *B)
        for g, w in zip(got, want):
            assert abs(g - w) <= 1e-9 * max(1.0, abs(w)), (B, got, want)
    # the tare is taken off Fz and Fr, so it moves Fx and Fy along the field's direction (shear_sign -1)
    untared = pkg.Calibration(make_calibration(order=5, seed=7))
    Fx0, Fy0, Fz0 = untared.evaluate(3000.0, 4000.0, 20000.0)
    Fx1, Fy1, Fz1 = calibration.evaluate(3000.0, 4000.0, 20000.0)
    assert (Fx1 - Fx0, Fy1 - Fy0, Fz1 - Fz0) == pytest.approx((-0.12 * 0.6, -0.12 * 0.8, -0.31))


def with_mls(cal: dict, order: int = 2, bandwidth: float = 0.15) -> dict:
    """``cal`` switched to moving least squares over a jittered grid of scan points inside its region."""
    rng = random.Random(9)
    bz, br, fz, fr = [], [], [], []
    for a in range(25):
        for b in range(15):
            z, r = 12000 + 18000 * (a + rng.uniform(0, 0.5)) / 25, 8000 * (b + rng.uniform(0, 0.5)) / 15
            if ref_inside(cal, z, r):
                bz.append(z)
                br.append(r)
                fz.append(2.0 * (z - 12000) / 9000 + 0.01 * math.sin(r / 700) + rng.gauss(0, 0.005))
                fr.append(1.5 * r / 4000 + 0.02 * math.cos(z / 3000) + rng.gauss(0, 0.005))
    return dict(cal, method="mls", mls={
        "order": order, "bandwidth": bandwidth, "units": "bandwidth in the scaled (u, v) of 'scaling'",
        "weight": "gaussian exp(-d^2 / (2 bandwidth^2)), d the distance in (u, v)",
        "points": {"Bz_uT": bz, "Br_uT": br, "Fz_N": fz, "Fr_N": fr}})


def ref_mls(cal: dict, Bz: float, Br: float) -> tuple:
    """docs/bundle.md's moving least squares with numpy over every point: untared (Fz, Fr)."""
    import numpy as np

    sc, m = cal["scaling"], cal["mls"]
    h, order = m["bandwidth"], m["order"]
    u = (np.array(m["points"]["Bz_uT"]) - sc["Bz_uT"]["center"]) / sc["Bz_uT"]["scale"]
    v = (np.array(m["points"]["Br_uT"]) - sc["Br_uT"]["center"]) / sc["Br_uT"]["scale"]
    uq = (Bz - sc["Bz_uT"]["center"]) / sc["Bz_uT"]["scale"]
    vq = (Br - sc["Br_uT"]["center"]) / sc["Br_uT"]["scale"]
    du, dv = (u - uq) / h, (v - vq) / h
    d2 = du**2 + dv**2
    w = np.exp(-0.5 * (d2 - d2.min()))
    P = np.column_stack([du**i * dv**(k - i) for k in range(order + 1) for i in range(k, -1, -1)])
    A = P.T @ (w[:, None] * P)
    A += 1e-12 * np.trace(A) * np.eye(len(A))
    y = np.column_stack([m["points"]["Fz_N"], m["points"]["Fr_N"]])
    sol = np.linalg.solve(A, P.T @ (w[:, None] * y))
    return float(sol[0, 0]), float(sol[0, 1])


def test_moving_least_squares_equals_an_independent_implementation(pkg):
    cal = with_mls(make_calibration(tare=(0.05, -0.02)))
    calibration = pkg.Calibration(cal)
    assert calibration.method == "mls"
    rng = random.Random(4)
    for _ in range(40):
        Bx, By, Bz = rng.uniform(-5000, 5000), rng.uniform(-5000, 5000), rng.uniform(11000, 31000)
        Br = math.hypot(Bx, By)
        Fz, Fr = ref_mls(cal, Bz, Br)
        Fz, Fr = Fz - 0.05, Fr + 0.02
        want = (-Fr * Bx / Br, -Fr * By / Br, Fz)  # shear_sign -1
        for g, w in zip(calibration.evaluate(Bx, By, Bz), want):
            assert abs(g - w) <= 1e-9 * max(1.0, abs(w))
        # "poly" is still what the firmware computes
        assert calibration.evaluate(Bx, By, Bz, method="poly") == pytest.approx(ref_forces(cal, Bx, By, Bz),
                                                                                 rel=1e-12, abs=1e-12)
    with pytest.raises(pkg.CalibrationError, match="mls = None: is missing"):
        pkg.Calibration({k: v for k, v in cal.items() if k != "mls"})


def test_region_flag_equals_an_independent_point_in_polygon_test(pkg, calibration):
    cal = pkg.Calibration(calibration)
    rng = random.Random(5)
    checked = 0
    for _ in range(3000):
        Bz, Br = rng.uniform(8000, 34000), rng.uniform(-500, 9000)
        if ref_distance_to_hull(calibration, Bz, Br) < 1e-6:
            continue
        assert cal.in_region(Bz, Br) == ref_inside(calibration, Bz, Br), (Bz, Br)
        checked += 1
    assert checked > 2900
    assert all(cal.in_region(*p) for p in calibration["valid_region"]["hull"])  # the boundary belongs to it


# --- frames ---------------------------------------------------------------------------------------------------

def test_crc_is_ccitt_false(pkg):
    assert pkg.crc16_ccitt_false(b"123456789") == ref_crc(b"123456789") == 0x29B1  # the catalogue's check value
    data = bytes(range(256)) * 3
    assert pkg.crc16_ccitt_false(data) == ref_crc(data)


def _frames(n, start=0):
    rng = random.Random(11)
    return [{"seq": (start + k) & 0xFF, "t_us": (4_294_960_000 + 1712 * k) & 0xFFFFFFFF, "status": k % 16,
             "counts": (rng.randint(-32768, 32767), rng.randint(-9000, 9000), rng.randint(0, 22000)),
             "t_raw": 46244 + k, "forces": (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0, 5))}
            for k in range(n)]


def test_package_frames_are_byte_identical_to_the_documented_layout(pkg):
    for f in _frames(20):
        assert pkg.encode_frame(f["seq"], f["t_us"], f["status"], f["counts"], f["t_raw"], f["forces"]) == \
            ref_frame(**f)


def test_decoder_resynchronises_rejects_bad_crcs_and_counts_them(pkg):
    frames = _frames(12, start=250)
    wire = [ref_frame(**f) for f in frames]
    corrupted = bytearray(wire[3])
    corrupted[20] ^= 0x10  # a flipped bit inside the forces: CRC failure
    wire[3] = bytes(corrupted)
    wire[6] = wire[6][:14]  # cut short: the next frame starts inside it
    noise = b"\x00\xffF,1,2\x13\xa5\x5a\x01\x02garbage" + bytes(40)  # a fake sync and a fake text start
    body = b"I,magfab,my,name,0123456789ABCDEF,0,2,0,2"
    info = body + b"*%04X\n" % ref_crc(body)
    stream = noise + b"".join(wire[:5]) + info + b"".join(wire[5:]) + b"\xa5"
    expected = [f["seq"] for k, f in enumerate(frames) if k not in (3, 6)]

    whole = pkg.Decoder(lsb_xy_uT=3.004, lsb_z_uT=4.84)
    items = whole.feed(stream)
    pieces = pkg.Decoder(lsb_xy_uT=3.004, lsb_z_uT=4.84)
    rng = random.Random(2)
    chunked, k = [], 0
    while k < len(stream):
        step = rng.choice([1, 1, 2, 5, 31, 64])
        chunked += pieces.feed(stream[k:k + step])
        k += step
    assert chunked == items and pieces.stats == whole.stats

    samples = [x for x in items if isinstance(x, pkg.Sample)]
    infos = [x for x in items if isinstance(x, pkg.DeviceInfo)]
    assert [s.seq for s in samples] == expected
    assert whole.stats.crc_errors == 3  # the fake sync, the corrupted frame, the truncated one
    assert whole.stats.lost == 2 and whole.stats.frames == 10
    assert infos == [pkg.DeviceInfo("my,name", "0123456789abcdef", 0, 2, 0, 2, body.decode())]
    by_seq = {f["seq"]: f for f in frames}
    for s in samples:
        f = by_seq[s.seq]
        assert (s.t_us, s.status, s.counts, s.temperature_raw) == (f["t_us"], f["status"], f["counts"], f["t_raw"])
        if s.chip_error:  # no reading from the chip: no force, field or temperature, whatever the frame carries
            assert all(math.isnan(x) for x in s.force_N + s.B_uT) and s.temperature_C is None
            assert s.fault == (f["t_raw"] or None)  # bytes 15..16 of an error frame: the fault word
        else:
            # an axis at full scale: the field stands, the force is none (a clipped field is no force)
            expected = (math.nan,) * 3 if f["status"] & 0x04 else tuple(f32(x) for x in f["forces"])
            assert all(a == b or (math.isnan(a) and math.isnan(b)) for a, b in zip(s.force_N, expected))
            assert s.B_uT == (f["counts"][0] * 3.004, f["counts"][1] * 3.004, f["counts"][2] * 4.84)
            assert s.temperature_C == pytest.approx(25 + (f["t_raw"] - 46244) / 45.2)
    assert sum(s.chip_error for s in samples) == 4  # statuses 2, 7, 10, 11 (3 and 6 are the broken frames)
    assert whole.stats.skipped_bytes == len(stream) - 10 * 31 - len(info) - 1  # the last byte may start a frame
    assert pkg.decode_frames(stream) == items


def checked(body: bytes, end: bytes = b"\n") -> bytes:
    """A text or info line with its checksum (docs/bundle.md section 3), computed by the tests' own CRC."""
    return body + b"*%04X" % ref_crc(body) + end


def test_text_lines_bad_lines_and_chip_errors(pkg):
    text = (checked(b"F,7,1000,0,0.1234,-0.5000,2.0000,60.08,-3.00,29824.08,25.02", b"\r\n")
            + checked(b"F,8,2712,2,nan,nan,nan,nan,nan,nan,nan,518")  # the fault: chip reset (6) at start (2)
            + checked(b"F,9,4424,1,1.0,2.0")  # too few fields
            + b"F,10,5000,0,0.0000,0.0000,1.5000,0.00,0.00,15000.00,24.98\n"  # no checksum
            + checked(b"F,11,5500,0,0.0000,0.0000,1.5000,0.00,0.00,15000.00,24.98")[:-3] + b"00\n"  # a wrong one
            + checked(b"F,12,6136,0,0.0000,0.0000,1.5000,0.00,0.00,15000.00,24.98"))
    decoder = pkg.Decoder()
    samples = decoder.feed(text)
    assert [s.seq for s in samples] == [7, 8, 12]
    assert samples[0].force_N == (0.1234, -0.5, 2.0) and samples[0].B_uT == (60.08, -3.0, 29824.08)
    assert samples[0].temperature_C == 25.02 and samples[0].source == "text"
    assert samples[1].chip_error and all(math.isnan(f) for f in samples[1].force_N)
    assert samples[1].fault == 518 and samples[1].fault_name == "chip reset at start"
    assert decoder.stats.bad_lines == 3 and decoder.stats.lost == 3
    line = pkg.encode_text_line(7, 1000, 0, (0.12344, -0.5, 2.0), (60.08, -3.0, 29824.08), 25.02)
    assert line == checked(b"F,7,1000,0,0.1234,-0.5000,2.0000,60.08,-3.00,29824.08,25.02")


# --- the simulated board ------------------------------------------------------------------------------------

def test_simulated_board_sends_the_firmware_format_and_the_embedded_calibration(pkg, calibration):
    sim = pkg.SimulatedDevice(realtime=False, chunk=300, text=False)
    frames = []
    while len(frames) < 3000:
        frames += ref_decode(sim.read(10**6))
    build = sys.modules["magfab_readout._build"]
    lsb = (build.LSB_XY_UT, build.LSB_XY_UT, build.LSB_Z_UT)
    Fz_seen = []
    for k, f in enumerate(frames):
        assert f["seq"] == k & 0xFF and f["t_us"] == k * round(1e6 / build.SAMPLE_RATE_HZ)
        B = tuple(c * s for c, s in zip(f["counts"], lsb))
        want = ref_forces(calibration, *B)
        assert f["forces"] == pytest.approx(tuple(f32(w) for w in want), rel=1.2e-7, abs=1e-12)
        Br = math.hypot(B[0], B[1])
        if ref_distance_to_hull(calibration, B[2], Br) > 1.0:
            assert bool(f["status"] & 1) == (not ref_inside(calibration, B[2], Br))
        Fz_seen.append(want[2])
    assert max(Fz_seen) - min(Fz_seen) > 1.0  # it presses
    assert sum(f["status"] & 1 for f in frames) < 0.05 * len(frames)  # and mostly within the region


THERMAL = {"reference_C": 25.0, "source": "recipe", "coefficient_per_C": {"Bx_uT": -0.0012, "By_uT": -0.0012,
                                                                          "Bz_uT": -0.0012}}


def test_a_warming_simulated_board_and_its_thermal_calibration(pkg, calibration):
    """A 15 C warm-up on the simulated board whose field follows the magnet's -0.12 %/C: with the calibration's
    ``thermal`` the forces it sends are the float64 evaluation at the field corrected with the temperature read
    (what the firmware sends; ``cross_check`` recomputes them to 0) and stay where they were at 25 C; the same
    board under a calibration without ``thermal`` drifts. ``upload`` of the calibration writes a version-4 record
    the board accepts."""
    simulate = sys.modules["magfab_readout.simulate"]
    warm = pkg.Calibration({**calibration, "thermal": THERMAL})
    ramp = simulate.TemperatureRamp(25.0, 40.0, duration_s=0.6, delay_s=0.1)
    build = sys.modules["magfab_readout._build"]
    lsb = (build.LSB_XY_UT, build.LSB_XY_UT, build.LSB_Z_UT)

    def run(cal, **kw):
        sim = pkg.SimulatedDevice(cal, realtime=False, chunk=400, text=False, noise_lsb=0.0, temperature=ramp,
                                  pattern=pkg.RestTip(20000.0), **kw)
        return pkg.Decoder().feed(sim.read(10**6))

    samples = run(warm)
    assert samples[-1].temperature_C == pytest.approx(40.0, abs=0.05)
    for s in samples[::23]:
        t = s.temperature_C
        want = ref_forces(calibration, *(c * q / (1 - 0.0012 * (t - 25.0)) for c, q in zip(s.counts, lsb)))
        assert s.force_N == pytest.approx(tuple(f32(w) for w in want), rel=1e-6, abs=1e-7)
        assert pkg.cross_check(s, warm) < 1e-6
    first, last = samples[0].force_N[2], samples[-1].force_N[2]
    assert abs(last - first) < 2e-3  # the field's quantisation, not the 1.8 % drift
    bare = run(pkg.Calibration(calibration), thermal_per_C=-0.0012)
    assert abs(bare[-1].force_N[2] - bare[0].force_N[2]) > 20 * abs(last - first) + 1e-3
    record = pkg.device.calibration_record({**calibration, "thermal": THERMAL})
    assert record[2] == 4 and len(record) == len(pkg.device.calibration_record(calibration)) + 16
    ee = sys.modules["magfab_readout.eeprom"]
    assert ee.check(record) and ee.thermal(record) == pytest.approx((25.0, -0.0012, -0.0012, -0.0012))


def test_simulated_text_mode_and_commands(pkg):
    sim = pkg.SimulatedDevice(realtime=False, chunk=5, text=False)
    sim.write(b"t")
    lines = sim.read(10**6).decode().splitlines()
    assert len(lines) == 5 and all(line.startswith("F,") and line.count(",") == 10 for line in lines)
    assert all(checked(line.encode()[:-5], b"") == line.encode() for line in lines)
    sim.write(b"i")
    assert sim.read(10**6).startswith(b"I,magfab,magone," + pkg.Calibration.embedded().short_hash.encode())
    sim.write(b"b")
    assert len(ref_decode(sim.read(10**6))) == 5


def test_zero_subtracts_the_mean_force_at_rest(pkg):
    reference = pkg.Decoder().feed(pkg.SimulatedDevice(realtime=False, chunk=300, text=False).read(10**6))
    with pkg.Device(transport=pkg.SimulatedDevice(realtime=False, chunk=300, text=False)) as device:
        offset = device.zero(100)
        assert offset == pytest.approx(tuple(sum(s.force_N[a] for s in reference[:100]) / 100 for a in range(3)))
        later = device.read(50)
    for sample, ref in zip(later, reference[100:150]):
        assert sample.device_force_N == ref.force_N
        assert sample.force_N == tuple(f - o for f, o in zip(ref.force_N, offset))
    assert max(abs(f) for s in later for f in s.force_N) < 0.05  # still at rest: about zero
    assert later[1].time_s - later[0].time_s == pytest.approx(1.84e-3, rel=1e-3)  # the datasheet table's T+X+Y+Z


def test_the_simulated_board_reads_zero_at_rest_without_a_tare(pkg, calibration):
    assert_reads_zero_at_rest(pkg, calibration)
    shifted = json.loads(json.dumps(calibration))  # Fz = 0 inside the region, not at its edge
    shifted["coefficients"]["Fz_N"][0] -= 0.5
    assert_reads_zero_at_rest(pkg, shifted)


# --- errors a user meets --------------------------------------------------------------------------------------

class Silent:
    """A port where nothing (or only noise) arrives."""

    port = "the test port"

    def __init__(self, noise=b""):
        self.noise = noise

    def read(self, size=4096, timeout_s=0.05):
        import time
        time.sleep(min(timeout_s, 0.01))
        return self.noise

    def write(self, data):
        return len(data)

    def close(self):
        pass


def test_device_errors_say_what_to_do(pkg):
    with pytest.raises(pkg.NoData, match=r"no frames from the test port within 0\.2 s; nothing arrived"):
        pkg.Device(transport=Silent(), timeout_s=0.2).read(1)
    with pytest.raises(pkg.NoData, match="none formed a frame or line: check that the baud rate"):
        pkg.Device(transport=Silent(bytes(range(0, 200, 7))), timeout_s=0.2).read(1)
    with pytest.raises(pkg.NoData, match="no info line"):
        pkg.Device(transport=Silent(), timeout_s=0.2).info()
    noisy = pkg.SimulatedDevice(realtime=False, corrupt_fraction=0.3, text=False)
    with pytest.raises(pkg.CrcErrorRate, match=r"failed their CRC \(\d+ %, the limit is 5 %\): check that the baud"):
        pkg.Device(transport=noisy).read(1000)
    mild = pkg.SimulatedDevice(realtime=False, corrupt_fraction=0.01, text=False)
    with pkg.Device(transport=mild) as device:
        assert len(device.read(1000)) == 1000 and 0 < device.stats.crc_errors < 30
    other = pkg.SimulatedDevice(realtime=False, calibration_hash="0123456789abcdef")
    with pkg.Device(transport=other) as device:
        info = device.info()
        with pytest.raises(pkg.CalibrationMismatch, match="runs calibration 0123456789abcdef .* embeds "
                           + pkg.Calibration.embedded().short_hash):
            device.check_info(info)
    chip_errors = pkg.SimulatedDevice(realtime=False, chip_error_every=10, text=False)
    with pkg.Device(transport=chip_errors) as device:
        samples = device.read(40)
    assert [s.seq for s in samples if s.chip_error] == [9, 19, 29, 39]
    assert [s.seq for s in samples if s.recovered] == [10, 20, 30]
    assert all(math.isnan(f) for s in samples if s.chip_error for f in s.force_N)


def test_missing_port_is_named(pkg):
    try:
        import serial  # noqa: F401 - imported only to learn whether pyserial is installed
    except ImportError:
        with pytest.raises(pkg.DeviceError, match="pyserial is not installed"):
            pkg.Device("/dev/does-not-exist")
        return
    with pytest.raises(pkg.PortNotFound, match="serial port '/dev/does-not-exist' not found"):
        pkg.Device("/dev/does-not-exist")


def test_the_port_defaults_to_MAGFAB_READOUT_PORT(pkg, monkeypatch):
    device = sys.modules["magfab_readout.device"]
    monkeypatch.setenv("MAGFAB_READOUT_PORT", "/dev/ttyACM7")
    assert device.default_port() == "/dev/ttyACM7"
    monkeypatch.setenv("MAGFAB_READOUT_PORT", " ")  # set but empty: the one USB serial port present
    monkeypatch.setattr(device, "find_port", lambda: "/dev/ttyUSB3")
    assert device.default_port() == "/dev/ttyUSB3"
    monkeypatch.delenv("MAGFAB_READOUT_PORT")
    assert device.default_port() == "/dev/ttyUSB3"


def test_the_board_is_found_by_its_usb_id_among_other_serial_ports(pkg, monkeypatch):
    """Among several USB serial ports (a USB-serial adapter, a modem), the one with a readout board's USB ID (the
    RP2040 image's 2E8A:000A, an Uno's 2341:0043) is the board's; two boards, or several ports and no board, are
    named and refused; a single USB port is taken whatever its ID (a Nano's bridge chip)."""
    device = sys.modules["magfab_readout.device"]
    monkeypatch.setattr(device, "_import_serial", lambda: None)  # the ports below stand for pyserial's list

    def port(name: str, vid, pid, description: str = "n/a"):
        return types.SimpleNamespace(device=name, vid=vid, pid=pid, description=description)

    adapter, rp, uno = port("/dev/ttyUSB0", 0x0403, 0x6001), port("/dev/ttyACM1", 0x2E8A, 0x000A), port(
        "/dev/ttyACM0", 0x2341, 0x0043)
    serial_port = port("/dev/ttyS0", None, None)
    for ports, found in (([adapter, rp, serial_port], "/dev/ttyACM1"), ([uno, adapter], "/dev/ttyACM0"),
                         ([adapter], "/dev/ttyUSB0")):
        monkeypatch.setattr(device, "_ports", lambda ports=ports: ports)
        assert device.find_port() == found
    for ports in ([rp, uno], [adapter, port("/dev/ttyUSB1", 0x1A86, 0x7523)]):
        monkeypatch.setattr(device, "_ports", lambda ports=ports: ports)
        with pytest.raises(pkg.PortNotFound, match="several USB serial ports"):
            device.find_port()
    rp.description, rp.serial_number = "magfab RP2040 readout", "E4630C7D2B4F3F29"  # the serial tells boards apart
    monkeypatch.setattr(device, "_ports", lambda: [rp, uno])
    with pytest.raises(pkg.PortNotFound, match=r"/dev/ttyACM1 \(magfab RP2040 readout, serial E4630C7D2B4F3F29\)"):
        device.find_port()


# --- the installed command line -----------------------------------------------------------------------------

def _rows(stdout: str) -> list:
    return [line.split() for line in stdout.splitlines() if line and not line.startswith("#")]


def test_installed_cli_streams_zeroes_and_checks(installed):
    proc = cli(installed, "stream", "--simulate", "--count", "60", "--zero", "100", "--raw", "--check")
    assert proc.returncode == 0, proc.stderr
    header = [line for line in proc.stdout.splitlines() if line.startswith("# t_s")]
    assert header == ["# t_s seq Fx_N Fy_N Fz_N Bx_uT By_uT Bz_uT T_C flags fault Bx_lsb By_lsb Bz_lsb T_raw dF_N"]
    rows = _rows(proc.stdout)
    assert len(rows) == 60 and all(len(r) == 16 for r in rows) and {r[10] for r in rows} == {"-"}
    assert max(abs(float(x)) for r in rows for x in r[2:5]) < 0.05  # tared at rest
    assert max(float(r[15]) for r in rows) < 1e-5  # host and "firmware" agree (float32)
    assert "# zero: offset" in proc.stdout and "0 CRC errors" in proc.stderr
    # the rate the stream had, from the frames' device time, against the chip's (the simulated board keeps it)
    rate = re.search(r"60 samples; ([0-9.]+) frames/s over ([0-9.]+) s of device time, against the chip's "
                     r"([0-9.]+) conversions/s \(([0-9.]+)%\)", proc.stderr)
    assert rate, proc.stderr
    chip = float(rate[3])
    assert float(rate[1]) == pytest.approx(chip, rel=0.01) and float(rate[2]) == pytest.approx(59 / chip, rel=0.02)
    # beside it, what the shipped image delivered at the busiest field on the real-timed simulated bus (build.json)
    image = re.search(r"the image delivered ([0-9]+) frames/s at the busiest field of its calibrated", proc.stderr)
    assert image and int(image[1]) == round(measured_rate()["worst"]["rate_Hz"]), proc.stderr


def test_pip_install_leaves_the_folder_as_it_was(installed):
    """``pip install ./readout`` from the folder holding it: no readout/build/, no *.egg-info."""
    assert installed.after == installed.before
    assert [p for p, _ in installed.after if p.endswith(".egg-info") or p == "readout/build"] == []


def test_installed_cli_streams_zero_at_rest_without_a_tare(installed, calibration):
    proc = cli(installed, "stream", "--simulate", "--count", "300")
    assert proc.returncode == 0, proc.stderr
    rows = _rows(proc.stdout)
    mean = [sum(float(r[k]) for r in rows) / len(rows) for k in (2, 3, 4)]
    bound = [calibration["errors"][key]["rms_holdout"] for key in ("Fr_N", "Fr_N", "Fz_N")]
    assert len(rows) == 300 and all(abs(m) < b for m, b in zip(mean, bound)), (mean, bound)


def test_installed_cli_records_a_scan_csv(installed, calibration, tmp_path):
    """``record`` writes the field and the sensor's own forces under ``F*_sensor_N`` (never the reference's
    ``F*_N`` a calibration fits to), with the device's time and the host's."""
    out = tmp_path / "scan.csv"
    started = time.time()
    proc = cli(installed, "record", out, "--seconds", "0.4", "--simulate")
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    comments = [line for line in text.splitlines() if line.startswith("#")]
    assert '# spec: "magone"' in comments
    assert f"# calibration_sha256: {calibration_sha256(calibration)}" in comments
    rows = list(csv.DictReader(io.StringIO("\n".join(line for line in text.splitlines() if not line.startswith("#")))))
    sensor = ("Fx_sensor_N", "Fy_sensor_N", "Fz_sensor_N")
    field = ("time_s", "host_time_s", "Bx_uT", "By_uT", "Bz_uT", "temperature_C")
    assert set(field + sensor) <= set(rows[0]) and not {"Fx_N", "Fy_N", "Fz_N"} & set(rows[0])
    assert 0.4 * 543.5 * 0.9 < len(rows) < 0.4 * 543.5 * 1.1  # 1 / 1.84 ms
    times = [float(r["time_s"]) for r in rows]
    assert times[0] == 0.0 and all(b >= a for a, b in itertools.pairwise(times))
    host = [float(r["host_time_s"]) for r in rows]
    assert started <= host[0] <= host[-1] <= time.time()
    for r in rows:
        assert all(math.isfinite(float(r[c])) for c in field + sensor)
        want = ref_forces(calibration, float(r["Bx_uT"]), float(r["By_uT"]), float(r["Bz_uT"]))
        got = tuple(float(r[c]) for c in sensor)
        assert all(abs(g - w) <= 1e-6 + 1e-6 * abs(w) for g, w in zip(got, want))


def test_installed_cli_info_and_errors(installed):
    proc = cli(installed, "info", "--simulate")
    assert proc.returncode == 0, proc.stderr
    assert "I,magfab,magone," in proc.stdout and "calibration: match" in proc.stdout
    proc = cli(installed, "stream", "--simulate", "--simulate-corrupt", "0.5", "--count", "500")
    assert proc.returncode == 2 and "failed their CRC" in proc.stderr
    proc = cli(installed, "stream", "--port", "/dev/does-not-exist", "--count", "1")
    assert proc.returncode == 2
    assert ("not found" if installed.serial else "pyserial is not installed") in proc.stderr
    proc = cli(installed, "stream", "--simulate", "--text", "--raw")
    assert proc.returncode == 2 and "--raw needs binary frames" in proc.stderr
    for option, value in (("--timeout", "nan"), ("--timeout", "-1"), ("--timeout", "inf"), ("--simulate-corrupt", "2"),
                          ("--simulate-corrupt", "-0.1"), ("--simulate-corrupt", "nan")):
        proc = cli(installed, "stream", "--simulate", "--count", "5", option, value)
        assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1 and option in proc.stderr, proc.stderr


def test_a_bug_of_ours_is_one_line_and_exit_1(pkg, monkeypatch, capsys):
    """Exit 1 is kept for magfab-readout's own bugs (2 for what was given or the bench, 3 for a failed check): an
    exception nobody expected is one line naming it, not a traceback."""
    cli_module = importlib.import_module(pkg.__name__ + ".cli")

    def broken(*_args, **_kwargs):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(cli_module, "_info", broken)
    assert cli_module.main(["info", "--simulate"]) == 1
    err = capsys.readouterr().err
    assert err == "magfab-readout: internal error: ZeroDivisionError: boom (a bug: please report it)\n"


def test_installed_cli_uploads_a_calibration(installed, calibration, tmp_path):
    """``magfab-readout upload [CALIBRATION.json]`` against the simulated board: the package's own calibration,
    then another one (its hash reported back); a file that is not a calibration is refused before anything is
    sent. The firmware's side of the round trip: tests/export/test_simbus.py::test_upload_round_trip."""
    proc = cli(installed, "upload", "--simulate")
    assert proc.returncode == 0, proc.stderr
    assert "read back equal" in proc.stdout and calibration_sha256(calibration)[:16] in proc.stdout
    other = json.loads(json.dumps(calibration))
    other["tare_N"]["Fz_N"] += 0.1
    path = tmp_path / "new.json"
    path.write_text(json.dumps(other))
    proc = cli(installed, "upload", str(path), "--simulate")
    assert proc.returncode == 0 and calibration_sha256(other)[:16] in proc.stdout, proc.stderr
    path.write_text(json.dumps({"format": "magfab-calibration/1"}))
    proc = cli(installed, "upload", str(path), "--simulate")
    assert proc.returncode == 2 and "calibration.json" in proc.stderr


@contextmanager
def pseudo_terminal(pkg, feed: bool):
    """A pty whose far end behaves as the board (the simulated device) when ``feed``; yields the port name."""
    import tty

    master, slave = os.openpty()
    tty.setraw(master)
    os.set_blocking(master, False)
    stop = threading.Event()
    sim = pkg.SimulatedDevice()

    def run():
        while not stop.is_set():
            if select.select([master], [], [], 0.005)[0]:
                with suppress(OSError):
                    sim.write(os.read(master, 256))
            data = sim.read(4096, 0.005)
            with suppress(OSError):  # nobody reads: the data is lost, as on a UART
                os.write(master, data)

    thread = threading.Thread(target=run, daemon=True)
    if feed:
        thread.start()
    try:
        yield os.ttyname(slave)
    finally:
        stop.set()
        if feed:
            thread.join(5)
        os.close(master)
        os.close(slave)


def test_installed_cli_over_a_real_serial_port(installed, pkg):
    if not installed.serial:
        pytest.skip("pyserial could not be installed into the test venv (no package index)")
    proc = cli(installed, "info", port_variable="/dev/magfab-no-such-port")
    assert proc.returncode == 2 and "'/dev/magfab-no-such-port' not found" in proc.stderr
    assert "the port named by MAGFAB_READOUT_PORT" in proc.stderr
    proc = cli(installed, "info", "--port", "/dev/does-not-exist", port_variable="/dev/magfab-no-such-port")
    assert proc.returncode == 2 and "'/dev/does-not-exist' not found" in proc.stderr  # --port comes first
    assert "MAGFAB_READOUT_PORT" not in proc.stderr
    with pseudo_terminal(pkg, feed=False) as port:
        proc = cli(installed, "stream", "--port", port, "--timeout", "0.5", "--count", "1")
        assert proc.returncode == 2 and f"no frames from {port} within 0.5 s; nothing arrived" in proc.stderr
    with pseudo_terminal(pkg, feed=True) as port:
        proc = cli(installed, "info", "--port", port)
        assert proc.returncode == 0 and "calibration: match" in proc.stdout, proc.stderr
        proc = cli(installed, "info", port_variable=port)  # no --port: MAGFAB_READOUT_PORT names it
        assert proc.returncode == 0 and "calibration: match" in proc.stdout, proc.stderr
        proc = cli(installed, "stream", "--port", port, "--count", "30", "--text", "--check")
        assert proc.returncode == 0, proc.stderr
        rows = _rows(proc.stdout)
        assert len(rows) == 30 and max(float(r[11]) for r in rows) < 1e-3  # text rounds the field to 0.01 uT


def _readout_mistakes(cli_module):
    """For every magfab-readout command: an unknown option, its required positionals left out, and each int or
    float option given a word (generated from the parser itself, so a new command or option is covered)."""
    import argparse

    parser = cli_module._parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    yield [], "the following arguments are required"
    for name, command in sorted(sub.choices.items()):
        positionals = [a for a in command._actions if not a.option_strings and a.required and a.nargs != "?"]
        yield [name, *["x"] * len(positionals), "--no-such-option"], "unrecognized arguments"
        if positionals:
            yield [name], "the following arguments are required"
        for action in command._actions:
            if action.option_strings and action.type in (int, float):
                yield [name, *["x"] * len(positionals), action.option_strings[0], "not-a-number"], "invalid"


def test_a_usage_mistake_is_one_line_and_exit_2(pkg, capsys):
    """argparse's own refusals (a usage line and the error before) are one line naming the mistake and the command's
    --help, exit 2, nothing on stdout: generated for every command and every typed option."""
    cli_module = importlib.import_module(pkg.__name__ + ".cli")
    cases = list(_readout_mistakes(cli_module))
    assert len(cases) > 20
    for args, said in cases:
        with pytest.raises(SystemExit) as exit_:
            cli_module.main(args)
        out, err = capsys.readouterr()
        assert exit_.value.code == 2 and out == "", (args, out)
        assert err.count("\n") == 1 and err.startswith("magfab-readout: error: ") and said in err, (args, err)
        assert "--help` lists what is allowed" in err, err


class _Past:
    """A field pattern: at rest, then Bz pushed past the chip's full scale for ``hold_s`` every ``period_s``."""

    def __init__(self, rest, full_uT: float, period_s: float = 0.05, hold_s: float = 0.02) -> None:
        self.rest, self.full, self.period, self.hold = rest, full_uT, period_s, hold_s

    def field(self, t_s: float):
        bx, by, bz = self.rest
        return (bx, by, 1.5 * self.full if (t_s % self.period) < self.hold else bz)


@pytest.mark.parametrize("text", [False, True])
def test_a_field_past_full_scale_gives_no_force_and_names_the_axis(pkg, calibration, text):
    """The simulated board pressed past the chip's full scale: every such sample reaches the Python API with NaN
    forces (after a tare too), its field kept and its fault named; the others carry their forces; zero skips the
    saturated ones."""
    full_z = pkg._build.FULL_SCALE_COUNTS * pkg._build.LSB_Z_UT
    rest = pkg.PressPattern(pkg.Calibration.embedded()).field(0.0)
    sim = pkg.SimulatedDevice(realtime=False, text=text, pattern=_Past(rest, full_z))
    with pkg.Device(transport=sim) as device:
        device.zero(20)
        samples = device.read(400)
    past = [s for s in samples if s.full_scale]
    assert 0.2 * len(samples) < len(past) < 0.6 * len(samples)
    for s in past:
        assert all(math.isnan(f) for f in s.force_N + s.device_force_N) and not s.chip_error
        assert s.B_uT[2] >= 0.99 * full_z and s.fault_name == ("full scale" if text else "full scale on Bz")
        assert math.isnan(pkg.cross_check(s, pkg.Calibration.embedded()))
    assert all(all(math.isfinite(f) for f in s.force_N) and s.fault_name is None for s in samples if not s.full_scale)
