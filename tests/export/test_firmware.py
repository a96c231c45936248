"""The readout firmware: the C core on the host against the simulated MLX90393 (protocol, conversion, forces,
faults and recovery, frames), the escaping of spec strings, the AVR image, the sketch and the flash scripts.

The harness (templates/firmware/host) prints the serial bytes on stdout and one event line per poll on stderr;
see host_main.c for the script commands. Forces are checked against an independent float64 evaluation of the
calibration dict written here from docs/bundle.md.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import _missing, ref_crc16, require_tool

from magfab import derive, load_spec
from magfab.errors import SpecError
from magfab.export import firmware, toolchain
from magfab.formats.calibration_json import CalibrationError
from magfab.spec import Acquisition, Transport

STUBS = Path(__file__).parents[1] / "firmware_sim" / "arduino_stub"
E_NACK, E_BUS, E_TIMEOUT, E_CHIP, E_COUNT, E_RESET, E_MODE, E_VERIFY = -1, -2, -3, -4, -5, -6, -7, -8
OUTSIDE, CHIP_ERROR, SATURATED, RECOVERED = 1, 2, 4, 8
STAGE_READ, STAGE_START, STAGE_EEPROM = 1, 2, 3  # the fault word's high byte (docs/bundle.md section 3)
E_CALIB = -10  # no valid calibration record
WEIRD_NAME = 'we"ird\\name\nwith?? trigraph??= and é'


# ---- calibration and its float64 reference ----------------------------------------------------------------


def make_calibration(order: int = 4, seed: int = 1, n_hull: int = 24) -> dict:
    """A calibration.json dict of the documented shape: random coefficients, an elliptical (convex, CCW) hull."""
    rng = np.random.default_rng(seed)
    monomials = [[i, k - i] for k in range(order + 1) for i in range(k, -1, -1)]
    angles = np.linspace(0.0, 2.0 * np.pi, n_hull, endpoint=False)
    hull = [[float(-3000.0 + 2400.0 * np.cos(a)), float(2000.0 + 1700.0 * np.sin(a))] for a in angles]
    return {
        "format": "magfab-calibration/1", "method": "poly", "order": order, "monomials": monomials,
        "scaling": {"Bz_uT": {"center": -3000.0, "scale": 2400.0}, "Br_uT": {"center": 2000.0, "scale": 1700.0}},
        "coefficients": {"Fz_N": [float(x) for x in rng.normal(0.0, 1.0, len(monomials))],
                         "Fr_N": [float(x) for x in rng.normal(0.0, 0.5, len(monomials))]},
        "shear_sign": -1, "direction_min_uT": 5.0, "tare_N": {"Fz_N": 0.05, "Fr_N": -0.01},
        "valid_region": {"Bz_uT": [-5400.0, -600.0], "Br_uT": [300.0, 3700.0], "hull": hull},
        "errors": {"Fz_N": {"rms_holdout": 0.003, "max_holdout": 0.01, "rms_fit": 0.002}, "folds": 5},
        "scan": {"sha256": "0" * 64, "rows": 100, "source": "simulated"},
    }


def py_terms(cal: dict, force: str, bz: float, br: float) -> tuple[float, float]:
    """Sum of the monomials in float64, and the sum of their magnitudes (the float32 error scale)."""
    s = cal["scaling"]
    u = (bz - s["Bz_uT"]["center"]) / s["Bz_uT"]["scale"]
    v = (br - s["Br_uT"]["center"]) / s["Br_uT"]["scale"]
    terms = [c * u**i * v**j for c, (i, j) in zip(cal["coefficients"][force], cal["monomials"])]
    return sum(terms), sum(abs(t) for t in terms) + abs(cal["tare_N"][force])


def py_forces(cal: dict, bx: float, by: float, bz: float) -> tuple[np.ndarray, np.ndarray]:
    """(Fx, Fy, Fz) in float64 per docs/bundle.md, and the scale of each one's float32 rounding error."""
    br = math.hypot(bx, by)
    fz, sz = py_terms(cal, "Fz_N", bz, br)
    fr, sr = py_terms(cal, "Fr_N", bz, br)
    fz -= cal["tare_N"]["Fz_N"]
    fr -= cal["tare_N"]["Fr_N"]
    if br >= cal["direction_min_uT"] and br > 0:
        k = cal["shear_sign"] * fr / br
        return np.array([k * bx, k * by, fz]), np.array([sr * abs(bx) / br, sr * abs(by) / br, sz])
    return np.array([0.0, 0.0, fz]), np.array([0.0, 0.0, sz])


def py_inside(cal: dict, bz: float, br: float) -> tuple[bool, float]:
    """In the valid region (box and hull), and the distance to its boundary (uT) for skipping edge cases."""
    region = cal["valid_region"]
    (zl, zh), (rl, rh) = region["Bz_uT"], region["Br_uT"]
    hull = region["hull"]
    dist = [bz - zl, zh - bz, br - rl, rh - br]
    for k in range(len(hull)):
        (x0, y0), (x1, y1) = hull[k - 1], hull[k]
        dist.append(((x1 - x0) * (br - y0) - (y1 - y0) * (bz - x0)) / math.hypot(x1 - x0, y1 - y0))
    return min(dist) >= 0, min(abs(d) for d in dist)


def sample_inside(cal: dict, rng: np.random.Generator, n: int) -> list[tuple[float, float, float]]:
    """n field vectors (Bx, By, Bz) in uT whose (Bz, Br) lies in the valid region, random azimuth."""
    out = []
    (zl, zh), (rl, rh) = cal["valid_region"]["Bz_uT"], cal["valid_region"]["Br_uT"]
    while len(out) < n:
        bz, br = rng.uniform(zl, zh), rng.uniform(rl, rh)
        inside, margin = py_inside(cal, bz, br)
        if inside and margin > 20.0:
            phi = rng.uniform(0, 2 * math.pi)
            out.append((br * math.cos(phi), br * math.sin(phi), bz))
    return out


# ---- the serial stream --------------------------------------------------------------------------------------


crc16_ccitt_false = ref_crc16


FRAME = struct.Struct("<BBBBBI3hH3fH")


def parse_stream(data: bytes) -> list[tuple[str, object]]:
    """Binary frames (CRC checked) and text lines (checksum checked and removed: ``body\n``), in order;
    anything else fails the test."""
    out: list[tuple[str, object]] = []
    i = 0
    while i < len(data):
        if data[i:i + 2] == b"\xa5\x5a":
            assert i + 31 <= len(data), "truncated frame"
            _s0, _s1, kind, seq, status, t, bx, by, bz, traw, fx, fy, fz, crc = FRAME.unpack_from(data, i)
            assert kind == 0x01
            assert crc == crc16_ccitt_false(data[i + 2:i + 29]), "CRC mismatch"
            out.append(("frame", {"seq": seq, "status": status, "t_us": t, "counts": (bx, by, bz), "t_raw": traw,
                                  "forces": np.array([fx, fy, fz], dtype=np.float64)}))
            i += 31
        else:
            end = data.index(b"\n", i)
            body, star, checksum = data[i:end].rpartition(b"*")
            assert star and checksum == b"%04X" % crc16_ccitt_false(body), "checksum mismatch"
            out.append(("line", body + b"\n"))
            i = end + 1
    return out


def frames_of(data: bytes) -> list[dict]:
    items = parse_stream(data)
    assert all(kind == "frame" for kind, _ in items), items
    return [f for _, f in items]


# ---- building and running the harness ----------------------------------------------------------------------


def spec_variant(name: str = "magone", **changes):
    """The MagOne spec with changes in (section, key) = value form, e.g. sensor_resolution=3."""
    spec = load_spec(None).model_copy(update={"name": name})
    for key, value in changes.items():
        section, field = key.split("_", 1)
        part = getattr(spec, section)
        spec = spec.model_copy(update={section: part.model_copy(update={field: value})})
    return spec


class Host:
    """A compiled harness for one spec and calibration."""

    def __init__(self, design, cal: dict, exe: Path, files: dict[str, bytes]) -> None:
        self.design, self.cal, self.exe, self.files = design, cal, exe, files
        self.chip = firmware.chip_config(design)

    def run(self, script: str, *args: str) -> tuple[bytes, list[list[str]]]:
        proc = subprocess.run([str(self.exe), *args], input=script.encode(), capture_output=True, timeout=60)
        assert proc.returncode == 0, proc.stderr.decode(errors="replace")[-2000:]
        events = [line.split() for line in proc.stderr.decode().splitlines()]
        return proc.stdout, events

    def lsb(self) -> tuple[float, float, float]:
        """uT per count, X Y Z, straight from the recipe (not from firmware.py)."""
        chip, s = self.design.chip, self.design.spec.sensor
        xy = chip[f"sensitivity_xy_gain{s.gain_sel}_uT_per_lsb"].nominal * 2**s.resolution
        return xy, xy, chip[f"sensitivity_z_gain{s.gain_sel}_uT_per_lsb"].nominal * 2**s.resolution


@pytest.fixture(scope="module")
def build_host(tmp_path_factory):
    require_tool("gcc")
    cache: dict[str, Host] = {}

    def build(key: str = "default", spec=None, cal: dict | None = None) -> Host:
        if key not in cache:
            design = derive(spec if spec is not None else spec_variant())
            cal = cal if cal is not None else make_calibration()
            files = firmware.render(design, cal)
            exe = toolchain.build_host(files, tmp_path_factory.mktemp(f"host-{key}"))
            cache[key] = Host(design, cal, exe, files)
        return cache[key]

    return build


@pytest.fixture(scope="module")
def host(build_host) -> Host:
    return build_host()


def polls(events: list[list[str]]) -> list[tuple[int, int, int, int]]:
    """(frame seq, error, lost, virtual time us) of every poll."""
    return [(int(e[1]), int(e[2]), int(e[3]), int(e[4])) for e in events if e[0] == "P"]


# ---- the host build -----------------------------------------------------------------------------------------


def test_host_build_is_strict_c99_and_warning_free(host):
    """build_host compiles with -Werror -pedantic; the core also passes -Wconversion on its own."""
    for flag in ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"):
        assert flag in firmware.HOST_CFLAGS
    assert host.exe.is_file()
    core = host.exe.parent.parent / firmware.CORE_DIR
    proc = subprocess.run(["gcc", *firmware.HOST_CFLAGS, "-Wconversion", "-fsyntax-only", "-I", str(core),
                           *[str(core / s) for s in firmware.CORE_SOURCES]], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_host_makefile_builds_the_same_harness(host, tmp_path):
    """The bundle's host/Makefile (what a user runs) builds a harness that gives the same bytes."""
    make = shutil.which("make")
    if make is None:  # not among the tools .ci/run installs: a plain skip
        pytest.skip("make is not installed")
    toolchain.write_tree(host.files, tmp_path)
    proc = subprocess.run([make, "-C", str(tmp_path / "host"), "CC=gcc"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    script = "B 900 -400 -2800 25\nS 3\nC i\nS 1\n"
    ours = subprocess.run([str(tmp_path / "host" / "magfab_host")], input=script.encode(), capture_output=True)
    assert ours.returncode == 0 and ours.stdout == host.run(script)[0]


def test_render_is_deterministic_and_complete(host):
    again = firmware.render(host.design, host.cal)
    assert again == host.files
    for rel in ("magfab_readout/magfab_readout.ino", "platformio.ini", "avr/main.c", "avr/Makefile", "flash.sh",
                "flash.bat", "host/sim_mlx90393.c", "magfab_readout/src/mf_nv_image.h", firmware.EEP_NAME):
        assert rel in again
    other = firmware.render(host.design, make_calibration(seed=2))
    changed = {rel for rel in again if again[rel] != other[rel]}
    # the calibration lives in EEPROM: the AVR image's sources do not change with it (the host's RAM store
    # starts from the record, mf_nv_image.h); the README states the float32 bound of this calibration
    assert changed == {"magfab_readout/src/mf_nv_image.h", firmware.EEP_NAME, "README.md"}
    assert b"\r\n" in again["flash.bat"] and b"\r\n" not in again["flash.sh"]


# ---- chip protocol ------------------------------------------------------------------------------------------


def test_register_setup_bytes(host):
    """Start-up: EX, RT, NOP, then read-modify-write-verify of registers 0-2 keeping bits the firmware does not
    own, then SB with X, Y, Z and T. The expected words are built here from the spec, bit by bit."""
    _, events = host.run("Q\n", "--log")
    writes = [[int(b, 16) for b in e[2:]] for e in events if e[0] == "W"]
    reads = [[int(b, 16) for b in e[2:]] for e in events if e[0] == "R" and e[1].endswith(":")]
    assert [w[0] for w in writes[:3]] == [0x80, 0xF0, 0x00]
    s = host.design.spec.sensor
    res = s.resolution
    expected = {
        0: (0x01FF, 0xC | s.gain_sel << 4),
        1: (0x1FFF, 0b1111 << 6),  # BURST_SEL zyxt, BURST_DATA_RATE 0, TCMP_EN 0
        2: (0x1FFF, s.osr | s.dig_filt << 2 | res << 5 | res << 7 | res << 9),
    }
    wr = [w for w in writes if w[0] == 0x60]
    assert [w[3] >> 2 for w in wr] == [0, 1, 2]
    rr_replies = [r for w, r in zip(writes, reads) if w[0] == 0x50]
    defaults = {}
    for w, r in zip(writes, reads):
        if w[0] == 0x50 and (w[1] >> 2) not in defaults:
            defaults[w[1] >> 2] = r[1] << 8 | r[2]
    assert defaults == {0: 0x047C, 1: 0x6000, 2: 0x0000}  # the simulated chip's power-on words
    for w in wr:
        reg, value = w[3] >> 2, w[1] << 8 | w[2]
        mask, fields = expected[reg]
        assert value == (defaults[reg] & ~mask & 0xFFFF) | fields, (reg, hex(value))
    assert len(rr_replies) == 6  # each register read before and after its write
    assert writes[len(writes) - 1] == [0x1F]  # SB with z, y, x, t
    regs = {int(e[1]): int(e[2]) for e in events if e[0] == "R" and not e[1].endswith(":")}
    assert regs == {w[3] >> 2: w[1] << 8 | w[2] for w in wr}
    assert ["M", "1"] in events  # burst mode


def test_single_mode_and_no_temperature(build_host):
    """Single measurements without T: no SB, one SM 0x3E then RM 0x4E per sample, BURST_SEL = zyx."""
    h = build_host("single", spec_variant(firmware_acquisition=Acquisition.SINGLE, firmware_temperature=False))
    out, events = h.run("B 800 -300 -2500 40\nS 3\n", "--log")
    writes = [[int(b, 16) for b in e[2:]] for e in events if e[0] == "W"]
    assert not any(w[0] & 0xF0 == 0x10 for w in writes)
    commands = [w[0] for w in writes if w[0] in (0x3E, 0x4E)]
    assert commands == [0x3E, 0x4E] * 3
    wr1 = next(w for w in writes if w[0] == 0x60 and w[3] >> 2 == 1)
    assert ((wr1[1] << 8 | wr1[2]) >> 6) & 0xF == 0b1110
    frames = frames_of(out)
    assert [f["status"] for f in frames] == [0, 0, 0]
    assert all(f["t_raw"] == 0 for f in frames)
    period = np.diff([f["t_us"] for f in frames])
    wait = h.chip.tconv_us + h.chip.read_margin_us
    assert np.all(period >= wait) and np.all(period < wait + 400)


@pytest.mark.parametrize("res", [0, 1, 2, 3])
def test_raw_counts_to_microtesla(build_host, res):
    """Raw words -> counts (RES 2/3 offsets 32768 / 16384 removed, RES 0/1 two's complement) -> uT with the
    recipe's sensitivity x 2^RES; the saturation flag at the output limit; then the simulated chip end to end."""
    h = build_host(f"res{res}", spec_variant(sensor_resolution=res))
    zero = {0: 0, 1: 0, 2: 32768, 3: 16384}[res]
    limit = {0: 32767, 1: 32767, 2: 22000, 3: 11000}[res]
    counts = [0, 1, -1, 1234, -4321, limit - 1, -(limit - 1), limit, -limit]
    word = [(c & 0xFFFF) if res < 2 else zero + c for c in counts]
    script = "".join(f"U 46244 {word[k]} {word[k + 1]} {word[k + 2]}\n" for k in range(0, len(counts) - 2))
    _, events = h.run(script)
    lsb = h.lsb()
    rows = [e for e in events if e[0] == "U"]
    assert len(rows) == len(counts) - 2
    for k, row in enumerate(rows):
        c = counts[k:k + 3]
        assert [int(v) for v in row[2:5]] == c
        for axis in range(3):
            want32 = np.float32(np.float32(c[axis]) * np.float32(lsb[axis]))
            assert np.float32(float(row[5 + axis])) == want32
            assert math.isclose(float(row[5 + axis]), c[axis] * lsb[axis], rel_tol=1e-6, abs_tol=1e-9)
        assert (int(row[1]) & SATURATED) == (SATURATED if any(abs(x) >= limit for x in c) else 0)
        assert math.isclose(float(row[8]), 25.0, abs_tol=1e-6)
    if res < 2:  # words that are negative only as two's complement
        _, events = h.run("U 46696 32768 65535 32767\n")
        row = next(e for e in events if e[0] == "U")
        assert [int(v) for v in row[2:5]] == [-32768, -1, 32767] and int(row[1]) & SATURATED
        assert math.isclose(float(row[8]), 35.0, abs_tol=1e-4)
    # through the simulated chip: the counts in the frames are the field over the recipe's LSB
    field = (0.9 * limit * lsb[0], -1234.5, -0.5 * limit * lsb[2])
    out, _ = h.run(f"B {field[0]} {field[1]} {field[2]} 25\nS 2\n")
    frame = frames_of(out)[-1]
    assert list(frame["counts"]) == [round(b / per_count) for b, per_count in zip(field, lsb)]
    assert frame["status"] & SATURATED == 0


def test_forces_equal_python_float64(host):
    """Simulated chip -> core -> binary frames: forces within 1e-4 of a float64 evaluation of the same dict, both
    through the serial frames and directly from raw words over many points."""
    rng = np.random.default_rng(7)
    fields = sample_inside(host.cal, rng, 40)
    script = "".join(f"B {bx:.3f} {by:.3f} {bz:.3f} 30\nS 1\n" for bx, by, bz in fields)
    out, events = host.run(script)
    frames = frames_of(out)
    assert len(frames) == len(fields)
    lsb = host.lsb()
    worst = 0.0
    for frame in frames:
        b = [c * per_count for c, per_count in zip(frame["counts"], lsb)]
        want, scale = py_forces(host.cal, *b)
        err = np.abs(frame["forces"] - want) / np.maximum(np.abs(want), scale)
        worst = max(worst, float(err.max()))
        assert frame["status"] == 0
    assert worst < 1e-4, worst
    # many more points straight from raw words (no bus), inside and outside the region
    (zl, zh), (_rl, rh) = host.cal["valid_region"]["Bz_uT"], host.cal["valid_region"]["Br_uT"]
    words, wanted = [], []
    for _ in range(400):
        bz, br, phi = rng.uniform(zl - 500, zh + 500), rng.uniform(0, rh + 500), rng.uniform(0, 2 * math.pi)
        w = firmware.raw_words(host.chip, (br * math.cos(phi), br * math.sin(phi), bz))
        c = [(x - 65536 if x >= 32768 else x) if host.chip.raw_signed else x - host.chip.raw_zero for x in w[1:]]
        words.append(w)
        wanted.append((py_forces(host.cal, *(ci * li for ci, li in zip(c, lsb))),
                       py_inside(host.cal, c[2] * lsb[2], math.hypot(c[0] * lsb[0], c[1] * lsb[1]))))
    _, events = host.run("".join("G {} {} {} {}\n".format(*w) for w in words))
    rows = [e for e in events if e[0] == "G"]
    outside_seen = 0
    for row, ((want, scale), (inside, margin)) in zip(rows, wanted):
        got = np.array([float(x) for x in row[2:5]])
        assert np.all(np.abs(got - want) <= 1e-4 * np.maximum(np.abs(want), scale)), (got, want)
        if margin > 1e-2:
            assert bool(int(row[1]) & OUTSIDE) == (not inside)
        outside_seen += not inside
    assert 50 < outside_seen < 350


def test_the_thermal_correction_equals_python_float64(build_host):
    """A calibration with ``thermal`` (a per axis, T0 25 C): at 40 C the core's forces are the float64 evaluation at
    the field divided by (1 + a (T - T0)), T the temperature word read back; far from the uncorrected ones."""
    cal = {**make_calibration(), "thermal": {"reference_C": 25.0, "source": "recipe",
                                             "coefficient_per_C": {"Bx_uT": -0.0012, "By_uT": -0.0015,
                                                                   "Bz_uT": -0.002}}}
    h = build_host("thermal", spec_variant(), cal)
    assert firmware.eeprom_record(h.design, cal)[2] == 4
    fields = sample_inside(cal, np.random.default_rng(11), 20)
    out, _ = h.run("".join(f"B {bx:.3f} {by:.3f} {bz:.3f} 40\nS 1\n" for bx, by, bz in fields))
    frames = frames_of(out)
    assert len(frames) == len(fields)
    a = (-0.0012, -0.0015, -0.002)
    moved = 0.0
    for frame in frames:
        t = 25.0 + (frame["t_raw"] - firmware.TEMPERATURE_RAW_25C) / firmware.TEMPERATURE_LSB_PER_C
        assert t == pytest.approx(40.0, abs=0.02)
        b = [c * q for c, q in zip(frame["counts"], h.lsb())]
        want, scale = py_forces(cal, *(x / (1 + k * (t - 25.0)) for x, k in zip(b, a)))
        assert np.all(np.abs(frame["forces"] - want) <= 1e-4 * np.maximum(np.abs(want), scale)), (frame, want)
        moved = max(moved, float(np.max(np.abs(py_forces(cal, *b)[0] - want))))
    assert moved > 1e-3  # the correction is not a rounding: at least a millinewton somewhere


def test_out_of_region_flag(host):
    """Readings outside the box, or inside the box but outside the hull, are flagged; forces still come."""
    region = host.cal["valid_region"]
    (zl, zh), (rl, _rh) = region["Bz_uT"], region["Br_uT"]
    corner = (zl + 50.0, rl + 50.0)  # in the box, outside the elliptical hull
    assert py_inside(host.cal, *corner)[0] is False
    centre = (-3000.0, 2000.0)
    script = ""
    for bz, br in (centre, corner, (zh + 800.0, 2000.0), (-3000.0, 0.0)):
        script += f"B {br / math.sqrt(2):.3f} {br / math.sqrt(2):.3f} {bz:.3f} 25\nS 1\n"
    frames = frames_of(host.run(script)[0])
    assert [f["status"] & OUTSIDE for f in frames] == [0, OUTSIDE, OUTSIDE, OUTSIDE]
    assert all(np.all(np.isfinite(f["forces"])) for f in frames)
    assert frames[3]["forces"][0] == 0.0 and frames[3]["forces"][1] == 0.0  # Br = 0: no shear direction


# ---- faults and recovery ------------------------------------------------------------------------------------


@pytest.mark.parametrize("fault, code", [
    ("nack", E_NACK), ("error 2", E_CHIP), ("short", E_COUNT), ("trunc", E_COUNT), ("timeout", E_TIMEOUT),
    ("stuck", E_CHIP), ("reset", E_RESET),
])
def test_fault_gives_error_frame_then_recovery(host, fault, code):
    """Each injected fault: that sample's error code, the chip-error flag, NaN forces and zero counts; then a
    reset and re-configuration, and the next frame is good again with the recovered flag. (A single taxel's read
    rejected with the ERROR bit is retried once, so the ERROR fault is injected twice.)"""
    out, events = host.run(f"B 900 -400 -2800 25\nS 3\nF {fault}\nS 1\nS 3\nQ\n")
    frames, p = frames_of(out), polls(events)
    assert [e for _, e, _, _ in p] == [0, 0, 0, code, 0, 0, 0]
    good, bad, after = frames[2], frames[3], frames[4]
    assert bad["status"] & CHIP_ERROR and np.all(np.isnan(bad["forces"])) and bad["counts"] == (0, 0, 0)
    assert bad["t_raw"] == STAGE_READ << 8 | -code  # an error frame carries its fault word
    assert after["status"] == RECOVERED
    np.testing.assert_array_equal(after["forces"], good["forces"])
    assert frames[5]["status"] == 0
    regs = {int(e[1]): int(e[2]) for e in events if e[0] == "R"}
    s = host.design.spec.sensor
    assert regs[2] & 0x1FFF == s.osr | s.dig_filt << 2 | s.resolution * (1 << 5 | 1 << 7 | 1 << 9)  # re-configured
    assert [f["seq"] for f in frames] == list(range(len(frames)))


def test_lost_chip_retries_then_recovers(host):
    """A chip that stops answering: error frames at the bounded retry rate while recovery fails, never a force;
    recovery as soon as it answers again."""
    out, events = host.run("B 900 -400 -2800 25\nS 2\nF nack 40\nS 8\n")
    frames, p = frames_of(out), polls(events)
    lost = [x for x in p if x[2] == 1]
    assert len(lost) >= 3
    assert all(f["status"] & CHIP_ERROR and np.all(np.isnan(f["forces"])) for f in frames[2:2 + len(lost)])
    assert [f["t_raw"] for f in frames[2:2 + len(lost)]] == [STAGE_READ << 8 | -E_NACK] + [
        STAGE_START << 8 | -E_NACK] * (len(lost) - 1)
    gaps = np.diff([f["t_us"] for f in frames[3:2 + len(lost)]])
    assert np.all(gaps >= firmware.LOST_RETRY_US)
    back = frames[2 + len(lost):]
    assert back and back[0]["status"] == RECOVERED and np.all(np.isfinite(back[0]["forces"]))
    assert all(f["status"] == 0 for f in back[1:])


def test_burst_pace_is_the_datasheet_conversion_time(host):
    """Burst frames come exactly one conversion apart, the datasheet table's 1.84 ms for MagOne's T+X+Y+Z at OSR 0,
    DIG_FILT 2 (the Table 8 formula would say 1.712 ms): a fixed grid, so no read is lost to drift. The simulated
    chip rejects a read before its conversion is done: a chip slower than the table needs retries (the safety
    net, each a quarter-conversion later, re-anchoring the grid) but still no error; one twice as slow fails."""
    chip = host.chip
    assert (chip.osr, chip.dig_filt, chip.temperature) == (0, 2, True) and chip.tconv_us == 1840
    axis = 67 + 64 * 2**chip.osr * (2 + 2**chip.dig_filt)
    assert chip.tconv_us > math.ceil(3 * axis + (67 + 192) + 100)  # the table is longer than the formula
    retry = math.ceil(chip.tconv_us * firmware.RETRY_FRACTION)
    for scale, retried, errors in ((1.0, False, False), (1.09, True, False), (1.3, True, False), (2.0, None, True)):
        out, events = host.run("B 900 -400 -2800 25\nS 60\n", "--clock-scale", str(scale))
        assert any(e != 0 for _, e, _, _ in polls(events)) is errors, scale
        if retried is not None:  # every read on the grid, or (a slow chip) the odd one retried a quarter later
            late = np.diff([f["t_us"] for f in frames_of(out)]) - chip.tconv_us
            assert set(late[late != 0]) <= set(range(retry, retry + 400)) and bool(np.any(late)) is retried, scale
    assert 1e6 / chip.tconv_us >= 500.0


# ---- output modes ------------------------------------------------------------------------------------------


def test_binary_frames_crc_and_layout(host):
    assert crc16_ccitt_false(b"123456789") == 0x29B1  # the catalogue check value of CRC-16/CCITT-FALSE
    out, _ = host.run("B 900 -400 -2800 25\nS 4\n")
    assert len(out) == 4 * 31
    frames = frames_of(out)
    assert [f["seq"] for f in frames] == [0, 1, 2, 3]
    assert frames[0]["t_raw"] == 46244
    broken = bytearray(out)
    broken[40] ^= 0x01
    with pytest.raises(AssertionError, match="CRC"):
        frames_of(bytes(broken))


def test_text_mode_info_and_switching(host):
    cal = host.cal
    out, _ = host.run("B 900 -400 -2800 31.5\nS 1\nC t\nS 2\nC i\nC b\nS 1\n")
    items = parse_stream(out)
    kinds = [k for k, _ in items]
    assert kinds == ["frame", "line", "line", "line", "frame"]
    sha = hashlib.sha256(json.dumps(cal, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    s = host.design.spec.sensor
    assert items[3][1] == f"I,magfab,magone,{sha[:16]},{s.gain_sel},{s.resolution},{s.osr},{s.dig_filt}\n".encode()
    assert firmware.info_line("magone", sha[:16], host.chip).encode() in out
    binary = items[0][1]
    for k in (1, 2):
        fields = items[k][1].decode().rstrip("\n").split(",")
        assert fields[0] == "F" and int(fields[1]) == k and int(fields[3]) == 0
        forces = [float(x) for x in fields[4:7]]
        assert all(len(x.split(".")[1]) == 4 for x in fields[4:7])
        np.testing.assert_allclose(forces, binary["forces"], atol=5.1e-5)
        lsb = host.lsb()
        np.testing.assert_allclose([float(x) for x in fields[7:10]],
                                   [c * per_count for c, per_count in zip(binary["counts"], lsb)], atol=5.1e-3)
        assert abs(float(fields[10]) - 31.5) < 0.03


def test_text_mode_error_line(host):
    out, _ = host.run("C t\nB 900 -400 -2800 25\nS 1\nF error 2\nS 1\n")
    lines = [x for _, x in parse_stream(out)]
    assert lines[1].decode().split(",")[3:] == ["2", "nan", "nan", "nan", "nan", "nan", "nan", "nan",
                                                f"{STAGE_READ << 8 | -E_CHIP}\n"]  # the fault word ends it


def test_text_lines_carry_a_checksum(host):
    """Every text and info line ends in *XXXX, the CRC-16/CCITT-FALSE of what precedes the
    '*' in upper-case hex; a changed byte fails it."""
    out, _ = host.run("C t\nB 900 -400 -2800 25\nS 3\nC i\nS 1\n")
    lines = out.split(b"\n")[:-1]
    assert len(lines) == 5 and all(re.fullmatch(rb"[FI],.*\*[0-9A-F]{4}", x) for x in lines), lines
    assert len(parse_stream(out)) == 5
    broken = bytearray(out)
    broken[out.index(b",", 10) + 1] ^= 0x01  # a digit of the first line's t_us or status
    with pytest.raises(AssertionError, match="checksum"):
        parse_stream(bytes(broken))


@pytest.mark.parametrize("line", ["K 0", "K nan", "K -1", "K inf", "K 1e300", "K", "B nan 0 0 25",
                                  "B 0 0 1e300 25", "B 0 0 100 inf"])
def test_host_double_refuses_values_outside_its_bands(host, line):
    """K 0, K nan and K -1 were once undefined behaviour in the simulator's arithmetic (the cast of
    an infinite or NaN conversion count); now a value outside its band is a line that cannot be read (exit 2)."""
    proc = subprocess.run([str(host.exe)], input=f"B 900 -400 -2800 25\nS 1\n{line}\nS 2\n".encode(),
                          capture_output=True, timeout=60)
    assert proc.returncode == 2 and f"line 3: cannot read: {line}" in proc.stderr.decode(), proc.stderr
    for bad in ("0", "nan", "-1"):
        usage = subprocess.run([str(host.exe), "--clock-scale", bad], input=b"S 1\n", capture_output=True, timeout=60)
        assert usage.returncode == 2 and b"usage" in usage.stderr


def test_host_double_is_free_of_undefined_behaviour_at_its_band_edges(host, tmp_path):
    """The harness and the core built with UBSan and ASan (aborting on the first report) run the bands' edges."""
    require_tool("gcc")
    toolchain.write_tree(host.files, tmp_path)
    core = tmp_path / firmware.CORE_DIR
    exe = tmp_path / "host" / "magfab_host_san"
    flags = ["-fsanitize=undefined,address,float-cast-overflow,float-divide-by-zero", "-fno-sanitize-recover=all", "-g"]
    proc = subprocess.run(["gcc", *firmware.HOST_CFLAGS, *flags, "-I", str(core), "-I", str(tmp_path / "host"),
                           "-o", str(exe), str(tmp_path / "host" / "host_main.c"),
                           str(tmp_path / "host" / "sim_mlx90393.c"), *[str(core / s) for s in firmware.CORE_SOURCES],
                           "-lm"], capture_output=True, text=True)
    if proc.returncode != 0 and ("sanitizer" in proc.stderr.lower() or "asan" in proc.stderr.lower()):
        pytest.skip("gcc's sanitizer runtimes are not installed")
    assert proc.returncode == 0, proc.stderr
    script = ("B 1e6 -1e6 1e6 250\nS 2\nK 0.01\nS 3\nK 100\nS 3\nB -1e6 0 -1e6 -100\nC t\nS 2\nF stuck\nS 2\n"
              "F reset\nS 2\nK 1\nF timeout 3\nS 4\nC i\nS 1\n")
    run = subprocess.run([str(exe)], input=script.encode(), capture_output=True, timeout=120)
    assert run.returncode == 0, run.stderr.decode(errors="replace")[-2000:]
    assert b"runtime error" not in run.stderr


def test_spec_strings_are_escaped(build_host):
    """A spec name with quotes, backslashes, a newline, '??' trigraphs and non-ASCII compiles warning-free
    and comes out byte for byte in the info line."""
    h = build_host("weird", spec_variant(WEIRD_NAME, firmware_output=Transport.TEXT))
    out, _ = h.run("C i\nS 1\n")
    assert out.startswith(b"I,magfab," + WEIRD_NAME.encode() + b",")
    assert out.count(b"\n") == 3  # the one inside the name, the info line's end, the text frame's end
    for rel, data in h.files.items():
        assert WEIRD_NAME.encode() not in data, rel


# ---- validation -------------------------------------------------------------------------------------------


def test_render_rejects_what_the_firmware_cannot_carry():
    """The format's own rules come from magfab.formats.calibration_json (the one validator); on top, what a
    float32 table and the C code's order limit cannot hold is a FirmwareError. Both name the key path."""
    design = derive(spec_variant())
    cases = {
        "coefficients.Fz_N[3]": lambda c: c["coefficients"]["Fz_N"].__setitem__(3, float("nan")),
        "coefficients.Fr_N": lambda c: c["coefficients"]["Fr_N"].pop(),
        "scaling.Br_uT.scale": lambda c: c["scaling"]["Br_uT"].__setitem__("scale", 0.0),
        "shear_sign": lambda c: c.__setitem__("shear_sign", 0),
        "valid_region.hull": lambda c: c["valid_region"]["hull"].reverse(),
        "monomials": lambda c: c["monomials"].__setitem__(2, [3, 3]),
        "tare_N.Fz_N": lambda c: c["tare_N"].pop("Fz_N"),
        "format": lambda c: c.__setitem__("format", "magfab-calibration/2"),
    }
    for key, spoil in cases.items():
        cal = make_calibration()
        spoil(cal)
        with pytest.raises(CalibrationError, match=re.escape(f"calibration.json: {key} = ")) as info:
            firmware.render(design, cal)
        assert info.value.key == key
    cal = make_calibration()
    hull = cal["valid_region"]["hull"]
    hull.insert(3, [(hull[2][0] + hull[3][0]) / 2 - 400.0, (hull[2][1] + hull[3][1]) / 2 - 400.0])  # a dent
    with pytest.raises(CalibrationError, match="convex"):
        firmware.render(design, cal)
    cal = make_calibration()
    cal["coefficients"]["Fz_N"][4] = 1e39  # past float32: the validator's bound on the polynomial refuses it first
    with pytest.raises(CalibrationError, match=re.escape("calibration.json: coefficients.Fz_N[4] = 1e+39:")):
        firmware.render(design, cal)
    with pytest.raises(SpecError, match=r"firmware\.baud"):
        firmware.render(derive(spec_variant(firmware_baud=230400)), make_calibration())


def test_hull_with_closing_and_collinear_points(build_host):
    """A closed ring and collinear points are accepted and give the same region as the clean hull."""
    cal = make_calibration(n_hull=8)
    hull = cal["valid_region"]["hull"]
    mid = [(hull[0][0] + hull[1][0]) / 2, (hull[0][1] + hull[1][1]) / 2]
    cal["valid_region"]["hull"] = [hull[0], mid, *hull[1:], hull[0]]
    h = build_host("ring", spec_variant(), cal)
    record = firmware.eeprom_record(h.design, cal)
    assert struct.unpack_from("<H", record, 6)[0] == 8  # the record's hull: the ring and the collinear point gone
    rng = np.random.default_rng(3)
    chip = h.chip
    words, want = [], []
    for _ in range(300):
        bz, br = rng.uniform(-5600, -400), rng.uniform(200, 3900)
        w = firmware.raw_words(chip, (br, 0.0, bz))
        bz32 = (w[3] - chip.raw_zero) * h.lsb()[2]
        br32 = (w[1] - chip.raw_zero) * h.lsb()[0]
        inside, margin = py_inside(make_calibration(n_hull=8), bz32, br32)
        if margin > 1e-2:
            words.append(w)
            want.append(not inside)
    _, events = h.run("".join("G {} {} {} {}\n".format(*w) for w in words))
    got = [bool(int(e[1]) & OUTSIDE) for e in events if e[0] == "G"]
    assert got == want and 30 < sum(want) < len(want) - 30


# ---- AVR, Arduino, flash scripts -----------------------------------------------------------------------------


def require_avr() -> None:
    for tool in ("avr-gcc", "avr-objcopy", "avr-size"):
        require_tool(tool)
    if not Path("/usr/lib/avr/include/avr/io.h").exists() and not shutil.which("avr-libc-config"):
        probe = subprocess.run(["avr-gcc", "-mmcu=atmega328p", "-E", "-x", "c", "-"], input="#include <avr/io.h>\n",
                               capture_output=True, text=True)
        if probe.returncode != 0:
            _missing("avr-libc is not installed (Debian package avr-libc; .ci/run installs it)")


@pytest.fixture(scope="module")
def avr_image(host):
    require_avr()
    result = toolchain.build_hex(host.files)
    assert result is not None
    return result


def test_avr_image_builds_clean_and_fits(avr_image, host, tmp_path):
    image, info = avr_image
    assert info["warnings"] == ""
    lines = image.decode().splitlines()
    assert all(line.startswith(":") for line in lines) and lines[-1] == ":00000001FF"
    assert 2000 < info["flash_bytes"] <= firmware.FLASH_LIMIT_BYTES
    assert 0 < info["ram_bytes"] <= firmware.RAM_LIMIT_BYTES
    if shutil.which("make"):  # the bundle's Makefile makes the same image
        toolchain.write_tree(host.files, tmp_path)
        proc = subprocess.run(["make", "-C", str(tmp_path / "avr")], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        assert (tmp_path / firmware.HEX_NAME).read_bytes() == image


def test_avr_image_runs_under_simavr(avr_image, host, tmp_path):
    """The real ATmega328P image (timer, UART interrupts, TWI driver) in simavr with an erased EEPROM and no
    MLX90393 on its bus: without a record it leaves the chip alone and sends text error lines naming the missing
    calibration (fault word 0x030A) at the bounded rate, never a force."""
    require_tool("simavr")
    elf, warnings = toolchain.build_avr_elf(host.files, tmp_path, "main")
    assert warnings == ""
    uart = toolchain.run_simavr(elf, stop_after_s=1.5)
    lines = [x for x in uart.splitlines() if x.startswith("F,")]
    assert len(lines) >= 3, uart[-2000:]
    rows = [x.rstrip(".").split("*")[0].split(",") for x in lines]
    assert all(r[3] == "2" and r[4:11] == ["nan"] * 7 and r[11] == str(STAGE_EEPROM << 8 | -E_CALIB) for r in rows)
    gaps = np.diff([int(r[2]) for r in rows])
    assert np.all(gaps >= firmware.NO_RECORD_US) and np.all(gaps < firmware.NO_RECORD_US + 2000)


def test_avr_cycles_per_sample_meet_500_hz(host, tmp_path):
    """Cycle counts from simavr (Timer1 at the CPU clock): the whole per-sample computation (counts -> uT ->
    forces with the full hull test -> binary frame) fits in a 500 Hz period at 16 MHz with room to spare."""
    require_avr()
    require_tool("simavr")
    elf, _ = toolchain.build_avr_elf(host.files, tmp_path, "bench")
    uart = toolchain.run_simavr(elf)
    cycles = {(m.group(1), m.group(2)): int(m.group(3)) for m in re.finditer(r"BENCH,(\w+),(\w+),(\d+)", uart)}
    flags = {m.group(1): int(m.group(2)) for m in re.finditer(r"FLAGS,(\w+),(\d+)", uart)}
    assert flags == {"centre": 0, "edge": 0, "axis": OUTSIDE, "outside": OUTSIDE}
    worst = max(c for (stage, _), c in cycles.items() if stage == "sample_binary")
    assert worst < 16e6 / 500 * 0.75, cycles


def test_arduino_sketch_compiles_against_the_wire_api(host, tmp_path):
    """The sketch compiles as the Arduino IDE would (C++, with the core's C headers), against stand-ins for
    Arduino.h and Wire.h with the AVR core's signatures."""
    avr = shutil.which("avr-g++")  # part of gcc-avr, so CI has it; the AVR branches of the sketch get compiled
    compiler = [avr, "-mmcu=atmega328p", "-DF_CPU=16000000UL"] if avr else [require_tool("g++")]
    toolchain.write_tree(host.files, tmp_path)
    ino = tmp_path / "magfab_readout" / "magfab_readout.ino"
    proc = subprocess.run([*compiler, "-x", "c++", "-std=c++11", "-Wall", "-Wextra", "-Werror", "-fsyntax-only",
                           "-I", str(STUBS), str(ino)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    ini = host.files["platformio.ini"].decode()
    assert "src_dir = magfab_readout" in ini and "board = nanoatmega328\n" in ini and "upload_speed = 57600" in ini


@pytest.mark.parametrize("board, baud", [("uno", "115200"), ("nano", "115200"), ("nano-old", "57600")])
def test_flash_script_calls_avrdude(host, tmp_path, board, baud):
    sh = require_tool("sh")
    toolchain.write_tree(host.files, tmp_path)
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "avrdude"
    fake.write_text('#!/bin/sh\nfor a in "$@"; do printf "%s\\n" "$a"; done\n')
    fake.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ.get('PATH', '')}"}
    script = tmp_path / "flash.sh"
    assert subprocess.run([sh, "-n", str(script)]).returncode == 0
    missing = subprocess.run([sh, str(script), board, "/dev/null"], capture_output=True, text=True, env=env)
    assert missing.returncode == 1 and "make" in missing.stderr
    (tmp_path / firmware.HEX_NAME).write_text(":00000001FF\n")
    proc = subprocess.run([sh, str(script), board, "/dev/null"], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    args = proc.stdout.split("\n")
    assert args[args.index("-p") + 1] == "atmega328p" and args[args.index("-c") + 1] == "arduino"
    assert args[args.index("-b") + 1] == baud and args[args.index("-P") + 1] == "/dev/null"
    assert args[args.index("-U") + 1] == f"flash:w:{tmp_path / firmware.HEX_NAME}:i"
    bad = subprocess.run([sh, str(script), "mega"], capture_output=True, text=True, env=env)
    assert bad.returncode == 2
    bat = host.files["flash.bat"].decode()
    assert "57600" in bat and "-c arduino" in bat and firmware.HEX_NAME in bat
