"""What the readout tests share: a calibration made here, independent implementations of the bundle formats
(docs/bundle.md) to check the package against, and the package rendered, imported and pip-installed.

Plain functions and fixture factories (no test in here); the test modules that use them import them."""

from __future__ import annotations

import importlib
import math
import os
import random
import struct
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import ref_crc16

PKG = "readout/src/magfab_readout"
CSV_REQUIRED = ("time_s", "Bx_uT", "By_uT", "Bz_uT", "Fx_N", "Fy_N", "Fz_N")


# --- a calibration built here (calibrate.py is not needed) ---------------------------------------------------

def make_calibration(order: int = 4, seed: int = 1, tare=(0.0, 0.0)) -> dict:
    """A plausible order-n calibration: Fz grows with Bz, Fr with Br, both zero at the region's low corner
    (where the magnet rests), plus small seeded terms on every monomial so each one is exercised."""
    monomials = [[i, k - i] for k in range(order + 1) for i in range(k, -1, -1)]
    rng = random.Random(seed)
    cz = [0.05 * rng.uniform(-1, 1) / (1 + i + j) for i, j in monomials]
    cr = [0.05 * rng.uniform(-1, 1) / (1 + i + j) for i, j in monomials]
    cz[0], cz[1] = 2.0, 2.0  # 2 (u + 1): u = -1 at the low end of Bz
    cr[0], cr[2] = 1.5, 1.5  # 1.5 (v + 1): v = -1 at Br = 0
    return {
        "format": "magfab-calibration/1", "method": "poly", "order": order, "monomials": monomials,
        "scaling": {"Bz_uT": {"center": 21000.0, "scale": 9000.0}, "Br_uT": {"center": 4000.0, "scale": 4000.0}},
        "coefficients": {"Fz_N": cz, "Fr_N": cr}, "shear_sign": -1, "direction_min_uT": 30.0,
        "tare_N": {"Fz_N": tare[0], "Fr_N": tare[1]},
        "valid_region": {"Bz_uT": [12000.0, 30000.0], "Br_uT": [0.0, 8000.0],
                         "hull": [[12000.0, 0.0], [30000.0, 0.0], [30000.0, 3000.0], [22000.0, 8000.0],
                                  [12000.0, 4000.0]]},
        "errors": {"Fz_N": {"rms_holdout": 0.012, "max_holdout": 0.05, "rms_fit": 0.01},
                   "Fr_N": {"rms_holdout": 0.011, "max_holdout": 0.04, "rms_fit": 0.009}, "folds": 5},
        "scan": {"sha256": "ab" * 32, "rows": 4000, "source": "simulated"},
        "chip": {"gain_sel": 0, "resolution": 2, "osr": 0, "dig_filt": 2, "lsb_xy_uT": 3.004, "lsb_z_uT": 4.84},
    }


# --- the simulated board at rest ------------------------------------------------------------------------------

def _rest_readings(samples):
    """Mean (Fx, Fy, Fz) of ``samples`` and how many were flagged outside the calibrated region."""
    mean = tuple(sum(s.force_N[a] for s in samples) / len(samples) for a in range(3))
    return mean, sum("o" in s.flags for s in samples)


def assert_reads_zero_at_rest(pkg, calibration: dict) -> None:
    """The simulated board at rest, untared, reads within the calibration's held-out RMS of zero, as a real one
    right after its calibration (it read Fx +37 mN at rest until --zero: its rest field was a coarse grid point
    off the axis), and inside the calibrated region."""
    sim = pkg.SimulatedDevice(pkg.Calibration(calibration), realtime=False, chunk=500, text=False)
    with pkg.Device(transport=sim, calibration=pkg.Calibration(calibration)) as device:
        samples = device.read(int(sim.pattern.rest_s * sim.rate_Hz))  # the pattern's first rest
    mean, outside = _rest_readings(samples)
    rms = calibration["errors"]
    bound = (rms["Fr_N"]["rms_holdout"], rms["Fr_N"]["rms_holdout"], rms["Fz_N"]["rms_holdout"])
    assert all(abs(m) < b for m, b in zip(mean, bound)), (mean, bound, sim.pattern.rest)
    assert outside <= 0.02 * len(samples)


# --- independent implementations ------------------------------------------------------------------------------

def ref_forces(cal: dict, Bx: float, By: float, Bz: float) -> tuple:
    """docs/bundle.md section 2 written out directly, float64."""
    Br = math.sqrt(Bx**2 + By**2)
    u = (Bz - cal["scaling"]["Bz_uT"]["center"]) / cal["scaling"]["Bz_uT"]["scale"]
    v = (Br - cal["scaling"]["Br_uT"]["center"]) / cal["scaling"]["Br_uT"]["scale"]
    F = {name: sum(c * u**i * v**j for c, (i, j) in zip(cal["coefficients"][name], cal["monomials"]))
         - cal["tare_N"][name] for name in ("Fz_N", "Fr_N")}
    if Br < cal["direction_min_uT"] or Br == 0:
        return 0.0, 0.0, F["Fz_N"]
    s = cal["shear_sign"]
    return s * F["Fr_N"] * Bx / Br, s * F["Fr_N"] * By / Br, F["Fz_N"]


def ref_inside(cal: dict, Bz: float, Br: float) -> bool:
    """Box test plus ray casting (a different algorithm from the package's half-plane test)."""
    region = cal["valid_region"]
    if not (region["Bz_uT"][0] <= Bz <= region["Bz_uT"][1] and region["Br_uT"][0] <= Br <= region["Br_uT"][1]):
        return False
    inside = False
    hull = region["hull"]
    for (x1, y1), (x2, y2) in zip(hull, hull[1:] + hull[:1]):
        if (y1 > Br) != (y2 > Br) and Bz < x1 + (Br - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def ref_distance_to_hull(cal: dict, Bz: float, Br: float) -> float:
    hull = cal["valid_region"]["hull"]
    best = math.inf
    for (x1, y1), (x2, y2) in zip(hull, hull[1:] + hull[:1]):
        dx, dy = x2 - x1, y2 - y1
        t = max(0.0, min(1.0, ((Bz - x1) * dx + (Br - y1) * dy) / (dx * dx + dy * dy)))
        best = min(best, math.hypot(Bz - x1 - t * dx, Br - y1 - t * dy))
    return best


ref_crc = ref_crc16


def ref_frame(seq, t_us, status, counts, t_raw, forces) -> bytes:
    """A force frame assembled field by field at the documented offsets."""
    body = bytearray(27)  # frame bytes 2..28
    body[0], body[1], body[2] = 0x01, seq, status
    body[3:7] = t_us.to_bytes(4, "little")
    for k, c in enumerate(counts):
        body[7 + 2 * k:9 + 2 * k] = int(c).to_bytes(2, "little", signed=True)
    body[13:15] = t_raw.to_bytes(2, "little")
    for k, f in enumerate(forces):
        body[15 + 4 * k:19 + 4 * k] = struct.pack("<f", f)
    return b"\xa5\x5a" + bytes(body) + ref_crc(bytes(body)).to_bytes(2, "little")


def ref_decode(data: bytes) -> list:
    """Frames laid back to back (no noise): each one's fields, asserting sync and CRC."""
    assert len(data) % 31 == 0
    out = []
    for k in range(0, len(data), 31):
        f = data[k:k + 31]
        assert f[:2] == b"\xa5\x5a" and f[2] == 1
        assert ref_crc(f[2:29]) == int.from_bytes(f[29:31], "little")
        counts = tuple(int.from_bytes(f[9 + 2 * a:11 + 2 * a], "little", signed=True) for a in range(3))
        forces = tuple(struct.unpack("<f", f[17 + 4 * a:21 + 4 * a])[0] for a in range(3))
        out.append({"seq": f[3], "status": f[4], "t_us": int.from_bytes(f[5:9], "little"), "counts": counts,
                    "t_raw": int.from_bytes(f[15:17], "little"), "forces": forces})
    return out


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


# --- the package on disk, imported, installed ---------------------------------------------------------------

def write_tree(files: dict, root: Path) -> Path:
    for relative, data in files.items():
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return root


@contextmanager
def imported(rendered: dict, root: Path):
    """The generated package imported in this process from its source tree under ``root``."""
    write_tree(rendered, root)
    src = str(root / "readout" / "src")
    sys.path.insert(0, src)
    try:
        yield importlib.import_module("magfab_readout")
    finally:
        sys.path.remove(src)
        for name in [n for n in sys.modules if n == "magfab_readout" or n.startswith("magfab_readout.")]:
            del sys.modules[name]


def listing(folder: Path) -> list:
    """Every file and folder under ``folder``: (relative path, size or None for a folder), sorted."""
    return sorted((p.relative_to(folder).as_posix(), None if p.is_dir() else p.stat().st_size)
                  for p in folder.rglob("*"))


def _pip(python: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """pip acting on the environment of ``python``: this interpreter's pip with ``--python`` (pip 22.3 or newer;
    the environment then needs no pip of its own, which takes seconds to install), else the environment's own
    (installed by ensurepip the first time)."""
    proc = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), *args], cwd=cwd,
                          capture_output=True, text=True, timeout=240)
    if "no such option: --python" not in proc.stderr:
        return proc
    subprocess.run([str(python), "-m", "ensurepip", "--default-pip"], capture_output=True, timeout=240)
    return subprocess.run([str(python), "-m", "pip", *args], cwd=cwd, capture_output=True, text=True, timeout=240)


def install(rendered: dict, root: Path) -> SimpleNamespace:
    """The package pip-installed into a fresh virtual environment under ``root`` as the README says, from the
    folder holding ``readout/`` (``pip install ./readout``): first as a user would (build isolation: the build
    backend and pyserial from the index), then offline with what the system has (``--no-build-isolation
    --no-deps``); skips when neither works. ``before`` and ``after`` list that folder around the install."""
    bundle = write_tree(rendered, root / "bundle")
    venv = root / "venv"
    made = subprocess.run([sys.executable, "-m", "venv", "--without-pip", "--system-site-packages", str(venv)],
                          capture_output=True, text=True, timeout=120)
    if made.returncode != 0:
        pytest.skip(f"cannot create a virtual environment here: {made.stderr.strip()[-500:]}")
    python = venv / "bin" / "python"
    log = []
    before = listing(bundle)
    for extra in ([], ["--no-build-isolation", "--no-deps"]):
        proc = _pip(python, bundle, "install", "--quiet", *extra, "./readout")
        if proc.returncode == 0:
            break
        log.append(proc.stderr.strip()[-800:])
    else:
        pytest.skip("pip cannot install the generated package here: " + " | ".join(log))
    serial = subprocess.run([str(python), "-c", "import serial"], capture_output=True).returncode == 0
    return SimpleNamespace(python=python, script=venv / "bin" / "magfab-readout", serial=serial, root=root,
                           bundle=bundle, before=before, after=listing(bundle))


# --- the command on a package of a build, against the simulated board whose EEPROM a file keeps ------------------

def readout_command(bench: dict, *args, timeout: float = 180) -> subprocess.CompletedProcess:
    """``python -m magfab_readout ARGS --simulate --simulate-eeprom FILE`` on the package of ``bench["build"]``, in
    ``bench["cwd"]``, with no sensor root in the environment (the sensor tests' benches)."""
    from magfab.formats.sensor_records import ROOT_ENV

    env = {k: v for k, v in os.environ.items() if k != ROOT_ENV}
    env["PYTHONPATH"] = str(bench["build"].out_dir / "readout" / "src")
    return subprocess.run([sys.executable, "-m", "magfab_readout", *map(str, args), "--simulate", "--simulate-eeprom",
                           str(bench["eeprom"])], capture_output=True, text=True, timeout=timeout, env=env,
                          cwd=bench["cwd"])


def snapshot(root: Path) -> dict:
    """Every file under ``root`` and its bytes."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def board_bytes(bench: dict) -> bytes:
    """The simulated board's EEPROM as its file keeps it (empty before the first write)."""
    return bench["eeprom"].read_bytes() if bench["eeprom"].exists() else b""


def assert_refused(bench: dict, message: str, *args) -> None:
    """``magfab-readout ARGS`` exits 2 with one line on stderr holding ``message``, and writes nothing to the board
    or the sensor records of ``bench["root"]``."""
    board, record = board_bytes(bench), snapshot(bench["root"])
    proc = readout_command(bench, *args)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert len(proc.stderr.splitlines()) == 1 and proc.stderr.startswith("magfab-readout: error: "), proc.stderr
    assert message in proc.stderr
    assert board_bytes(bench) == board and snapshot(bench["root"]) == record
