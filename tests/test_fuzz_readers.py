"""Byte-level fuzzing of every reader of a user's file or byte stream, in magfab and in magfab-readout (the
adversarial pass's second class, after the size and shape bounds of test_adversarial_inputs.py).

For any bytes a reader either gives a value or raises its package's documented input error, whose message is one
line: magfab's :class:`~magfab.errors.InputError` (and the sensor records' ``RecordError``, which magfab's commands
report as one), magfab-readout's own types (those its command line exits 2 on: ``UsageError``, ``InputFileError``,
``DeviceError``, ``CalibrationError``, ``FormatError``, ``EepromError``, ``IdentityError``, ``RecordError``). No
other exception escapes (no KeyError, TypeError, ValueError, IndexError, UnicodeDecodeError, RecursionError,
OverflowError or struct.error), a reader writes nothing to stdout or stderr, and none runs on: each call has a
watchdog far above what a reader takes, which only a reader that loops for ever trips.

The readers, by the file or stream they read:

magfab (the ``magfab`` command's inputs)
    scan CSV               ``magfab.formats.scan_csv.read_scan_csv`` (a calibration scan, and a recording read
                           without the force columns), ``read_recording`` (magfab-readout's ``record`` output, of a
                           single taxel or of one taxel of an array) and ``read_reference`` (a reference sensor's log)
    calibration.json       ``magfab.formats.calibration_json.loads`` (the readout's validator, one copy) and
                           ``magfab.models.calibration.Calibration.from_json`` (magfab's model of it, which also
                           reads the thermal object's informative keys); a build's present calibration through
                           ``magfab.models.scan_guards.reject_self_calibrated_file``
    acceptance.json        ``magfab.formats.acceptance_json.loads``
    array.json             ``magfab.formats.bounded.loads_json`` then ``magfab.formats.array_json.validate`` (and its
                           compensation applied once), and a build's array.json through ``magfab.array_bench``
    spec TOML              ``magfab.spec.load_spec`` (``magfab.toml_input.read_toml`` and ``loads_toml``, then the
                           spec's model); targets TOML: ``magfab.inverse.targets.load_targets``; a build's
                           spec.json: ``magfab.spec.load_build_spec``
    sensor records         ``magfab.formats.sensor_records`` (sensors.json, sensor.json, events/NNNNNN-KIND.json:
                           ``Sensor.info``, ``events``, ``epoch``, ``calibrations``, ``current_calibration``,
                           ``owner_of``, ``list_sensors``) and what ``magfab sensor show/list`` computes from them
                           (``magfab.sensors.history``, ``summary``, ``comparisons``)

magfab-readout (a build's package, rendered and imported as the user's Python imports it)
    serial stream          ``frames.Decoder.feed`` (binary force and field frames, text lines, the info line, the
                           EEPROM command replies), fed in arbitrary pieces: it never raises at all, and every
                           sample, info line and reply it gives comes from a frame whose CRC or a line whose
                           checksum holds (checked against the bytes fed, independently of the decoder)
    the board's replies    ``device.Device.info``, ``check_info`` and ``read_identity`` on a board that answers with
                           the bytes given
    EEPROM record          ``eeprom.check`` (any bytes), and ``unpack_header``, ``addresses``, ``thermal``,
                           ``reference`` of a record ``check`` accepts; the identity block: ``identity.unpack``
                           (an Identity or None, never an error)
    calibration.json       ``calibration.Calibration.from_json``, and ``upload CALIBRATION.json``'s path
                           (``bounded.loads_json``, then ``device.calibration_record``: the validator and the
                           EEPROM layout)
    array.json             ``taxels.ArrayCalibration.from_files`` (array.json and the taxel files it names)

Not here: build.json and crosstalk.json, the package's own data that magfab writes into it (no user hands them
in); Intel HEX, which magfab writes (``eeprom.intel_hex``) and nothing reads back.

Each reader meets three kinds of input: (a) random bytes; (b) a valid file the project itself writes, mutated at
the byte level (bits flipped, cut short, a span repeated, deleted or replaced, and NUL, a BOM, CR, huge numbers,
NaN, inf, 1e999, negative zero or bytes that are not UTF-8 put in), with every cut of it in a test of its own;
(c) structure-aware: the valid document parsed, values swapped for wrong types, deep nesting, empty containers
and extreme numbers, keys dropped or added, and written again (JSON, TOML, CSV). The default run keeps the budget
small; ``-m slow`` runs each with many more examples and every cut of every file. The bugs the fuzzers found are
kept as explicit cases at the end."""

from __future__ import annotations

import contextlib
import copy
import importlib
import io
import json
import math
import re
import shutil
import signal
import struct
import sys
import tempfile
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import tomli_w
from hypothesis import given, settings
from hypothesis import strategies as st
from readout_support import make_calibration, write_tree

from magfab.errors import InputError

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "magfab" / "examples"
#: Examples each (reader, kind of input) runs by default, and with ``-m slow``.
EXAMPLES_DEFAULT = 50
EXAMPLES_SLOW = 600
#: Cuts of each valid file the default run tries (spread over the file, plus its first and last bytes); the slow
#: run tries every one.
CUTS_DEFAULT = 48
#: Longest message an error may carry: values are shown cut (magfab.errors.shown), so a line longer than this holds
#: a value shown whole, e.g. a name of 5,000 characters.
MAX_MESSAGE = 2000
#: A reader still running after this long loops for ever (the slowest takes well under a second).
WATCHDOG_S = 30
DEFAULT = settings(max_examples=EXAMPLES_DEFAULT, deadline=None, derandomize=True, database=None)
SLOW = settings(DEFAULT, max_examples=EXAMPLES_SLOW)


# --- what every reader must do -----------------------------------------------------------------------------------

class Hang(Exception):
    """The watchdog fired: a reader ran past :data:`WATCHDOG_S`."""


@contextlib.contextmanager
def watchdog() -> Iterator[None]:
    """:class:`Hang` in the reader when it runs past :data:`WATCHDOG_S` (a real-time timer: no clock is asserted,
    only an endless loop ends the test)."""
    def fire(signum, frame):
        raise Hang(f"a reader ran for more than {WATCHDOG_S} s")

    previous = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, WATCHDOG_S)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def one_line(exc: BaseException) -> str:
    message = str(exc).strip()
    assert message and not any(c in message for c in "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"), repr(message)
    assert len(message) <= MAX_MESSAGE, message[:300]
    return message


def outcome(read: Callable[[Any], Any], data: Any, errors: tuple[type[BaseException], ...]) -> Any:
    """``read(data)``'s value, or None when it raised one of ``errors`` in one line; anything else raised fails the
    test, and so does a reader that prints."""
    out, err = io.StringIO(), io.StringIO()
    with watchdog(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            return read(data)
        except errors as exc:
            one_line(exc)
            return None
        finally:
            assert out.getvalue() == err.getvalue() == "", (out.getvalue() + err.getvalue())[:500]


# --- generators ----------------------------------------------------------------------------------------------------

#: What a mutation puts into a file: the bytes that break parsers (NUL, a BOM, CR, line separators, bytes that are
#: not UTF-8, an unpaired surrogate's escape), numbers past every range, and the punctuation of JSON, TOML and CSV.
TOKENS = [b"\x00", b"\xef\xbb\xbf", b"\r", b"\r\n", b"\n", b"\x85", "\u2028".encode(), b"\xff", b"\xfe\xff", b"\xc3(",
          b"\x80", b"\xed\xa0\x80", "é".encode(), "１".encode(), b"1e999", b"-1e999", b"1e-400", b"NaN", b"nan",
          b"-inf", b"inf", b"Infinity", b"-0", b"-0.0", b"9" * 400, b"9" * 5000, b"1_000", b"0x10", b"1e308",
          b"5e-324", b"true", b"null", b"[]", b"{}", b'"', b"'", b",", b".", b"=", b"#", b"[", b"]", b"{", b"}",
          b"[[", b"]]", b'"""', b"'''", b"\\", b'"\\u0000"', b'"\\ud800"', b"1979-05-27T07:32:00Z", b" ", b"\t"]


@st.composite
def mutated(draw, valid: bytes) -> bytes:
    """``valid`` with one to three byte-level changes."""
    data = bytearray(valid)
    for _ in range(draw(st.integers(1, 3))):
        n = len(data)
        at = draw(st.integers(0, n))
        span = draw(st.integers(1, 64))
        op = draw(st.sampled_from(["flip", "cut", "repeat", "insert", "replace", "delete"]))
        if op == "flip" and n:
            for k in draw(st.lists(st.integers(0, n - 1), min_size=1, max_size=4)):
                data[k] ^= 1 << draw(st.integers(0, 7))
        elif op == "cut":
            del data[at:]
        elif op == "repeat":
            data[at:at] = data[at:at + span]
        elif op == "insert":
            data[at:at] = draw(st.sampled_from(TOKENS))
        elif op == "replace":
            data[at:at + draw(st.integers(1, 8))] = draw(st.sampled_from(TOKENS))
        else:
            del data[at:at + span]
    return bytes(data)


def cuts(valid: bytes, every: bool) -> list[int]:
    """Where to cut ``valid``: everywhere, or at :data:`CUTS_DEFAULT` places spread over it plus its ends."""
    if every or len(valid) <= CUTS_DEFAULT:
        return list(range(len(valid) + 1))
    spread = np.linspace(0, len(valid), CUTS_DEFAULT).astype(int).tolist()
    return sorted({*spread, *range(8), *range(len(valid) - 8, len(valid) + 1)})


def deep(depth: int, leaf: Any = 1) -> Any:
    for _ in range(depth):
        leaf = [leaf]
    return leaf


#: Values put in place of a document's own: every JSON type, empty containers, the extreme numbers (an integer
#: past a float's range, the largest and smallest floats, negative zero, NaN and the infinities, which Python's
#: json writes and reads), strings that look like numbers, text with line breaks.
WRONG = [None, True, False, 0, -1, 1, 2, 255, 256, 2**31, 2**53 + 1, 2**64, -2**63, 10**400, -10**400, 1e308,
         -1e308, 5e-324, -0.0, math.nan, math.inf, -math.inf, "", "x", "1e999", "NaN", "0x10", "a\nb", "\u2028",
         "N42" * 2000, [], {}, [[]], [None], [1.0, 2.0], [0.0, 0.0, 0.0], [[0.0, 0.0]] * 3, {"a": 1}, {"\n": 1}]


def paths(node: Any, at: tuple = ()) -> Iterator[tuple]:
    yield at
    if isinstance(node, dict):
        for k, v in node.items():
            yield from paths(v, (*at, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from paths(v, (*at, i))


@st.composite
def changed_tree(draw, doc: Any, values: list) -> Any:
    """``doc`` (parsed JSON or TOML) with one to three of its values replaced by one of ``values`` or nested up to
    40 deep, deleted, repeated in a list, or joined by an unknown key."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        where = [p for p in paths(doc) if p]
        if not where:
            break
        path = draw(st.sampled_from(where))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        key = path[-1]
        op = draw(st.sampled_from(["value", "value", "nest", "delete", "grow"]))
        wrong = copy.deepcopy(draw(st.sampled_from(values)))  # a copy: the list's own containers stay empty
        if op == "value":
            parent[key] = wrong
        elif op == "nest":
            parent[key] = deep(draw(st.integers(1, 40)), parent[key])
        elif op == "delete":
            del parent[key]
        elif isinstance(parent[key], dict):
            parent[key][draw(st.sampled_from(["x", "format", "taxel", "\n", ""]))] = wrong
        elif isinstance(parent[key], list):
            parent[key].append(wrong)
        else:
            parent[key] = [parent[key], parent[key]]
    return doc


def json_variants(doc: Any) -> st.SearchStrategy[bytes]:
    return changed_tree(doc, WRONG).map(lambda d: json.dumps(d, allow_nan=True).encode("utf-8"))


def _toml_value(x: Any) -> bool:
    """Whether TOML can hold ``x`` (it has no null, and tomli_w writes no NaN inside an array of tables)."""
    if x is None:
        return False
    if isinstance(x, dict):
        return all(_toml_value(v) for v in x.values())
    if isinstance(x, list):
        return all(_toml_value(v) for v in x)
    return True


def _toml_dumps(doc: Any) -> bytes | None:
    try:
        return tomli_w.dumps(doc).encode("utf-8")
    except (TypeError, ValueError):  # a document TOML cannot hold (e.g. a list mixing tables and values)
        return None


def toml_variants(doc: dict) -> st.SearchStrategy[bytes]:
    values = [v for v in WRONG if _toml_value(v)]
    return changed_tree(doc, values).map(_toml_dumps).filter(lambda b: b is not None)


CELLS = ["nan", "NaN", "inf", "-inf", "Infinity", "-0", "-0.0", "1e999", "-1e999", "1e-400", "", " ", "1_000", "１",
         "0x10", "9" * 400, "\x00", '"1"', "1,2", "+1", ".5", "5.", "1e5", "\ufeff1", " 1 ", "1e", "--1", "١"]


@st.composite
def csv_variants(draw, valid: bytes) -> bytes:
    """``valid`` (a CSV of comments, a header and rows) changed as a spreadsheet or a hand edit changes it: a
    cell swapped for a form that is not a plain decimal (or is, at the edge of a band), a column dropped, repeated
    or renamed in the header, a cell added to or taken from a row, rows dropped or swapped, other line ends, a
    BOM, comments inside."""
    lines = valid.decode("utf-8").splitlines()
    body = [k for k, line in enumerate(lines) if line and not line.startswith("#")]
    header = body[0]
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["cell", "cell", "header", "width", "rows", "swap", "ends", "bom", "comment"]))
        row = draw(st.sampled_from(body))
        cells = lines[row].split(",")
        if op == "cell":
            cells[draw(st.integers(0, len(cells) - 1))] = draw(st.sampled_from(CELLS))
            lines[row] = ",".join(cells)
        elif op == "header":
            names = lines[header].split(",")
            k = draw(st.integers(0, len(names) - 1))
            names[k] = draw(st.sampled_from([names[0], names[-1], "", "Bz_uT ", "BZ_UT", "taxel", "Fx_sensor_N"]))
            lines[header] = ",".join(names)
        elif op == "width":
            lines[row] = ",".join(cells[:-1] if draw(st.booleans()) else [*cells, "0"])
        elif op == "rows":
            keep = draw(st.integers(0, len(body)))
            lines = lines[:body[0] + 1 + keep] if keep < len(body) else lines
            body = [k for k in body if k < len(lines)]
        elif op == "swap" and len(body) > 2:
            a, b = body[1], body[-1]
            lines[a], lines[b] = lines[b], lines[a]
        elif op == "comment":
            lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(["#", "# x,y", "  # c", ",,,"])))
            body = [k for k, line in enumerate(lines) if line and not line.startswith("#")]
            header = body[0]
    end = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    text = end.join(lines) + draw(st.sampled_from([end, ""]))
    return (("\ufeff" if draw(st.booleans()) else "") + text).encode("utf-8")


# --- the valid files ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def readout(tmp_path_factory) -> Iterator[SimpleNamespace]:
    """MagOne's readout package, rendered by magfab and imported as the user's Python imports it (under its own
    name, with its own error types), and those types: what its command line exits 2 on."""
    from magfab import derive, load_spec
    from magfab.export.readout import render

    root = tmp_path_factory.mktemp("readout")
    write_tree(render(derive(load_spec(None)), make_calibration()), root)
    src = str(root / "readout" / "src")

    def forget() -> None:
        for name in [n for n in sys.modules if n == "magfab_readout" or n.startswith("magfab_readout.")]:
            del sys.modules[name]

    forget()  # a source tree imported before (it has no build data) must not stand in for the build's package
    sys.path.insert(0, src)
    try:
        names = ["bounded", "calibration", "cli_shared", "device", "eeprom", "frames", "identity", "json_checks",
                 "records", "taxels"]
        m = SimpleNamespace(**{n: importlib.import_module(f"magfab_readout.{n}") for n in names})
        m.errors = (m.cli_shared.UsageError, m.bounded.InputFileError, m.device.DeviceError,
                    m.calibration.CalibrationError, m.json_checks.FormatError, m.eeprom.EepromError,
                    m.identity.IdentityError, m.records.RecordError)
        yield m
    finally:
        sys.path.remove(src)
        forget()


def calibration_doc() -> dict:
    """The readout tests' calibration with a thermal object as magfab's fit writes it (every informative key)."""
    from magfab.models.calibration_thermal import ThermalFit

    doc = make_calibration()
    doc["thermal"] = ThermalFit(25.0, (-0.0012, -0.0012, -0.0011), "fit", (1e-5, 1e-5, 2e-5), 30.0, -0.0012,
                                "fitted to the scan").as_json()
    return doc


def scan_bytes() -> bytes:
    """A calibration scan as magfab writes one (:func:`magfab.formats.scan_csv.scan_csv`): an 8 x 8 raster of
    (Bz, Br) with its forces and the temperature, 64 rows."""
    from magfab.formats.scan_csv import Scan, scan_csv

    bz, br = np.meshgrid(np.linspace(15000.0, 25000.0, 8), np.linspace(0.0, 4000.0, 8))
    bz, br = bz.ravel(), br.ravel()
    n = bz.size
    B = np.column_stack([br * 0.6, -br * 0.8, bz])
    F = np.column_stack([br * 1e-4, -br * 2e-4, (bz - 15000.0) * 2e-4])
    scan = Scan(np.arange(n) * 0.01, B, F, np.full(n, 24.5))
    return scan_csv(scan, ["scan of the fuzz tests"]).encode("utf-8")


def recording_bytes(columns: tuple[str, ...], taxels: int = 1) -> bytes:
    """A recording in magfab-readout ``record``'s columns (``columns``; an array's with a ``taxel`` column), 12
    samples of each taxel, with the comment lines ``record`` begins with."""
    names = [*columns, "taxel"] if taxels > 1 else list(columns)
    lines = ["# magfab-readout 0.1.0 record", "# spec: \"magone\"", ",".join(names)]
    for i in range(12):
        for k in range(taxels):
            values = {"time_s": f"{0.01 * i:.6f}", "host_time_s": f"{1.7e9 + 0.01 * i:.6f}", "Bx_uT": "12.50",
                      "By_uT": "-3.25", "Bz_uT": f"{20000 + 40 * i:.2f}", "temperature_C": "24.50",
                      "Fx_sensor_N": "0.0100", "Fy_sensor_N": "-0.0020", "Fz_sensor_N": f"{0.05 * i:.4f}",
                      "status": "0", "seq": str(i), "taxel": str(k)}
            lines.append(",".join(values.get(c, "0") for c in names))
    return ("\n".join(lines) + "\n").encode("utf-8")


def reference_bytes() -> bytes:
    rows = ["# reference force sensor", "time_s,Fx_N,Fy_N,Fz_N"]
    rows += [f"{1.7e9 + 0.005 * i:.4f},0.010,-0.002,{0.025 * i:.4f}" for i in range(24)]
    return ("\n".join(rows) + "\n").encode("utf-8")


def acceptance_doc() -> dict:
    """acceptance.json as the format tests have it (tests/formats/test_calibration_json.py), with both drift
    sections."""
    return {
        "format": "magfab-acceptance/1",
        "rest": {"Bz_uT": {"min": 18000.0, "nominal": 20000.0, "max": 22000.0}, "Bxy_max_uT": 900.0,
                 "earth_field_uT": 65.0},
        "weight": {"weight_g": 20.0, "max_weight_g": 100.0,
                   "table": {"force_N": [0.0, 0.5, 1.0], "delta_Bz_min_uT": [0.0, 400.0, 800.0],
                             "delta_Bz_nominal_uT": [0.0, 500.0, 1000.0], "delta_Bz_max_uT": [0.0, 600.0, 1200.0]}},
        "measurement": {"noise_z_uT": 5.0, "noise_xy_uT": 3.0, "allowance_sigmas": 4.0},
        "magnet": {"grade": "N42", "remanence_T": {"low": 1.28, "nominal": 1.3, "high": 1.32}},
        "rotation": {"band_uT": 40.0, "earth_change_uT": 130.0, "self_weight_change_uT": 3.0,
                     "gradient_uT_per_mm": 900.0, "self_weight_mN": 4.0, "predicted_normal_rest_mN": None},
        "warmup": {"min_change_C": 5.0, "per_C_mN": {"without": 2.0, "with": 0.2, "fitted": 0.1}, "noise_mN": 1.0,
                   "magnet_pct_per_C": -0.12, "channel_mN_per_uT": 0.05},
    }


@pytest.fixture(scope="module")
def array_doc() -> dict:
    """array.json of a 1 x 2 strip as magfab writes it (the layout and the exact field tables, without a fit)."""
    from magfab import derive
    from magfab.formats.array_json import FORMAT
    from magfab.models.taxels import array_field
    from magfab.spec import parse_spec

    design = derive(parse_spec('[array]\nrows = 1\ncols = 2\npitch_mm = 14.0\npolarity = "alternating"\n', "strip"))
    doc = {"format": FORMAT, "dynamic": True, **array_field(design).as_json(),
           "taxels": [{**t.as_dict(), "calibration": f"taxel_{t.index:02d}.json"} for t in design.taxels]}
    return json.loads(json.dumps(doc))


# --- the readers: name -> how to read bytes, the valid bytes, the errors allowed, and the structured variants ------

def _in_folder(name: str, data: bytes, read: Callable[[Path], Any]) -> Any:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_bytes(data)
        return read(path)


def _targets(data: bytes) -> Any:
    from magfab.inverse.targets import load_targets

    return _in_folder("targets.toml", data, load_targets)


def _spec(data: bytes) -> Any:
    from magfab.spec import load_spec

    return _in_folder("fuzz.toml", data, load_spec)


def _spec_json(data: bytes) -> Any:
    from magfab.spec import load_build_spec

    return _in_folder("spec.json", data, lambda path: load_build_spec(path.parent))


def _calibration_model(data: bytes) -> Any:
    """magfab's model of the file (:meth:`Calibration.from_json` on what parses within bounds: its callers, the
    sensor records and the guard below, refuse what does not before the model sees it), and the guard that reads a
    build's present calibration from its folder (skipping one that has gone bad)."""
    from magfab.formats import bounded
    from magfab.formats.scan_csv import read_scan_csv
    from magfab.models.calibration import Calibration
    from magfab.models.scan_guards import reject_self_calibrated_file

    scan = read_scan_csv(scan_bytes())
    far = replace(scan, F_N=scan.F_N + 100.0)  # forces the calibration does not give: the guard lets it pass
    _in_folder("calibration.json", data, lambda path: reject_self_calibrated_file(far, path, 5.0))
    try:
        doc = bounded.loads_json(data, "calibration.json")
    except bounded.InputFileError:
        raise
    except ValueError:
        return None
    return Calibration.from_json(doc)


def _array(data: bytes) -> Any:
    """A build's array.json as ``magfab calibrate`` of an array's taxel reads it (:mod:`magfab.array_bench`)."""
    from magfab.array_bench import _offsets

    return _in_folder("array.json", data, _offsets)


def magfab_readers(array: dict) -> dict[str, tuple[Callable[[bytes], Any], bytes, st.SearchStrategy[bytes] | None]]:
    from magfab.formats import acceptance_json, bounded, calibration_json, scan_csv
    from magfab.toml_input import loads_toml

    recording = ("time_s", "host_time_s", "Bx_uT", "By_uT", "Bz_uT", "temperature_C", "Fx_sensor_N", "Fy_sensor_N",
                 "Fz_sensor_N", "status", "seq")
    scan, cal, acc = scan_bytes(), json.dumps(calibration_doc()).encode(), json.dumps(acceptance_doc()).encode()
    spec, targets = (EXAMPLES / "magone.toml").read_bytes(), (EXAMPLES / "targets.toml").read_bytes()
    from magfab.spec import load_spec

    spec_json = json.dumps(load_spec(None).dump()).encode()
    single, arrayed = recording_bytes(recording), recording_bytes(recording, taxels=3)
    return {
        "scan CSV": (scan_csv.read_scan_csv, scan, csv_variants(scan)),
        "scan CSV as a recording": (lambda b: scan_csv.read_scan_csv(b, require_force=False, min_rows=2), scan,
                                    csv_variants(scan)),
        "recording": (scan_csv.read_recording, single, csv_variants(single)),
        "recording of an array's taxel": (lambda b: scan_csv.read_recording(b, taxel=1), arrayed,
                                          csv_variants(arrayed)),
        "reference log": (scan_csv.read_reference, reference_bytes(), csv_variants(reference_bytes())),
        "calibration.json": (calibration_json.loads, cal, json_variants(calibration_doc())),
        "calibration.json, magfab's model": (_calibration_model, cal, json_variants(calibration_doc())),
        "acceptance.json": (acceptance_json.loads, acc, json_variants(acceptance_doc())),
        "array.json": (_array, json.dumps(array).encode(), json_variants(array)),
        "spec TOML": (_spec, spec, toml_variants(tomllib.loads(spec.decode()))),
        "targets TOML": (_targets, targets, toml_variants(tomllib.loads(targets.decode()))),
        "spec.json": (_spec_json, spec_json, json_variants(json.loads(spec_json))),
        "bounded JSON": (lambda b: bounded.loads_json(b, "JSON"), cal, json_variants(calibration_doc())),
        "bounded TOML": (lambda b: loads_toml(b.decode("utf-8"), "spec", "fuzz.toml"), spec,
                         toml_variants(tomllib.loads(spec.decode()))),
    }


#: What each magfab reader may raise besides InputError: the bounded TOML parser passes tomllib's errors and a text
#: that is not UTF-8 on to its callers (the spec and targets readers), which turn them into a SpecError.
PASSED_ON = {"bounded TOML": (tomllib.TOMLDecodeError, ValueError), "bounded JSON": (ValueError,)}


@pytest.fixture(scope="module")
def magfab_table(array_doc):
    return magfab_readers(array_doc)


MAGFAB_READERS = ["scan CSV", "scan CSV as a recording", "recording", "recording of an array's taxel",
                  "reference log", "calibration.json", "calibration.json, magfab's model", "acceptance.json",
                  "array.json", "spec TOML", "targets TOML", "spec.json", "bounded JSON", "bounded TOML"]


def magfab_read(table, name: str, data: bytes) -> Any:
    from magfab.formats import sensor_records

    read = table[name][0]
    if name == "bounded TOML":  # its callers decode; bytes that are not UTF-8 never reach it
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            return None
    return outcome(read, data, (InputError, sensor_records.RecordError, *PASSED_ON.get(name, ())))


def test_every_valid_file_is_read(magfab_table):
    for name in MAGFAB_READERS:
        read, valid, _ = magfab_table[name]
        assert read(valid) is not None or name == "calibration.json, magfab's model", name


@pytest.mark.parametrize("name", MAGFAB_READERS)
@DEFAULT
@given(data=st.data())
def test_random_bytes(magfab_table, name, data):
    magfab_read(magfab_table, name, data.draw(st.binary(max_size=4096)))


@pytest.mark.parametrize("name", MAGFAB_READERS)
@DEFAULT
@given(data=st.data())
def test_a_valid_file_mutated(magfab_table, name, data):
    magfab_read(magfab_table, name, data.draw(mutated(magfab_table[name][1])))


@pytest.mark.parametrize("name", MAGFAB_READERS)
@DEFAULT
@given(data=st.data())
def test_a_valid_document_with_wrong_values(magfab_table, name, data):
    magfab_read(magfab_table, name, data.draw(magfab_table[name][2]))


@pytest.mark.parametrize("name", MAGFAB_READERS)
def test_a_valid_file_cut_short(magfab_table, name):
    valid = magfab_table[name][1]
    for cut in cuts(valid, every=False):
        magfab_read(magfab_table, name, valid[:cut])


@pytest.mark.slow
@pytest.mark.parametrize("name", MAGFAB_READERS)
@SLOW
@given(data=st.data())
def test_exhaustively(magfab_table, name, data):
    valid, structured = magfab_table[name][1:]
    kind = data.draw(st.sampled_from(["random", "mutated", "structured"]))
    drawn = {"random": st.binary(max_size=65536), "mutated": mutated(valid), "structured": structured}[kind]
    magfab_read(magfab_table, name, data.draw(drawn))


@pytest.mark.slow
@pytest.mark.parametrize("name", MAGFAB_READERS)
def test_every_cut(magfab_table, name):
    valid = magfab_table[name][1]
    for cut in cuts(valid, every=True):
        magfab_read(magfab_table, name, valid[:cut])


# --- sensor records ----------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def record(tmp_path_factory) -> Path:
    """A sensor root whose record has every kind of event that is read back: added (keeping spec.json and
    acceptance.json), two calibrations on two skins (a reskin between them), a check, an upload, a note."""
    from magfab.formats import sensor_records as rec
    from magfab.spec import load_spec

    root = tmp_path_factory.mktemp("records") / "sensors"
    cal = json.dumps(make_calibration()).encode()
    figures = {"taxel": None, "rest_field_uT": [12.0, -3.0, 20000.0], "sensitivity_normal_uT_per_N": 900.0,
               "sensitivity_shear_uT_per_N": 300.0, "range_normal_N": 5.0, "range_shear_N": 2.0,
               "rms_holdout_Fz_mN": 12.0, "rms_holdout_Fr_mN": 11.0, "method": "poly", "order": 4}
    rec.create(root, "finger-01", {"spec_name": "magone", "taxels": None},
               {"spec.json": json.dumps(load_spec(None).dump()).encode(),
                "acceptance.json": json.dumps(acceptance_doc()).encode()},
               date="2026-11-28T14:05:00Z",
               then=[("calibration", figures, {"calibration.json": cal, "scan.csv": scan_bytes()}),
                     ("check", {"taxel": None, "verdict": "pass", "calibration_sha256": "ab" * 32,
                                "figures": {"Bz_rest_uT": 20010.0, "Bz_rise_uT": 420.0, "weight_g": 20.0,
                                            "turned_dFz_mN": None},
                                "steps": [{"name": "rest", "verdict": "pass", "text": "ok"}]}, {}),
                     ("upload", {"taxel": None, "calibration_sha256": "ab" * 32}, {}),
                     ("reskin", {"note": "torn skin replaced"}, {}),
                     ("calibration", dict(figures, rest_field_uT=[11.0, -2.0, 20100.0]), {"calibration.json": cal}),
                     ("note", {"text": "kept in the drawer"}, {})])
    return root


def record_files(root: Path) -> list[str]:
    """The files of the record a reader parses: the root's marker, sensor.json and every event (the kept files are
    checked against their hash before they are parsed)."""
    sensor = root / "finger-01"
    return ["sensors.json", "finger-01/sensor.json",
            *(f"finger-01/events/{p.name}" for p in sorted((sensor / "events").iterdir()))]


def read_record(root: Path) -> None:
    """Everything magfab and magfab-readout read from a record."""
    from magfab import sensors
    from magfab.formats import sensor_records as rec

    rec.list_sensors(root)
    sensor = rec.open_sensor(root, "finger-01")
    sensor.info  # noqa: B018 - a property that reads sensor.json
    sensor.events()
    sensor.epoch()
    list(sensor.calibrations())
    sensor.current_calibration()
    rec.owner_of(root, "ab" * 32)
    sensors.history(sensor)
    sensors.summary(sensor)
    sensors.comparisons(sensor)


def record_outcome(root: Path, relative: str, data: bytes) -> None:
    from magfab.formats import sensor_records as rec

    with tempfile.TemporaryDirectory() as folder:
        copy_root = Path(folder) / "sensors"
        shutil.copytree(root, copy_root)
        (copy_root / relative).write_bytes(data)
        outcome(read_record, copy_root, (InputError, rec.RecordError))


@st.composite
def record_change(draw, root: Path, kind: str) -> tuple[str, bytes]:
    relative = draw(st.sampled_from(record_files(root)))
    valid = (root / relative).read_bytes()
    if kind == "random":
        return relative, draw(st.binary(max_size=2048))
    if kind == "mutated":
        return relative, draw(mutated(valid))
    return relative, draw(json_variants(json.loads(valid)))


def test_the_record_is_read(record):
    read_record(record)


@pytest.mark.parametrize("kind", ["random", "mutated", "structured"])
@DEFAULT
@given(data=st.data())
def test_a_sensor_record_edited(record, kind, data):
    record_outcome(record, *data.draw(record_change(record, kind)))


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["random", "mutated", "structured"])
@SLOW
@given(data=st.data())
def test_a_sensor_record_edited_exhaustively(record, kind, data):
    record_outcome(record, *data.draw(record_change(record, kind)))


# --- magfab-readout: the serial stream --------------------------------------------------------------------------

def valid_stream(frames, ident: bytes) -> bytes:
    """What a board sends: force frames (one a chip error), text lines, the info line, an array's field frame and
    line, and the answers to an EEPROM write and read, as the firmware encodes them."""
    out = b""
    for i in range(6):
        error = i == 3  # a chip-error frame, its fault word where the temperature goes
        out += frames.encode_frame(i, 1250 * i, 2 if error else i & 1, (10 * i, -i, 4000 + i),
                                   0x0101 if error else 46000, (0.01 * i, -0.02, 0.5 * i))
        out += frames.encode_text_line(i, 1250 * i, 0, (0.01, -0.02, 0.3), (12.5, -3.25, 20000.0 + i), 24.5)
    out += frames.encode_text_line(6, 9000, 2, (math.nan,) * 3, (math.nan,) * 3, None, fault=0x0104)
    out += frames.encode_info_line("magone", "0123456789abcdef", 0, 2, 0, 2)
    out += frames.encode_field_frame(1, 7, 9100, 0, (1, 2, 3), 46000)
    out += frames.encode_cycle_frame(8, 9200, [(0, 0, (1, 2, 3), 46000), (2, 350, (0, 0, 0), 0x0101),
                                               (8, 700, (-4, 5, -6), 46100)])
    out += frames.encode_field_line(1, 7, 9100, 0, (1.5, 2.5, 3.5), 24.0)
    for body in (b"W,0,16,0,0", b"R,960," + ident[:32].hex().upper().encode()):
        out += body + frames.line_checksum(body) + b"\n"
    return out


def _sources(frames, stream: bytes) -> tuple[list[tuple], list[bytes]]:
    """Every binary frame in ``stream`` whose CRC holds (its fields unpacked) and every line whose checksum holds
    (its body): found here from the bytes alone, the oracle the decoder's output is checked against."""
    binary = []
    for m in re.finditer(re.escape(frames.SYNC), stream):
        for length, layout in ((frames.FRAME_LENGTH, "<BBBI3hH3f"), (frames.FIELD_FRAME_LENGTH, "<BBBIB3hH")):
            frame = stream[m.start():m.start() + length]
            if len(frame) == length and frames.crc16_ccitt_false(frame[2:-2]) == struct.unpack("<H", frame[-2:])[0]:
                binary.append(struct.unpack(layout, frame[2:-2]))
        head = stream[m.start():m.start() + 9]  # a cycle frame: each chip's reading as a field frame's fields
        if len(head) == 9 and head[2] == frames.FRAME_CYCLE and 1 <= head[8] <= 16:
            frame = stream[m.start():m.start() + 11 + 11 * head[8]]
            if len(frame) == 11 + 11 * head[8] and frames.crc16_ccitt_false(frame[2:-2]) == struct.unpack(
                    "<H", frame[-2:])[0]:
                seq, t_us = head[3], struct.unpack_from("<I", head, 4)[0]
                for k in range(head[8]):
                    status, dt, bx, by, bz, t_raw = struct.unpack_from("<BH3hH", frame, 9 + 11 * k)
                    binary.append((frames.FRAME_FIELD, seq, status, (t_us + dt) & 0xFFFFFFFF, k, bx, by, bz, t_raw))
    lines = []
    for line in stream.split(b"\n"):
        for start in (m.start() for m in re.finditer(rb"[FIBWR],", line)):
            body, star, check = line[start:].rstrip(b"\r").rpartition(b"*")
            if star and check == b"%04X" % frames.crc16_ccitt_false(body):
                lines.append(body)
    return binary, lines


def check_decoded(readout, stream: bytes, items: list) -> None:
    """Every item the decoder gave has a source in ``stream``, and no sample carries a force the firmware could not
    have meant (module doc of frames.py)."""
    frames = readout.frames
    binary, lines = _sources(frames, stream)
    for item in items:
        if isinstance(item, frames.Sample) and item.source == "binary":
            field = (frames.FRAME_FIELD, item.seq, item.status, item.t_us, item.taxel, *item.counts,
                     item.temperature_raw) in binary
            force = not item.taxel and any(f[:8] == (frames.FRAME_FORCE, item.seq, item.status, item.t_us,
                                                     *item.counts, item.temperature_raw) for f in binary)
            if item.taxel or (math.isnan(item.force_N[0]) and not item.chip_error and not item.full_scale):
                assert field, item  # an array's field frame
            else:  # a force frame; one at full scale or with a chip error has no force, as taxel 0's field reading
                assert force or ((item.full_scale or item.chip_error) and field), item
        elif isinstance(item, frames.Sample):
            head = (b"B,%d,%d,%d,%d," % (item.taxel, item.seq, item.t_us, item.status) if item.taxel else
                    b"F,%d,%d,%d," % (item.seq, item.t_us, item.status))
            assert any(body.startswith(head) for body in lines) or any(
                body.startswith(b"B,0,%d,%d,%d," % (item.seq, item.t_us, item.status)) for body in lines), item
        elif isinstance(item, frames.DeviceInfo):
            assert item.line.encode() in lines, item
        else:
            assert any(body.startswith(b"%s,%d," % (item.kind.encode(), item.address)) for body in lines), item
        if isinstance(item, frames.Sample) and not item.chip_error:
            forces = [f for f in item.force_N if not math.isnan(f)]
            assert all(abs(f) <= frames.FORCE_LIMIT_N for f in forces), item
            assert all(abs(b) <= frames.FIELD_LIMIT_UT for b in item.B_uT) or item.source == "binary", item


def decode(readout, stream: bytes, pieces: list[int]) -> None:
    """``stream`` fed to a decoder in pieces of the sizes ``pieces`` (the rest at once): it must not raise."""
    decoder = readout.frames.Decoder()
    items, at = [], 0
    with watchdog():
        for n in [*pieces, len(stream)]:
            items += decoder.feed(stream[at:at + n])
            at += n
    stats = decoder.stats
    assert stats.bytes == len(stream) and stats.samples >= 0
    check_decoded(readout, stream, items)


@st.composite
def stream_and_pieces(draw, readout, kind: str, max_size: int = 4096) -> tuple[bytes, list[int]]:
    ident = readout.identity.pack(readout.identity.Identity("finger-01", "2026-11-28T14:05:00Z", "0123456789abcdef"))
    valid = valid_stream(readout.frames, ident)
    if kind == "random":
        stream = draw(st.binary(max_size=max_size))
    elif kind == "mutated":
        stream = draw(mutated(valid))
    else:  # frames and lines whose CRC or checksum is wrong, mixed with good ones and noise
        stream = draw(bad_crc_stream(readout.frames, valid))
    return stream, draw(st.lists(st.integers(1, 97), max_size=12))


@st.composite
def bad_crc_stream(draw, frames, valid: bytes) -> bytes:
    """A stream of frames and lines, some sealed right and some with a wrong CRC or checksum (a body byte changed
    after sealing, or the check itself changed), between noise and cut frames."""
    parts = []
    for _ in range(draw(st.integers(1, 12))):
        part = draw(st.sampled_from([
            frames.encode_frame(draw(st.integers(0, 255)), draw(st.integers(0, 2**32 - 1)), draw(st.integers(0, 255)),
                                (draw(st.integers(-32768, 32767)), 0, 100), draw(st.integers(0, 0xFFFF)),
                                (draw(st.sampled_from([0.5, -0.0, 1e30, math.inf, math.nan, 999.0, 1001.0])), 0.0,
                                 1.0)),
            frames.encode_field_frame(draw(st.integers(0, 255)), 3, 100, draw(st.integers(0, 255)), (1, 2, 3), 4),
            frames.encode_cycle_frame(3, 100, [(draw(st.integers(0, 255)), 40 * k, (1, k, 3), 4)
                                               for k in range(draw(st.integers(0, 17)))]),
            frames.encode_text_line(3, 100, draw(st.integers(0, 255)), (0.1, 1e4, 0.2), (1e7, 0.0, 1.0), 25.0),
            frames.encode_info_line("magone", "0123456789abcdef", 0, 2, 0, 2, draw(st.integers(1, 16))),
            b"R,0,A55A01\n", valid[:draw(st.integers(0, len(valid)))]]))
        if draw(st.booleans()):  # spoil it: a byte of the body, or of the check
            k = draw(st.integers(2, max(2, len(part) - 2)))
            part = part[:k] + bytes([part[k - 1] ^ draw(st.integers(1, 255))]) + part[k + 1:] if k < len(part) else part
        parts.append(part)
        parts.append(draw(st.sampled_from([b"", b"\xa5", b"\xa5\x5a", b"F,", b"\n", b"\r\n", b"*", b"\x00" * 3])))
    return b"".join(parts)


@pytest.mark.parametrize("kind", ["random", "mutated", "bad CRC"])
@DEFAULT
@given(data=st.data())
def test_the_decoder_never_raises_nor_invents_a_sample(readout, kind, data):
    decode(readout, *data.draw(stream_and_pieces(readout, kind)))


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["random", "mutated", "bad CRC"])
@SLOW
@given(data=st.data())
def test_the_decoder_exhaustively(readout, kind, data):
    decode(readout, *data.draw(stream_and_pieces(readout, kind, max_size=65536)))


def test_the_decoder_reads_every_cut_of_a_valid_stream(readout):
    ident = readout.identity.pack(readout.identity.Identity("finger-01", "2026-11-28T14:05:00Z", "0123456789abcdef"))
    valid = valid_stream(readout.frames, ident)
    for cut in range(len(valid) + 1):
        decode(readout, valid[:cut], [])
    items = readout.frames.Decoder().feed(valid)
    # 5 force frames and a chip error, 7 lines, the info line, 2 field samples, a cycle frame's 3 samples, 2 replies
    assert len(items) == 21


class Exhausted(Exception):
    """The board has sent everything it had: the command waited for an answer that never came."""


class Board:
    """A transport answering with ``data`` in pieces, then nothing (:class:`Exhausted`, so no test waits for the
    device's timeout)."""

    port = "the fuzz board"

    def __init__(self, data: bytes, pieces: list[int]) -> None:
        self.data, self.pieces = data, [*pieces]

    def read(self, size: int, timeout_s: float) -> bytes:
        if not self.data:
            raise Exhausted
        n = self.pieces.pop(0) if self.pieces else 4096
        out, self.data = self.data[:n], self.data[n:]
        return out

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        pass


def board_answers(readout) -> bytes:
    """The info line of this package's calibration and the identity block, read in two EEPROM read replies."""
    frames = readout.frames
    ident = readout.identity.pack(readout.identity.Identity("finger-01", "2026-11-28T14:05:00Z", "0123456789abcdef"))
    out = frames.encode_info_line("magone", readout.device.Calibration.embedded().short_hash, 0, 2, 0, 2)
    for at in (0, 32):
        body = b"R,%d," % (readout.identity.ADDRESS + at) + ident[at:at + 32].hex().upper().encode()
        out += body + frames.line_checksum(body) + b"\n"
    return out


def ask_board(readout, answers: bytes, pieces: list[int]) -> Any:
    """What ``upload --sensor`` asks a board (its info line, checked against the package, and its identity block)
    of a board answering ``answers``; None when it ran out of answers first."""
    device = readout.device.Device(transport=Board(answers, pieces), timeout_s=60)

    def ask(_: None) -> Any:
        info = device.info()
        with contextlib.suppress(readout.device.CalibrationMismatch):  # another calibration's board: the identity
            device.check_info(info)
        return device.read_identity()

    try:
        return outcome(ask, None, readout.errors)
    except Exhausted:
        return None


def test_the_board_answers_are_read(readout):
    found = ask_board(readout, board_answers(readout), [])
    assert found == readout.identity.Identity("finger-01", "2026-11-28T14:05:00Z", "0123456789abcdef")


@pytest.mark.parametrize("kind", ["random", "mutated"])
@DEFAULT
@given(data=st.data())
def test_the_boards_answers(readout, kind, data):
    answers = data.draw(st.binary(max_size=1024) if kind == "random" else mutated(board_answers(readout)))
    ask_board(readout, answers, data.draw(st.lists(st.integers(1, 64), max_size=8)))


# --- magfab-readout: the EEPROM record and the identity block ---------------------------------------------------

def read_eeprom(readout, data: bytes) -> None:
    eeprom = readout.eeprom
    with watchdog():
        if not eeprom.check(data):
            return
        head = eeprom.unpack_header(data)
        assert head["magic"] == eeprom.MAGIC and head["length"] <= len(data)
        eeprom.addresses(data)
        eeprom.thermal(data)
        eeprom.reference(data)


def read_identity(readout, data: bytes) -> None:
    with watchdog():
        found = readout.identity.unpack(data)
    assert found is None or readout.identity.pack(found) == data[:readout.identity.SIZE]


def eeprom_valid(readout) -> tuple[bytes, bytes]:
    record = readout.device.calibration_record(calibration_doc())
    block = readout.identity.pack(readout.identity.Identity("finger-01", "2026-11-28T14:05:00Z", "0123456789abcdef"))
    return record + b"\xff" * (readout.identity.ADDRESS - len(record)) + block, block


@pytest.mark.parametrize("kind", ["random", "mutated"])
@DEFAULT
@given(data=st.data())
def test_an_eeprom_read_back(readout, kind, data):
    memory, block = eeprom_valid(readout)
    if kind == "random":
        drawn = data.draw(st.binary(max_size=1024))
        read_eeprom(readout, drawn)
        read_identity(readout, drawn)
    else:
        read_eeprom(readout, data.draw(mutated(memory)))
        read_identity(readout, data.draw(mutated(block)))


def test_every_cut_of_an_eeprom_and_its_identity(readout):
    memory, block = eeprom_valid(readout)
    assert readout.eeprom.check(memory) and readout.identity.unpack(block) is not None
    for cut in range(len(memory) + 1):
        read_eeprom(readout, memory[:cut])
    for cut in range(len(block) + 1):
        read_identity(readout, block[:cut])


# --- magfab-readout: calibration.json and array.json ----------------------------------------------------------

def readout_calibration(readout, data: bytes) -> Any:
    """``upload CALIBRATION.json``'s path (cli._upload): parsed within bounds, then the EEPROM record made from it
    (the validator and the layout); and :meth:`Calibration.from_json` on the text."""
    def upload(raw: bytes) -> bytes:
        try:
            parsed = readout.bounded.loads_json(raw, "calibration.json", "fuzz.json")
        except readout.bounded.InputFileError:
            raise
        except ValueError as exc:
            raise readout.calibration.CalibrationError("", "fuzz.json", f"is not valid JSON ({exc})") from None
        return readout.device.calibration_record(parsed)

    outcome(upload, data, readout.errors)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:  # from_json takes text: the command decodes first (bounded.read_text)
        return None
    return outcome(readout.calibration.Calibration.from_json, text, readout.errors)


def readout_array(readout, array: dict, data: bytes) -> Any:
    """ArrayCalibration.from_files with ``data`` as array.json and the readout tests' calibration for each taxel."""
    files = {"array.json": data, **{t["calibration"]: json.dumps(make_calibration()).encode() for t in array["taxels"]}}

    def read(name: str) -> bytes:
        if name not in files:
            raise readout.device.DeviceError(f"{name}: no such file in the package")
        return files[name]

    return outcome(lambda _: readout.taxels.ArrayCalibration.from_files(read), None, readout.errors)


@pytest.mark.parametrize("kind", ["random", "mutated", "structured"])
@pytest.mark.parametrize("what", ["calibration.json", "array.json"])
@DEFAULT
@given(data=st.data())
def test_the_readouts_json(readout, array_doc, what, kind, data):
    doc = calibration_doc() if what == "calibration.json" else array_doc
    drawn = {"random": st.binary(max_size=4096), "mutated": mutated(json.dumps(doc).encode()),
             "structured": json_variants(doc)}[kind]
    if what == "calibration.json":
        readout_calibration(readout, data.draw(drawn))
    else:
        readout_array(readout, array_doc, data.draw(drawn))


def test_the_readouts_valid_json_is_read(readout, array_doc):
    assert readout_calibration(readout, json.dumps(calibration_doc()).encode()) is not None
    assert readout_array(readout, array_doc, json.dumps(array_doc).encode()) is not None


@pytest.mark.slow
@pytest.mark.parametrize("what", ["calibration.json", "array.json"])
@SLOW
@given(data=st.data())
def test_the_readouts_json_exhaustively(readout, array_doc, what, data):
    doc = calibration_doc() if what == "calibration.json" else array_doc
    drawn = data.draw(st.one_of(st.binary(max_size=65536), mutated(json.dumps(doc).encode()), json_variants(doc)))
    if what == "calibration.json":
        readout_calibration(readout, drawn)
    else:
        readout_array(readout, array_doc, drawn)


# --- what the fuzzers found, kept as explicit cases ------------------------------------------------------------------

BIG = 10**400  # an integer JSON holds and no float does: math.isfinite and float() raise OverflowError on it


@pytest.mark.parametrize("path", ["coefficients.Fz_N.2", "valid_region.Bz_uT.0", "valid_region.hull.1.0",
                                  "scaling.Bz_uT.center", "tare_N.Fz_N", "thermal.coefficient_per_C.Bx_uT"])
def test_an_integer_too_large_for_a_float_is_refused_by_calibration_json(readout, path):
    from magfab.formats import calibration_json

    doc = calibration_doc()
    node = doc
    *parents, last = path.split(".")
    for part in parents:
        node = node[int(part)] if isinstance(node, list) else node[part]
    node[int(last) if isinstance(node, list) else last] = BIG
    text = json.dumps(doc)
    with pytest.raises(calibration_json.CalibrationError, match=re.escape(path.split(".")[0])):
        calibration_json.loads(text)
    with pytest.raises(readout.calibration.CalibrationError):
        readout.calibration.Calibration.from_json(text)


def test_an_integer_too_large_for_a_float_is_refused_by_acceptance_and_array_json(array_doc):
    from magfab.formats import acceptance_json, array_json

    doc = acceptance_doc()
    doc["weight"]["table"]["force_N"][2] = BIG
    with pytest.raises(acceptance_json.AcceptanceError, match=re.escape("weight.table.force_N")):
        acceptance_json.loads(json.dumps(doc).encode())
    for key in ("chips_mm", "travel_mm", "own_lateral_uT"):
        doc = copy.deepcopy(array_doc)
        doc[key][1] = [BIG, 0.0, 0.0] if key == "chips_mm" else BIG
        with pytest.raises(array_json.ArrayError, match=re.escape(key)):
            array_json.validate(doc)


@pytest.mark.parametrize("change, key", [
    ({"files": [0.0, 0.0]}, "files"), ({"files": {"calibration.json": ["ab" * 32]}}, "files"),
    ({"taxel": [None]}, "taxel"), ({"rest_field_uT": [2.0, 20100.0]}, "rest_field_uT"),
    ({"rest_field_uT": [1.0, 2.0, "NaN"]}, "rest_field_uT"), ({"rest_field_uT": 5.0}, "rest_field_uT"),
    ({"sensitivity_normal_uT_per_N": [101.0]}, "sensitivity_normal_uT_per_N"),
    ({"range_normal_N": BIG}, "range_normal_N"), ({"date": None}, "date"), ({"date": "yesterday"}, "date"),
    ({"figures": [[{}], 0.0]}, "figures"), ({"figures": {"weight_g": BIG}}, "figures")])
def test_an_event_edited_by_hand_is_refused_naming_its_file_and_key(record, change, key):
    from magfab.formats import sensor_records as rec

    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder) / "sensors"
        shutil.copytree(record, root)
        path = root / "finger-01" / "events" / "000002-calibration.json"
        path.write_text(json.dumps({**json.loads(path.read_text()), **change}))
        with pytest.raises(rec.RecordError) as info:
            rec.open_sensor(root, "finger-01").events()
        assert str(info.value).startswith(f"events/000002-calibration.json: {key} = ")
        one_line(info.value)


def test_a_calibration_event_without_its_file_and_a_kept_file_that_is_not_json(record):
    from magfab.formats import sensor_records as rec

    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder) / "sensors"
        shutil.copytree(record, root)
        path = root / "finger-01" / "events" / "000006-calibration.json"
        path.write_text(json.dumps({**json.loads(path.read_text()), "files": {}}))
        with pytest.raises(rec.RecordError, match=r"000006-calibration\.json: files .*must keep the calibration\.json"):
            rec.open_sensor(root, "finger-01").current_calibration()
        sensor = rec.open_sensor(root, "finger-01")
        sha = sensor._keep(b"{not json", "json")
        with pytest.raises(rec.RecordError, match="is kept in the record but is not valid JSON"):
            sensor.json_file(sha, "calibration.json")


def test_the_thermal_objects_informative_keys_are_checked_by_magfabs_model():
    from magfab.formats.calibration_json import CalibrationError
    from magfab.models.calibration import Calibration

    for key, value in (("span_C", [1]), ("recipe_per_C", BIG), ("uncertainty_per_C", {}), ("uncertainty_per_C", 3),
                       ("note", 5)):
        doc = calibration_doc()
        doc["thermal"][key] = value
        with pytest.raises(CalibrationError, match=re.escape(f"thermal.{key}")):
            Calibration.from_json(doc)


def test_a_builds_array_json_gone_bad(tmp_path, array_doc):
    from magfab.array_bench import _offsets
    from magfab.formats.array_json import ArrayError

    path = tmp_path / "array.json"
    for data in (b"{not json", b"\xff\xfe", json.dumps(dict(array_doc, offset_uT=[[1.0]])).encode(),
                 json.dumps([array_doc]).encode()):
        path.write_bytes(data)
        with pytest.raises(ArrayError):
            _offsets(path)


def test_the_readouts_array_json_gone_bad(readout, array_doc):
    """Not JSON, not UTF-8, a rest field that is not N triples, a taxel file that is not UTF-8: the format's error
    (exit 2), and a neighbour table's error names its place in the table."""
    bad = [b"{not json", b"\xb5", json.dumps(dict(array_doc, rest_uT=[[[1.0]], 2.0])).encode()]
    for data in bad:
        with pytest.raises(readout.json_checks.FormatError):
            readout.taxels.ArrayCalibration.from_files(lambda name, data=data: data if name == "array.json" else b"")
    with pytest.raises(readout.calibration.CalibrationError, match=re.escape("taxel_00.json")):
        readout.taxels.ArrayCalibration.from_files(
            lambda name: json.dumps(array_doc).encode() if name == "array.json" else b"\xff")
    doc = copy.deepcopy(array_doc)
    doc["neighbour_uT"][0][1] = [[1.0, 2.0]]
    with pytest.raises(readout.json_checks.FormatError, match=r"neighbour_uT\[0\]\[1\]"):
        readout.taxels.ArrayCalibration.from_files(lambda name: json.dumps(doc).encode() if name == "array.json"
                                                   else json.dumps(make_calibration()).encode())


def test_a_deeply_nested_present_calibration_is_skipped_by_guard_b(tmp_path):
    from magfab.formats.scan_csv import read_scan_csv
    from magfab.models.scan_guards import reject_self_calibrated_file

    path = tmp_path / "calibration.json"
    path.write_text("[" * 100_000 + "]" * 100_000)  # past json's recursion limit: a RecursionError before
    assert reject_self_calibrated_file(read_scan_csv(scan_bytes()), path, 5.0) is None


def test_a_long_unknown_name_in_the_targets_is_shown_cut():
    from magfab.errors import SpecError
    from magfab.inverse.targets import parse_targets

    text = (EXAMPLES / "targets.toml").read_text()
    for old, new in (('"N42"', '"N4' + "9" * 5000 + '"'), ('"diameter_mm"', '"' + "d" * 5000 + '"')):
        assert old in text
        with pytest.raises(SpecError) as info:
            parse_targets(text.replace(old, new, 1))
        assert len(one_line(info.value)) < 400, str(info.value)[:200]


def test_an_integer_too_large_for_a_float_in_the_targets_is_out_of_bounds():
    from magfab.errors import SpecError
    from magfab.inverse.targets import parse_targets

    text = (EXAMPLES / "targets.toml").read_text()
    assert "elastomer_diameter_mm = [8.0, 14.0]" in text
    with pytest.raises(SpecError, match=r"variables\.elastomer_diameter_mm .*must lie within"):
        parse_targets(text.replace("elastomer_diameter_mm = [8.0, 14.0]", f"elastomer_diameter_mm = [8.0, {BIG}]"))


@pytest.mark.parametrize("key", ["index", "polarity", "i2c_address"])
@pytest.mark.parametrize("value", [True, False])
def test_a_taxels_bool_is_not_an_integer(array_doc, key, value):
    """JSON's true equals 1 and false 0 in Python, and both are ints there: array.json's taxel index, polarity and
    address refuse them as what they are, a bool."""
    from magfab.formats.array_json import ArrayError, validate

    doc = json.loads(json.dumps(array_doc))
    doc["taxels"][int(value)][key] = value
    with pytest.raises(ArrayError, match=r"taxels\[[01]\]"):
        validate(doc)
