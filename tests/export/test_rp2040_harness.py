"""The RP2040 readout board on the emulator (tests/firmware_sim/rp2040). arm-none-eabi-gcc builds the harness's smoke
images from the bundle's RP2040 sources (templates/firmware/rp2040), magfab writes them as UF2 files behind a sealed
boot2 (magfab.formats.uf2), and rp2040js runs them from the vector table after boot2: the line one sends on UART0
arrives, and the other enumerates as a USB CDC device and its lines arrive. The harness checks each block and boot2's
checksum in its own implementation and refuses a file whose boot2 or family is wrong. Then the build's own .uf2 (an
RP2040 build of MagOne: the image magfab ships and the build's record) streams, recovers and keeps its rate."""

from __future__ import annotations

import bisect
import contextlib
import functools
import importlib
import json
import math
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import require_node_package, require_tool
from readout_support import ref_forces

from magfab import derive, load_spec
from magfab.board.plan import address_plan
from magfab.export import firmware, rp2040, toolchain
from magfab.export.templating import templates_dir
from magfab.formats.uf2 import boot2_sealed, read, seal_boot2, write, write_regions
from magfab.readout.src.magfab_readout import calibration_json
from magfab.readout.src.magfab_readout.float32_bound import float32_error_N

HARNESS = Path(__file__).resolve().parent.parent / "firmware_sim" / "rp2040"
BUNDLE = templates_dir() / "firmware" / rp2040.RP2040_DIR  # the RP2040 sources every RP2040 build's bundle holds
KEY = "qtpy-rp2040"  # examples/magone_qtpy.toml's board: the sensor's bus is I2C1 (its STEMMA QT socket)
EXAMPLE = Path(firmware.__file__).parents[1] / "examples" / "magone_qtpy.toml"


def _run(node: str, uf2: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([node, str(HARNESS / "run.mjs"), str(uf2), *args], capture_output=True, text=True,
                          timeout=60, cwd=HARNESS)


ARM = ("-mcpu=cortex-m0plus", "-mthumb", "-Os", "-Wall", "-Wextra", "-Werror")


def _compile(out: Path, name: str, linker: str, sources: list[Path], *flags: str) -> Path:
    """``sources`` built for the Cortex-M0+ with ``linker`` (a file of the bundle's RP2040 sources) into
    ``out``/``name``.bin: its path."""
    elf = out / f"{name}.elf"
    subprocess.run([require_tool("arm-none-eabi-gcc"), *ARM, "-T", str(BUNDLE / linker), "-o", str(elf),
                    *map(str, sources), *flags], check=True)  # flags last: a library (-lm) follows the objects
    binary = elf.with_suffix(".bin")
    subprocess.run([require_tool("arm-none-eabi-objcopy"), "-O", "binary", str(elf), str(binary)], check=True)
    return binary


@functools.cache
def _boot2() -> bytes:
    """boot2.c built alone (position-independent, at most 252 bytes) and sealed with its checksum."""
    out = Path(tempfile.mkdtemp(prefix="boot2-"))
    return seal_boot2(_compile(out, "boot2", "boot2.ld", [BUNDLE / "boot2.c"], "-ffreestanding", "-nostdlib",
                               "-fPIC").read_bytes())


def _build(out: Path, smoke: str, *bundled: str) -> bytes:
    """The flash contents of one harness image: boot2.c's boot2, then the harness's ``smoke`` program on the bundle's
    start.c and ``bundled`` sources, built for the Cortex-M0+."""
    binary = _compile(out, Path(smoke).stem, "rp2040.ld",
                      [HARNESS / smoke, *(BUNDLE / s for s in ("start.c", *bundled))], f"-I{BUNDLE}",
                      "-ffreestanding", "-nostdlib")
    return _boot2() + binary.read_bytes()


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    """The UART smoke image: (node, its flash contents, the .uf2's path)."""
    node = require_node_package(HARNESS, "rp2040js")
    out = tmp_path_factory.mktemp("rp2040")
    flash = _build(out, "smoke.c")
    uf2 = out / "smoke.uf2"
    uf2.write_bytes(write(flash))
    return node, flash, uf2


def test_the_smoke_image_runs_on_the_emulated_rp2040(smoke):
    node, flash, uf2 = smoke
    start, image = read(uf2.read_bytes())
    assert start == 0x10000000 and image[:len(flash)] == flash and boot2_sealed(image)
    run = _run(node, uf2, "--until", "\n", "--ms", "30000")
    assert run.returncode == 0, run.stdout + run.stderr
    report = json.loads(run.stdout)
    assert report["boot2_crc_ok"] and report["blocks"] == -(-len(flash) // 256)
    assert report["uart"] == "magfab rp2040 smoke\n"


def test_boot2_starts_the_image_from_where_the_bootrom_runs_it(smoke, tmp_path):
    """boot2.c: 252 bytes at most, sealed; entered as the bootrom enters it (copied to 0x20041f00 and run there,
    --boot2), it sets the SSI for XIP and starts the image, whose line arrives. An empty boot2 with a good checksum
    starts nothing: the test can fail."""
    node, flash, _ = smoke
    assert len(_boot2()) == 256 and boot2_sealed(_boot2())
    uf2 = tmp_path / "smoke.uf2"
    uf2.write_bytes(write(flash))
    run = _run(node, uf2, "--boot2", "--until", "\n", "--ms", "30000")
    assert run.returncode == 0 and json.loads(run.stdout)["uart"] == "magfab rp2040 smoke\n", run.stdout
    empty = tmp_path / "empty.uf2"
    empty.write_bytes(write(seal_boot2(b"") + flash[256:]))
    run = _run(node, empty, "--boot2", "--us", "20000", "--ms", "30000")
    assert run.returncode == 0 and json.loads(run.stdout)["uart"] == "", run.stdout


def test_a_cdc_device_enumerates_and_echoes_on_the_emulated_usb(smoke, tmp_path):
    """usb_smoke.c on usb_cdc.c, a CDC-ACM device from the datasheet: rp2040js's host sets its address, reads its
    configuration (67 bytes, in two packets), configures it and sets the control lines; its greeting arrives, and a
    line sent to it, longer than a packet, comes back in capitals, whole and in order."""
    node = smoke[0]
    uf2 = tmp_path / "usb.uf2"
    uf2.write_bytes(write(_build(tmp_path, "usb_smoke.c", "usb_cdc.c", "clocks.c")))
    line = "ping " + "abcdefghij" * 10 + "\n"
    run = _run(node, uf2, "--send", line, "--until", line.upper(), "--ms", "30000")
    assert run.returncode == 0, run.stdout + run.stderr
    report = json.loads(run.stdout)
    assert report["usb_connected"] and report["usb"] == "magfab rp2040 usb\n" + line.upper()


@pytest.mark.parametrize(("change", "refusal"), [("boot2", "boot2 checksum"), ("family", "block 0: family")])
def test_the_harness_refuses_what_the_bootrom_would(smoke, tmp_path, change, refusal):
    node, flash, _ = smoke
    data = write(bytes([flash[0] ^ 1]) + flash[1:]) if change == "boot2" else write(flash, family=0x68ED2B88)
    bad = tmp_path / "bad.uf2"
    bad.write_bytes(data)
    run = _run(node, bad)
    assert run.returncode == 2 and json.loads(run.stdout) == {"refused": refusal}


FIELD_UT = (1200.0, -800.0, 20000.0)  # inside MagOne's calibrated region (as tests/export/test_simbus.py)


@pytest.fixture(scope="module")
def readout_image(smoke, rp2040_build, tmp_path_factory):
    """The RP2040 build's ready-to-flash .uf2 (the QT Py's shipped image and the build's record), and the build's
    MLX90393 model (its sim_mlx90393.c) served by mlxd.c: (node, uf2, mlxd, the build's folder). The build's own
    RP2040 sources, compiled here without a warning, give the shipped image byte for byte (its ELF, beside the .uf2,
    names the functions of a profile)."""
    node = smoke[0]
    out = tmp_path_factory.mktemp("rp2040-readout")
    fw = rp2040_build.out_dir / "firmware"
    mlxd = out / "mlxd"
    subprocess.run([require_tool("cc"), "-std=gnu99", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{fw / 'host'}",
                    f"-I{fw / 'magfab_readout' / 'src'}", "-o", str(mlxd), str(HARNESS / "mlxd.c"),
                    str(fw / "host" / "sim_mlx90393.c"), "-lm"], check=True)
    bundle = {rel: p.read_bytes() for p in fw.rglob("*") if p.is_file() and (rel := p.relative_to(fw).as_posix())
              .startswith((firmware.CORE_DIR + "/", rp2040.RP2040_DIR + "/"))}
    require_tool("arm-none-eabi-gcc")
    flash, sizes = toolchain.build_rp2040(bundle, KEY, out / "src")
    assert sizes["warnings"] == "" and flash == rp2040.shipped_image(KEY)[0]
    uf2 = out / "readout.uf2"
    uf2.write_bytes((fw / rp2040.image_name(KEY)).read_bytes())
    (out / "src" / rp2040.RP2040_DIR / "build" / f"{KEY}.elf").rename(uf2.with_suffix(".elf"))
    return node, uf2, mlxd, rp2040_build.out_dir


@contextlib.contextmanager
def _readout_package(out: Path) -> Iterator[str]:
    """The build's readout package (``out``/readout/src) importable as ``magfab_readout`` inside the block, and
    forgotten after it (another build's may follow)."""
    readout = str(out / "readout" / "src")
    sys.path.insert(0, readout)
    try:
        yield "magfab_readout"
    finally:
        sys.path.remove(readout)
        for name in [n for n in sys.modules if n == "magfab_readout" or n.startswith("magfab_readout.")]:
            del sys.modules[name]


def _model(readout_image, addr_offset: int = 0, field: tuple = FIELD_UT) -> tuple[list[str], dict]:
    """The harness's arguments for the build's MLX90393 model at the build's address (plus ``addr_offset``) serving
    ``field`` at 25 C, and the build's build.json."""
    _, _, mlxd, out = readout_image
    info = json.loads((out / "readout" / "src" / "magfab_readout" / "build.json").read_text())
    return ["--mlx", str(mlxd), "--i2c", "1", "--addr", str(info["image_settings"]["i2c_address"] + addr_offset),
            "--field", ",".join(str(b) for b in (*field, 25.0))], info


def _stream(readout_image, addr_offset: int = 0, inject: str = "", us: int = 250_000,
            timed: bool = False, send: str = "", field: tuple = FIELD_UT, extra: tuple = ()) -> tuple[list, list, dict]:
    """``us`` of emulated time of the readout image against the model at the build's address (plus ``addr_offset``),
    ``inject`` the harness's --inject (FAULT@US), ``timed`` its --bus-timing, ``send`` what the host sends once the
    device is connected: (the samples the build's readout package decodes from what came over USB and every other
    item it decodes, build.json)."""
    node, uf2, _, out = readout_image
    model, info = _model(readout_image, addr_offset, field)
    run = _run(node, uf2, *model, "--hex", "--us", str(us), "--ms", "50000",
               *(("--inject", inject) if inject else ()), *(("--bus-timing",) if timed else ()),
               *(("--send", send) if send else ()), *extra)
    assert run.returncode == 0, run.stdout + run.stderr
    report = json.loads(run.stdout)
    assert report["usb_connected"]
    with _readout_package(out) as package:
        frames = importlib.import_module(f"{package}.frames")
        decoder = frames.Decoder()
        items = list(decoder.feed(bytes.fromhex(report["usb_hex"])))
        samples = [s for s in items if isinstance(s, frames.Sample)]
        others = [s for s in items if not isinstance(s, frames.Sample)]
    assert decoder.stats.crc_errors == 0 and decoder.stats.lost == 0
    info["reset_us"] = report["reset_us"]  # when the harness restarted the chip (--reset-phase), or None
    return samples, others, info


def _wrong(readout_image, samples: list, info: dict, cal: dict | None = None, field: tuple = FIELD_UT) -> list:
    """The samples that carry a force (no chip-error flag) other than the model's field at the build's gain and
    resolution, or a force off the build's calibration.json (or ``cal``) at it (float64, docs/bundle.md written out)
    by more than the float32 bound the firmware README states."""
    cal = cal or json.loads((readout_image[3] / "calibration" / "calibration.json").read_text())
    lsb = (info["lsb_xy_uT"], info["lsb_xy_uT"], info["lsb_z_uT"])
    counts = tuple(round(b / q) for b, q in zip(field, lsb))
    truth = ref_forces(cal, *(c * q for c, q in zip(counts, lsb)))
    bound_z, bound_xy = float32_error_N(calibration_json.validate(cal))
    return [s for s in samples if not s.chip_error and (s.counts != counts or not all(
        abs(f - t) <= b for f, t, b in zip(s.force_N, truth, (bound_xy, bound_xy, bound_z))))]


def test_the_readout_core_streams_true_forces_over_usb_from_the_emulated_rp2040(readout_image):
    """The frames that come over USB decode with the build's readout package, and each is a true force."""
    samples, _, info = _stream(readout_image)
    assert len(samples) > 50 and not any(s.chip_error for s in samples)
    assert _wrong(readout_image, samples, info) == []


#: The AVR image's fault matrix (tests/export/test_simbus.py) on the RP2040: the fault and the one the host is told
#: of (None: no error frame). Not yet here: the held bus (the harness has no bus time yet).
FAULTS = {
    "address NACK": ("nack-addr", "nack at read"),
    "data NACK": ("nack-data", "nack at read"),
    "short read": ("chip:short", "byte count at read"),
    "all 0xFF": ("all-ff", "bus error at read"),
    "chip reset in burst": ("chip:reset", "chip reset at read"),
    "conversions stop": ("chip:stuck", "chip ERROR bit at read"),
    "ERROR bit once": ("chip:error", None),  # the read's one retry absorbs it
}
INJECT_US = 100_000


@pytest.mark.parametrize("fault", list(FAULTS))
def test_fault_gives_error_frames_never_a_wrong_force(readout_image, fault):
    """Each fault at 100 ms of emulated time, mid-stream: no wrong force before or after it; the first error frame
    names the fault; the stream recovers (the first good frame after an error is flagged recovered) and ends with
    good frames."""
    inject, named = FAULTS[fault]
    samples, _, info = _stream(readout_image, inject=f"{inject}@{INJECT_US}", timed=True)
    # from the last sample stamped before the fault: a sample carries its conversion's time, so the one whose read
    # meets the fault is stamped before it
    after = samples[next(i for i, s in enumerate(samples) if s.t_us >= INJECT_US) - 1:]
    marks = "".join("E" if s.chip_error else ("R" if s.recovered else ".") for s in after)
    assert _wrong(readout_image, samples, info) == [], marks
    errors = [s for s in after if s.chip_error]
    assert (errors[0].fault_name if errors else None) == named, marks
    assert after[-5:] and not any(s.chip_error for s in after[-5:]), marks
    if errors:
        assert next(s for s in after[after.index(errors[0]):] if not s.chip_error).recovered, marks


STARTUP_PHASES = 28  # EX, RT, NOP, three read-modify-verify register updates, SB, the first RM: 2 phases each


@pytest.mark.parametrize("phase", range(1, STARTUP_PHASES + 1))
def test_chip_reset_at_every_start_up_step(readout_image, phase):
    """A chip reset (power-on registers, RS pending) at each address phase of the start-up and the first read (as the
    AVR image's, tests/export/test_simbus.py): never a wrong force (the counts at the build's gain and resolution: the
    configuration re-applied), and forces streaming in the end."""
    samples, _, info = _stream(readout_image, timed=True, us=150_000, extra=("--reset-phase", str(phase)))
    marks = "".join("E" if s.chip_error else ("R" if s.recovered else ".") for s in samples)
    assert info["reset_us"] is not None and (not samples or info["reset_us"] <= samples[0].t_us + 2000), marks
    assert _wrong(readout_image, samples, info) == [], marks
    assert samples[-3:] and not any(s.chip_error for s in samples[-3:]), marks


@pytest.mark.parametrize("phase", range(1, STARTUP_PHASES + 1))
def test_chip_reset_at_every_recovery_step(readout_image, phase):
    """The same during the recovery after a fault (an address NACK at 100 ms): the reset strikes the restart's
    ``phase``-th address phase after the NACKed one."""
    samples, _, info = _stream(readout_image, timed=True, us=320_000, inject=f"nack-addr@{INJECT_US}",
                               extra=("--reset-phase", str(1 + phase), "--reset-after", str(INJECT_US)))
    after = [s for s in samples if s.t_us >= INJECT_US - 5000]
    marks = "".join("E" if s.chip_error else ("R" if s.recovered else ".") for s in after)
    assert info["reset_us"] is not None and INJECT_US < info["reset_us"] < after[-3].t_us, marks
    assert _wrong(readout_image, samples, info) == [], marks
    assert any(s.chip_error for s in after) and not any(s.chip_error for s in after[-3:]), marks


def test_no_chip_on_the_bus_gives_error_frames_never_a_force(readout_image):
    """The model at another address: every address phase goes unanswered, and what comes over USB is error frames
    (the chip-error flag, no field, no force), never a force."""
    samples, _, _ = _stream(readout_image, addr_offset=1)
    assert samples and all(s.chip_error for s in samples)
    assert all(all(f != f for f in s.force_N) for s in samples)  # NaN


SETTLE_US = 40_000  # boot to steady streaming, with margin (as the AVR image's rate test)
#: The AVR image's rate settings (tests/export/test_simbus.py's RATE_SETTINGS): (OSR, DIG_FILT).
RATE_SETTINGS = ((0, 2), (1, 1), (0, 4))


@pytest.mark.parametrize(("osr", "dig_filt"), RATE_SETTINGS)
def test_the_rate_on_a_timed_bus_is_every_conversion_of_the_chip(readout_image, tmp_path, osr, dig_filt):
    """The bus timed at the SCL clock the image sets (400 kHz), the chip converting at the datasheet table's time
    (the build's model), MagOne's calibration with the record of these OSR / DIG_FILT (what ``magfab build`` renders
    for them): over 200 conversions after the start, every frame a distinct conversion and at least 99 % of the chip's
    conversions delivered as true forces (the AVR image's goal; the closing note gives the measured share)."""
    default = load_spec(EXAMPLE)
    design = derive(default.model_copy(update={"sensor": default.sensor.model_copy(
        update={"osr": osr, "dig_filt": dig_filt})}))
    image = readout_image
    if (osr, dig_filt) != (default.sensor.osr, default.sensor.dig_filt):  # the build's .uf2 with that record
        cal = json.loads((readout_image[3] / "calibration" / "calibration.json").read_text())
        uf2 = tmp_path / "rate.uf2"
        uf2.write_bytes(rp2040.build_uf2(KEY, firmware.eeprom_record(design, cal)))
        image = (readout_image[0], uf2, *readout_image[2:])
    tconv = firmware.chip_config(design).tconv_us
    samples, _, info = _stream(image, us=SETTLE_US + 200 * tconv, timed=True)
    steady = [s for s in samples if s.t_us >= SETTLE_US]
    assert _wrong(readout_image, steady, info) == [] and not any(s.chip_error for s in steady)
    conversions = (steady[-1].t_us - steady[0].t_us) / tconv
    print(f"OSR {osr} DIG_FILT {dig_filt}: {len(steady) - 1} frames over {conversions:.2f} conversions of "
          f"{tconv} us: {(len(steady) - 1) / conversions:.2%}")
    assert len(steady) - 1 <= conversions + 1  # every frame a distinct conversion
    assert (len(steady) - 1) / conversions >= 0.99, (len(steady) - 1, conversions)


def _region_fields(cal: dict) -> list[tuple[float, float, float]]:
    """Fields across the calibrated region: its hull's centroid and each vertex a twentieth of the way in from it
    (valid_region.hull's (Bz, Br) points, uT), Br along x."""
    hull = cal["valid_region"]["hull"]
    bz = sum(p[0] for p in hull) / len(hull)
    br = sum(p[1] for p in hull) / len(hull)
    points = [(bz, br)] + [(bz + 0.95 * (z - bz), br + 0.95 * (r - br)) for z, r in hull]
    return [(max(r, 0.0), 0.0, z) for z, r in points]


def test_the_rate_holds_across_the_calibrated_region(readout_image):
    """MagOne's settings on the timed bus, at the calibrated region's centre and near each vertex of its hull (where
    the calibration's hull test and direction split cost most): at every field, every frame a distinct conversion, at
    least 99 % of the chip's conversions delivered, each a true force; the worst field's share printed."""
    cal = json.loads((readout_image[3] / "calibration" / "calibration.json").read_text())
    tconv = firmware.chip_config(derive(load_spec(EXAMPLE))).tconv_us
    shares = []
    for field in _region_fields(cal):
        samples, _, info = _stream(readout_image, us=SETTLE_US + 100 * tconv, timed=True, field=field)
        steady = [s for s in samples if s.t_us >= SETTLE_US]
        assert not any(s.chip_error for s in steady) and _wrong(readout_image, steady, info, field=field) == []
        conversions = (steady[-1].t_us - steady[0].t_us) / tconv
        assert len(steady) - 1 <= conversions + 1
        shares.append(((len(steady) - 1) / conversions, field))
    worst = min(shares)
    print(f"{len(shares)} fields: the worst {worst[0]:.2%} of the chip's conversions at {worst[1]}")
    assert worst[0] >= 0.99, shares


#: Each array case's rate a taxel, Hz, for the two-bus case's ratio to the one-bus case (parametrised in this order).
RATES: dict[tuple[int, int], float] = {}


@pytest.mark.parametrize(("chips", "buses"), [(5, 1), (16, 1), (16, 2)])
def test_an_array_reads_every_chip_at_the_chips_or_the_buss_rate(readout_image, tmp_path, chips, buses):
    """The shipped image with an array record of ``chips`` chips (0x0C up, MagOne's settings) on ``buses`` I2C buses
    (two: taxel k on the second when k is odd, the board's second controller), each chip the build's model at its
    address on its timed bus: every chip's readings in each cycle frame, each the model's field at the build's gain
    and resolution, no error, every chip equally often. Each bus's own limit is the cycles a second it would carry
    if it never rested (run.mjs's bus_busy_us and bus_b_busy_us over the steady window: every step at the image's
    SCL). The taxels must come at 99 % of the chip's conversions where the chip's rate is the lower (five chips),
    and at 93 % of the busiest bus's limit where a bus binds (sixteen chips; measured 95.8 %, on one bus and on two:
    the core's own work between one chip's reply and its bus's next read, about 11 us a read at 125 MHz, is the
    rest); on two buses the taxels come at least 1.9 times as often as on one (measured 2.0)."""
    node, _, mlxd, out = readout_image
    design = derive(load_spec(EXAMPLE))
    settings = firmware.image_settings(design)
    addresses = [0x0C + k for k in range(chips)]
    second = [k for k in range(chips) if buses == 2 and k % 2]
    record = firmware._eeprom_module().pack_array(addresses, "0" * 16, settings, sum(1 << k for k in second))
    uf2 = tmp_path / "array.uf2"
    uf2.write_bytes(rp2040.build_uf2(KEY, record))
    on_b = [addresses[k] for k in second]
    on_a = [a for a in addresses if a not in on_b]
    fields = ";".join(",".join(str(b) for b in (*FIELD_UT, 25.0)) for _ in addresses)
    settle, window = SETTLE_US + 10_000 * chips, 300_000
    run = _run(node, uf2, "--mlx", str(mlxd), "--i2c", "1", "--addr", ",".join(map(str, on_a)),
               *(("--addr-b", ",".join(map(str, on_b)), "--i2c-b", "0") if on_b else ()), "--field", fields,
               "--hex", "--us", str(settle + window), "--ms", "120000", "--bus-timing", "--busy-after", str(settle))
    report = json.loads(run.stdout)
    with _readout_package(out) as package:
        frames = importlib.import_module(f"{package}.frames")
        decoder = frames.Decoder()
        got = [s for s in decoder.feed(bytes.fromhex(report["usb_hex"])) if isinstance(s, frames.Sample)]
    assert decoder.stats.crc_errors == 0 and decoder.stats.lost == 0
    lsb = (settings["lsb_xy_uT"], settings["lsb_xy_uT"], settings["lsb_z_uT"])
    counts = tuple(round(b / q) for b, q in zip(FIELD_UT, lsb))
    assert not any(s.chip_error for s in got) and all(s.counts == counts for s in got)
    steady = [s for s in got if s.t_us >= settle]
    per = [sum(s.taxel == k for s in steady) for k in range(chips)]
    assert max(per) - min(per) <= 1
    elapsed = (steady[-1].t_us - steady[0].t_us) / 1e6
    tconv = firmware.chip_config(design).tconv_us
    rate, chip_hz = min(per) / elapsed, 1e6 / tconv
    busiest = max(report["bus_busy_us"], report["bus_b_busy_us"])  # from the settle time on
    bus_hz = (len(steady) / chips) / (busiest / 1e6)  # cycles a second if the busiest bus never rested
    goal = min(chip_hz, bus_hz)
    print(f"{chips} chips on {buses} bus(es): {rate:.1f} Hz a taxel, {rate / chip_hz:.1%} of the chip's "
          f"{chip_hz:.1f} conversions/s; the busiest bus's own limit {bus_hz:.1f} cycles/s; "
          f"{rate / goal:.1%} of the lower")
    assert rate >= (0.99 if chip_hz <= bus_hz else 0.93) * goal
    RATES[(chips, buses)] = rate
    if (16, 1) in RATES and (16, 2) in RATES:
        assert RATES[(16, 2)] >= 1.9 * RATES[(16, 1)], RATES


def test_the_builds_two_bus_array_reads_each_chip_on_its_own_bus(readout_image, two_bus_build):
    """The build's own .uf2 of an array split over two buses (examples/fingertip_2x2.toml with ``array.buses = 2`` on
    a QT Py RP2040), each chip the build's model on the bus its address plan names (J1's on the STEMMA QT socket's
    I2C1, J2's on the castellated pads' I2C0), each bus timed at 400 kHz: every taxel's readings are its chip's field,
    at 99 % of the chip's conversions or more. Wired wrong (every chip on J1's bus), the odd taxels' frames all carry
    the error flag and no reading, and the even ones' are still their chips' (slower: the lost chips' restarts take
    the bus), so no reading comes from a chip the taxel does not name."""
    node, _, mlxd, _ = readout_image
    out, design = two_bus_build.out_dir, two_bus_build.design
    uf2 = out / "firmware" / rp2040.image_name(KEY)
    plan = address_plan(design)
    settings = firmware.image_settings(design)
    fields = [(1200.0 + 150.0 * r["taxel"], -800.0 + 90.0 * r["taxel"], 20000.0 - 700.0 * r["taxel"]) for r in plan]
    lsb = (settings["lsb_xy_uT"], settings["lsb_xy_uT"], settings["lsb_z_uT"])
    tconv = firmware.chip_config(design).tconv_us
    for wired in ("right", "all on J1"):
        on_b = [r for r in plan if r["bus"] == 1 and wired == "right"]
        on_a = [r for r in plan if r not in on_b]
        order = on_a + on_b  # run.mjs's --field order: the first bus's chips, then the second's
        run = _run(node, uf2, "--mlx", str(mlxd), "--i2c", "1", "--addr", ",".join(str(r["address"]) for r in on_a),
                   *(("--addr-b", ",".join(str(r["address"]) for r in on_b), "--i2c-b", "0") if on_b else ()),
                   "--field", ";".join(",".join(map(str, (*fields[r["taxel"]], 25.0))) for r in order),
                   "--hex", "--us", str(SETTLE_US + 40_000 + 200_000), "--ms", "120000", "--bus-timing")
        with _readout_package(out) as package:
            frames = importlib.import_module(f"{package}.frames")
            decoder = frames.Decoder()
            got = [x for x in decoder.feed(bytes.fromhex(json.loads(run.stdout)["usb_hex"]))
                   if isinstance(x, frames.Sample) and x.t_us >= SETTLE_US + 40_000]
        assert decoder.stats.crc_errors == 0 and got
        for r in plan:
            mine = [x for x in got if x.taxel == r["taxel"]]
            truth = tuple(round(b / q) for b, q in zip(fields[r["taxel"]], lsb))
            if wired == "right" or r["bus"] == 0:
                assert mine and all(not x.chip_error and x.counts == truth for x in mine), (wired, r["taxel"])
                share = (len(mine) - 1) / ((mine[-1].t_us - mine[0].t_us) / tconv)
                assert share >= 0.99 or wired != "right", (r["taxel"], share)  # wrong: the lost chips' retries cost
            else:
                assert mine and all(x.chip_error and all(map(math.isnan, x.B_uT)) for x in mine), r["taxel"]


def test_each_board_gives_its_flash_chips_unique_id_as_its_usb_serial_number(readout_image):
    """The image reads its flash chip's 64-bit unique ID (4Bh, from SRAM with the SSI out of XIP, as it programs the
    record) at start-up and gives it as the USB serial number string a host reads (GET_DESCRIPTOR string 3): two boards
    (two flash chips) give two serial numbers, each its chip's ID; the flash model saw no read of flash meanwhile."""
    node, uf2, _, _ = readout_image
    for chip in ("0123456789ABCDEF", "E4630C7D2B4F3F29"):
        transport = HarnessTransport(node, uf2, "--flash-id", chip)
        try:
            transport.ask("run 30000", answered=True)
            serial = json.loads(transport.ask("usb-serial", answered=True))
            flash = json.loads(transport.ask("flash", answered=True))
        finally:
            transport.close()
        assert serial == chip and flash["errors"] == [], (serial, flash)


def test_the_host_asks_the_board_what_it_runs_over_usb(readout_image):
    """The host's 'i' over USB (what ``magfab-readout info`` sends): the board answers with the build's spec name,
    calibration hash and chip settings, between its frames."""
    samples, others, info = _stream(readout_image, send="i", us=60_000)
    answers = [x for x in others if type(x).__name__ == "DeviceInfo"]
    assert samples and len(answers) == 1
    answer = answers[0]
    assert answer.spec_name == info["spec_name"] and answer.calibration_hash == info["calibration_sha256"][:16]
    assert (answer.gain_sel, answer.resolution, answer.osr, answer.dig_filt) == tuple(
        info[k] for k in ("gain_sel", "resolution", "osr", "dig_filt"))


class HarnessTransport:
    """The emulated board as the serial port of the build's ``magfab_readout.Device`` (run.mjs --interactive): each
    read runs 2 ms of emulated time and returns what the device sent over USB meanwhile; each write is sent by the
    emulated USB host."""

    port = "the emulated RP2040"

    def __init__(self, node: str, uf2: Path, *harness_args: str) -> None:
        self.proc = subprocess.Popen([node, str(HARNESS / "run.mjs"), str(uf2), "--interactive", *harness_args],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=HARNESS)

    def ask(self, line: str, answered: bool = False) -> str:
        """Send run.mjs one command; ``answered``: it answers with a line ('run', the second 'profile'), returned."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return self.proc.stdout.readline().strip() if answered else ""

    def read(self, size: int = 4096, timeout_s: float = 0.05) -> bytes:
        return bytes.fromhex(self.ask("run 2000", answered=True))

    def write(self, data: bytes) -> int:
        self.ask("send " + data.hex())
        return len(data)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.ask("quit")
            self.proc.wait(timeout=30)


def test_the_readout_package_reads_the_emulated_board(readout_image):
    """The real client: the build's ``magfab_readout.Device`` on the emulated board's USB. It asks what the board runs
    (``magfab-readout info``'s 'i') and finds the build's spec and calibration, with nothing to complain of
    (``check_info``), then takes 50 samples (``stream``'s path): each a true force."""
    node, uf2, _, out = readout_image
    model, info = _model(readout_image)
    transport = HarnessTransport(node, uf2, *model, "--bus-timing")
    with _readout_package(out) as package:
        device = importlib.import_module(f"{package}.device").Device(transport=transport, timeout_s=20.0)
        try:
            answer = device.info()
            problems = device.check_info(answer)
            samples = list(device.samples(count=50))
        finally:
            device.close()
    assert answer.spec_name == info["spec_name"] and problems == [], problems
    assert len(samples) == 50 and _wrong(readout_image, samples, info) == []


def _shifted(out: Path) -> dict:
    """The build's calibration with 0.5 N more normal force everywhere: another valid calibration, another hash."""
    cal = json.loads((out / "calibration" / "calibration.json").read_text())
    cal["coefficients"]["Fz_N"][0] += 0.5
    return cal


def test_upload_programs_the_flash_and_the_board_boots_with_it(readout_image, tmp_path):
    """The real client's upload (``magfab-readout upload``'s Device.upload): the board programs the record into its
    flash sector from SRAM, one 'w' at a time, reads it back and reports the new hash; the flash model saw every erase
    and program made as a SPI NOR flash takes them and nothing read from flash while the SSI was out of XIP (no
    error). Then the new calibration's forces stream, and a board started again from that flash (a new emulator on
    the image and the sector as the upload left it) runs the new calibration: no compiler, no reflash."""
    node, uf2, _, out = readout_image
    model, info = _model(readout_image)
    new = _shifted(out)
    offset = rp2040.record_offset(rp2040.resolve.board(KEY))
    transport = HarnessTransport(node, uf2, *model, "--bus-timing")
    with _readout_package(out) as package:
        device = importlib.import_module(f"{package}.device")
        board = device.Device(transport=transport, timeout_s=60.0)
        record = device.calibration_record(new)
        try:
            answer = board.upload(new)
            samples = list(board.samples(count=20))
            flash = json.loads(transport.ask("flash", answered=True))
            sector = bytes.fromhex(transport.ask(f"peek {offset},{len(record)}", answered=True))
        finally:
            board.close()
    assert answer.calibration_hash == calibration_json.calibration_sha256(new)[:16]
    assert flash["errors"] == [] and flash["erases"] >= 1 and flash["programs"] >= 4, flash
    assert sector == record and _wrong(readout_image, samples, info, new) == []
    again = tmp_path / "after-upload.uf2"
    again.write_bytes(rp2040.build_uf2(KEY, sector))
    _, others, _ = _stream((node, again, *readout_image[2:]), send="i", us=60_000)
    assert [x.calibration_hash for x in others if type(x).__name__ == "DeviceInfo"] == [answer.calibration_hash]


def test_calibration_uf2_dropped_on_the_drive_replaces_the_record_and_keeps_the_identity(readout_image, tmp_path):
    """A board that runs the build's .uf2 and carries a sensor identity (written by ``upload --sensor``'s
    write_identity, into the sector below the record's) takes a calibration.uf2 of another calibration on its drive
    (the bootrom erases only the sectors a file writes): it then runs the new calibration, and reads back the same
    identity."""
    node, uf2, _, out = readout_image
    model, _ = _model(readout_image)
    offset = rp2040.record_offset(rp2040.resolve.board(KEY))
    new = _shifted(out)
    with _readout_package(out) as package:
        device = importlib.import_module(f"{package}.device")
        identity = importlib.import_module(f"{package}.identity")
        ident = identity.Identity("finger-07", "2026-12-03T10:00:00Z", calibration_json.calibration_sha256(new)[:16])
        transport = HarnessTransport(node, uf2, *model)
        board = device.Device(transport=transport, timeout_s=60.0)
        try:
            board.write_identity(ident)
            image = rp2040.shipped_image(KEY)[0]
            held = [(at, bytes.fromhex(transport.ask(f"peek {at},{n}", answered=True)))  # what the board's flash holds
                    for at, n in ((0, len(image)), (offset - 4096, identity.SIZE), (offset, 1024))]
        finally:
            board.close()
        assert held[0][1] == image and held[1][1] == identity.pack(ident)
        flash = tmp_path / "board.uf2"  # the same, as a file to start the emulator from
        flash.write_bytes(write_regions([(0x10000000 + at, data) for at, data in held]))
        dropped = tmp_path / rp2040.CALIBRATION_UF2
        dropped.write_bytes(rp2040.calibration_uf2(KEY, device.calibration_record(new)))
        transport = HarnessTransport(node, flash, *model, "--drop", str(dropped))
        board = device.Device(transport=transport, timeout_s=60.0)
        try:
            answer = board.info()
            kept = board.read_identity()
        finally:
            board.close()
    assert answer.calibration_hash == calibration_json.calibration_sha256(new)[:16] and kept == ident


#: The hardware layer's functions that wait (for USB, the bus, a delay): a sample's cycles outside them are the work.
WAITING = {"cdc_poll", "arm", "rp_i2c_read", "rp_i2c_write", "rp_delay_us", "i2c_finish", "i2c_aborted", "wait_set"}


def test_the_cycle_budget_leaves_the_core_most_of_a_sample(readout_image):
    """The CPU's cycles over 100 samples at MagOne's settings on the timed bus (run.mjs's 'profile': cycles by
    instruction address, mapped to the image's functions with arm-none-eabi-nm): a sample's period is 230,000 cycles
    at 125 MHz, and the work outside the hardware layer's waits (the driver, the calibration in soft float, the frame
    and its CRC) takes under a fifth of it; the closing note gives the figures."""
    node, uf2, _, _ = readout_image
    transport = HarnessTransport(node, uf2, *_model(readout_image)[0], "--bus-timing")
    try:
        transport.ask("run 50000", answered=True)
        transport.ask("profile")
        transport.ask("run 184000", answered=True)  # 100 conversions of 1840 us
        cycles = {int(pc) & ~1: n for pc, n in json.loads(transport.ask("profile", answered=True)).items()}
    finally:
        transport.close()
    nm = subprocess.run([require_tool("arm-none-eabi-nm"), "-S", "--defined-only", "-n", str(uf2.with_suffix(".elf"))],
                        capture_output=True, text=True, check=True).stdout
    functions = sorted((int(a, 16), int(size, 16), name) for a, size, kind, name in
                       (line.split() for line in nm.splitlines() if len(line.split()) == 4) if kind in "tTwW")
    starts = [f[0] for f in functions]
    by_function: dict[str, int] = {}
    for pc, n in cycles.items():
        i = bisect.bisect_right(starts, pc) - 1
        name = functions[i][2] if i >= 0 and pc < functions[i][0] + functions[i][1] else "?"
        by_function[name] = by_function.get(name, 0) + n
    total = sum(by_function.values())
    work = sum(n for name, n in by_function.items() if name not in WAITING)
    print(f"cycles per sample: {total / 100:.0f}, of which the work {work / 100:.0f} ({work / total:.1%}); "
          + ", ".join(f"{k} {v / 100:.0f}" for k, v in sorted(by_function.items(), key=lambda kv: -kv[1])[:8]))
    assert total == pytest.approx(100 * 230_000, rel=1e-3)
    assert "?" not in by_function and work < 0.2 * total
