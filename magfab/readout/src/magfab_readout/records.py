"""Sensor records (format ``magfab-sensors/1``, docs/sensors.md): one folder per physical sensor that no build
ever writes, holding what it was made from and every measurement made on it, append-only.

One implementation for both ends: ``magfab calibrate --sensor ID`` and ``magfab sensor ...`` write and read records
with it, and so does ``magfab-readout`` (``upload --sensor ID`` reads the current calibration, ``check --sensor ID``
appends its verdict). It uses the standard library only (the readout package runs on Python 3.8 without magfab).

A root folder (``sensors/`` beside the spec, or one the user names) holds ``sensors.json`` (the format's name) and
one folder per sensor ID::

    sensors/
      sensors.json                       {"format": "magfab-sensors/1"}
      finger-01/
        sensor.json                      the ID, when it was added, the design (names and hashes); written once
        files/<sha256>.<ext>             every file an event keeps (spec, design, scans, reference logs,
                                         calibrations), named by the SHA-256 of its bytes
        events/000001-added.json         the history: one JSON file per event, numbered in order
        events/000002-calibration.json
        ...

Nothing in a record is ever replaced or deleted. Every file is written whole under a temporary name, flushed to
disk, then linked to its final name, which fails rather than replace anything already there; a kill at any point
leaves either the old record or the old record plus the new event, never half an event (a leftover temporary
``.tmp-*`` file is ignored by readers). Files are content-addressed, so keeping the same file twice stores it once.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import math
import os
import re
import secrets
from pathlib import Path
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence, Tuple

from . import bounded

__all__ = ["EVENT_KINDS", "FORMAT", "ID_PATTERN", "MARKER", "ROOT_ENV", "RecordError", "Sensor", "check_id", "create",
           "find_root", "init_root", "list_sensors", "now_utc", "open_sensor", "owner_of", "parse_date",
           "sha256_hex"]

FORMAT = "magfab-sensors/1"
#: The root's marker file: a folder is a sensor root when it holds it.
MARKER = "sensors.json"
#: The environment variable naming the root (after ``--sensors``, before the search from the working folder).
ROOT_ENV = "MAGFAB_SENSORS"
#: A sensor ID: what a lab writes on a label; it names a folder and goes into the board's EEPROM (32 bytes there).
ID_PATTERN = r"[A-Za-z0-9][A-Za-z0-9._-]{0,31}"
#: What an event may be (docs/sensors.md section 3).
EVENT_KINDS = ("added", "calibration", "check", "drift", "reskin", "upload", "note")
#: Largest file an event may keep (a scan of several hours at the chip's fastest rate fits well within it).
FILE_MAX_BYTES = 256 * 1024 * 1024
_EVENT_NAME = re.compile(r"^(\d{6})-([a-z]+)\.json$")
_SHA = re.compile(r"^[0-9a-f]{64}$")
_EXT = re.compile(r"^[a-z0-9]{1,8}$")


class RecordError(ValueError):
    """A sensor record cannot be read or written as asked: what, its value, and what is allowed (one line)."""

    def __init__(self, what: str, value: object, allowed: str) -> None:
        super().__init__(f"{what} = {value}: {allowed}")
        self.what, self.value, self.allowed = what, value, allowed


def _shown(value: object) -> str:
    """``value`` for a :class:`RecordError` line: JSON, at most 60 characters (a hand-edited record may hold
    anything, of any length)."""
    try:
        text = json.dumps(value, sort_keys=True)
    except (TypeError, ValueError):  # not JSON, or an integer past Python's digit limit
        text = type(value).__name__
    return text if len(text) <= 60 else text[:57] + "..."


#: The numbers a calibration event carries (docs/sensors.md section 3), each a finite number or null.
_EVENT_NUMBERS = ("rms_holdout_Fz_mN", "rms_holdout_Fr_mN", "sensitivity_normal_uT_per_N",
                  "sensitivity_shear_uT_per_N", "range_normal_N", "range_shear_N", "predicted_error_Fz_mN",
                  "predicted_error_shear_mN")


def _finite(x: object) -> bool:
    """A JSON number a float holds finitely (bool is not one; nor is an integer too large for a float)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def _is_date(x: object) -> bool:
    """A date as the records write it (ISO 8601, a trailing Z for UTC), which every reader of a history parses."""
    if not isinstance(x, str):
        return False
    try:
        _dt.datetime.fromisoformat(x[:-1] + "+00:00" if x.endswith("Z") else x)
    except ValueError:
        return False
    return True


def _check_event(event: Dict[str, Any], what: str) -> None:
    """:class:`RecordError` naming the event file ``what`` and the key unless ``event`` holds what every event
    must (``date``, ``sensor``, ``files`` as docs/sensors.md section 3 has them) and each documented field present
    has its documented type. The readers of a history compute with these fields (a date parsed, a figure
    formatted, a file looked up by its hash), so a record edited by hand is refused here in one line, not deep
    inside one of them."""
    def refuse(key: str, allowed: str) -> RecordError:
        return RecordError(f"{what}: {key}", _shown(event.get(key)), allowed)

    if not _is_date(event.get("date")):
        raise refuse("date", "must be an ISO 8601 date and time, e.g. 2026-11-28T14:05:00Z")
    if not isinstance(event.get("sensor"), str):
        raise refuse("sensor", "must be the sensor's ID (a string)")
    files = event.get("files")
    if not isinstance(files, dict) or not all(isinstance(v, str) and _SHA.fullmatch(v) for v in files.values()):
        raise refuse("files", "must map each kept file's role to its SHA-256 in hex")
    taxel = event.get("taxel")
    if taxel is not None and (isinstance(taxel, bool) or not isinstance(taxel, int) or taxel < 0):
        raise refuse("taxel", "must be null (a single taxel) or an array's taxel index, an integer from 0")
    for key in _EVENT_NUMBERS:
        if event.get(key) is not None and not _finite(event[key]):
            raise refuse(key, "must be a finite number or null")
    rest = event.get("rest_field_uT")
    if rest is not None and not (isinstance(rest, list) and len(rest) == 3 and all(_finite(x) for x in rest)):
        raise refuse("rest_field_uT", "must be [Bx, By, Bz], three finite numbers, or null")
    figures = event.get("figures")
    if figures is not None and not (isinstance(figures, dict)
                                    and all(v is None or _finite(v) for v in figures.values())):
        raise refuse("figures", "must map each figure's name to a finite number or null")
    for key in ("calibration_sha256", "verdict"):
        if event.get(key) is not None and not isinstance(event[key], str):
            raise refuse(key, "must be a string")


def _iso(when: _dt.datetime) -> str:
    return when.astimezone(_dt.timezone.utc).replace(microsecond=0, tzinfo=None).isoformat() + "Z"


def now_utc() -> str:
    """The current time, UTC, to the second, as ISO 8601 (``2026-11-28T20:15:00Z``)."""
    return _iso(_dt.datetime.now(_dt.timezone.utc))


def parse_date(text: str) -> str:
    """A date as a lab writes it (``2026-11-28``, ``2026-11-28T14:05``, with seconds or a ``Z``/offset) as the
    records' UTC ISO 8601 form; a date without a zone is UTC. :class:`RecordError` for anything else."""
    raw = text.strip()
    try:
        when = _dt.datetime.fromisoformat(raw[:-1] + "+00:00" if raw.endswith("Z") else raw)
    except ValueError:
        raise RecordError("date", json.dumps(text), "must be an ISO 8601 date such as 2026-11-28 or "
                          "2026-11-28T14:05 (UTC unless it names a zone)") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=_dt.timezone.utc)
    return _iso(when)


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def check_id(sensor_id: str) -> str:
    if not isinstance(sensor_id, str) or not re.fullmatch(ID_PATTERN, sensor_id):
        raise RecordError("sensor", json.dumps(sensor_id), "must be 1 to 32 of A-Z a-z 0-9 . _ - starting with a "
                          "letter or digit")
    return sensor_id


# ---- writing without replacing ------------------------------------------------------------------------------------


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(str(folder), os.O_RDONLY)
    except OSError:  # a platform without directory handles (Windows): the link is as durable as it gets
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _temporary(folder: Path, data: bytes) -> Path:
    """``data`` written whole and flushed under a fresh temporary name in ``folder``."""
    tmp = folder / f".tmp-{os.getpid()}-{secrets.token_hex(6)}"
    fd = os.open(str(tmp), os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    finally:
        os.close(fd)
    return tmp


def _publish(tmp: Path, final: Path) -> bool:
    """Give the whole file ``tmp`` the name ``final`` unless that name exists (then False); ``tmp`` is removed."""
    try:
        os.link(str(tmp), str(final))
    except FileExistsError:
        return False
    finally:
        tmp.unlink()
    _fsync_dir(final.parent)
    return True


def _write_new(final: Path, data: bytes) -> bool:
    """Write ``final`` whole, never replacing it: False (and nothing written) when it already exists."""
    if final.exists():
        return False
    return _publish(_temporary(final.parent, data), final)


def _json_bytes(data: Mapping[str, Any]) -> bytes:
    return (json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n").encode("utf-8")


def _read_json(path: Path, what: str) -> Dict[str, Any]:
    try:
        data = bounded.loads_json(bounded.read_bytes(path, "JSON"), what, path)
    except bounded.InputFileError:
        raise
    except FileNotFoundError:
        raise RecordError(what, str(path), "is missing: the sensor record is incomplete") from None
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise RecordError(what, str(path), f"cannot be read as JSON ({exc})") from None
    if not isinstance(data, dict):
        raise RecordError(what, str(path), "must hold a JSON object")
    return data


# ---- the root -----------------------------------------------------------------------------------------------------


def _is_root(folder: Path) -> bool:
    return (folder / MARKER).is_file()


def find_root(explicit: Optional[Path] = None, start: Optional[Path] = None, *, must_exist: bool = True) -> Path:
    """The sensor root: ``explicit`` (``--sensors``), else ``$MAGFAB_SENSORS``, else the nearest ``sensors/``
    folder holding :data:`MARKER` in ``start`` (the working folder) or a folder above it, else ``start/sensors``.
    With ``must_exist`` a root that has no marker yet is :class:`RecordError` naming ``magfab sensor add``."""
    chosen = explicit if explicit is not None else (Path(os.environ[ROOT_ENV]) if os.environ.get(ROOT_ENV) else None)
    if chosen is None:
        here = (start or Path.cwd()).resolve()
        found = next((d / "sensors" for d in (here, *here.parents) if _is_root(d / "sensors")), None)
        chosen = found if found is not None else here / "sensors"
    if must_exist and not _is_root(chosen):
        raise RecordError("sensors", str(chosen), f"holds no sensor records ({MARKER} missing): add a sensor first "
                          f"with `magfab sensor add ID --build DIR`, or name the root with --sensors DIR or ${ROOT_ENV}"
                          )
    return chosen


def init_root(root: Path) -> Path:
    """Make ``root`` a sensor root (its marker file) if it is not one; refuses a folder that is a build's."""
    root = Path(root)
    if _is_root(root):
        return root
    for folder in (root.resolve(), *root.resolve().parents):
        if (folder / "manifest.json").is_file() and (folder / "design.json").is_file():
            raise RecordError("sensors", str(root), f"is inside the build folder {folder}, which a rebuild "
                              "replaces: keep sensor records outside every build (e.g. sensors/ beside the spec)")
    root.mkdir(parents=True, exist_ok=True)
    _write_new(root / MARKER, _json_bytes({"format": FORMAT}))
    return root


def list_sensors(root: Path) -> List[Sensor]:
    """Every sensor of ``root``, by ID."""
    root = Path(root)
    return [Sensor(root, d.name) for d in sorted(root.iterdir(), key=lambda p: p.name)
            if d.is_dir() and re.fullmatch(ID_PATTERN, d.name) and (d / "sensor.json").is_file()]


def open_sensor(root: Path, sensor_id: str) -> Sensor:
    """The record of ``sensor_id`` in ``root``; :class:`RecordError` naming the IDs there when it has none."""
    check_id(sensor_id)
    sensor = Sensor(Path(root), sensor_id)
    if not (sensor.path / "sensor.json").is_file():
        known = [s.id for s in list_sensors(root)]
        raise RecordError("sensor", sensor_id, "has no record in {} ({}): add it with `magfab sensor add {} --build "
                          "DIR`".format(root, "sensors there: " + ", ".join(known) if known else "none yet",
                                        sensor_id))
    return sensor


def create(root: Path, sensor_id: str, info: Mapping[str, Any], files: Mapping[str, bytes], *,
           date: Optional[str] = None, then: Sequence[Tuple[str, Mapping[str, Any], Mapping[str, bytes]]] = ()
           ) -> Sensor:
    """A new record: ``sensor.json`` (``info`` with the ID and the date) and its first event, ``added``, keeping
    ``files`` (role -> bytes, e.g. ``{"spec.json": ...}``), then the events ``then`` ((kind, data, files) each: what
    the record starts with, such as a calibration measured before it existed). ``sensor.json`` is written last, so
    the ID has a record only once every one of them is there. :class:`RecordError` when the ID has a record."""
    check_id(sensor_id)
    root = init_root(root)
    sensor = Sensor(root, sensor_id)
    if (sensor.path / "sensor.json").exists():
        raise RecordError("sensor", sensor_id, f"already has a record in {root}: pick another ID, or use that one"
                          )
    (sensor.path / "events").mkdir(parents=True, exist_ok=True)
    (sensor.path / "files").mkdir(exist_ok=True)
    when = date or now_utc()
    # the events first: a kill before sensor.json leaves a folder that is not yet a record, and a retry finds the
    # events already there, in order, and appends the rest
    planned = [("added", dict(info), files), *((kind, dict(data), kept) for kind, data, kept in then)]
    done = sensor.events()
    for k, (kind, data, kept) in enumerate(planned):
        if k < len(done):
            if done[k]["kind"] != kind or any(done[k].get(key) != value for key, value in data.items()):
                raise RecordError("sensor", sensor_id, f"has a folder in {root} left by another command that was "
                                  f"stopped (events/{done[k]['number']:06d}-{done[k]['kind']}.json differs from what "
                                  "this one adds): remove that folder, or pick another ID")
            continue
        sensor.append(kind, data, kept, date=when)
    head = dict(info, format=FORMAT, id=sensor_id, added=when)
    if not _write_new(sensor.path / "sensor.json", _json_bytes(head)):
        raise RecordError("sensor", sensor_id, "was added by another command at the same time: run it again")
    return sensor


def owner_of(root: Path, sha256: str, *, kinds: Tuple[str, ...] = ("calibration",)) -> List[str]:
    """The IDs whose events of ``kinds`` keep a file with this SHA-256 (a scan belongs to the sensor it
    calibrated)."""
    owners = []
    for sensor in list_sensors(root):
        if any(sha256 in ev.get("files", {}).values() for ev in sensor.events() if ev["kind"] in kinds):
            owners.append(sensor.id)
    return owners


# ---- one sensor ---------------------------------------------------------------------------------------------------


class Sensor:
    """One physical sensor's record (``root/ID``)."""

    def __init__(self, root: Path, sensor_id: str) -> None:
        self.root = Path(root)
        self.id = sensor_id
        self.path = self.root / sensor_id

    def __repr__(self) -> str:
        return f"Sensor({str(self.root)!r}, {self.id!r})"

    @property
    def info(self) -> Dict[str, Any]:
        """sensor.json: the ID, when it was added, the design it was made from."""
        return _read_json(self.path / "sensor.json", "sensor.json")

    def events(self) -> List[Dict[str, Any]]:
        """Every event in order, each with its ``number`` and ``kind`` (from its file name)."""
        folder = self.path / "events"
        if not folder.is_dir():
            return []
        out = []
        for path in sorted(folder.iterdir(), key=lambda p: p.name):
            match = _EVENT_NAME.match(path.name)
            if match is None:
                continue  # a temporary file a kill left behind, or a file a person put there
            event = _read_json(path, "events/" + path.name)
            _check_event(event, "events/" + path.name)
            event["number"], event["kind"] = int(match.group(1)), match.group(2)
            out.append(event)
        return out

    def _keep(self, data: bytes, ext: str) -> str:
        if len(data) > FILE_MAX_BYTES:
            raise RecordError("file", f"{len(data)} bytes", f"must be at most {FILE_MAX_BYTES} bytes")
        digest = sha256_hex(data)
        final = self.path / "files" / f"{digest}.{ext}"
        if not _write_new(final, data) and sha256_hex(final.read_bytes()) != digest:
            raise RecordError("file", str(final), "does not hold the bytes its name promises: the record was "
                              "edited by hand; restore it from a backup")
        return digest

    def append(self, kind: str, data: Mapping[str, Any], files: Optional[Mapping[str, bytes]] = None, *,
               date: Optional[str] = None) -> Dict[str, Any]:
        """Append an event of ``kind`` with ``data`` and keep ``files`` (role -> bytes: the role's extension, e.g.
        ``scan.csv``, names the stored file's); returns the event as written. Never replaces anything."""
        if kind not in EVENT_KINDS:
            raise RecordError("event", kind, "must be one of " + ", ".join(EVENT_KINDS))
        kept = {}
        for role, blob in sorted((files or {}).items()):
            ext = role.rsplit(".", 1)[-1].lower() if "." in role else "bin"
            kept[role] = self._keep(bytes(blob), ext if _EXT.match(ext) else "bin")
        event = dict(data, date=date or now_utc(), files=kept, sensor=self.id)
        body = _json_bytes(event)
        folder = self.path / "events"
        folder.mkdir(parents=True, exist_ok=True)
        tmp = _temporary(folder, body)
        try:
            number = 1 + max((e["number"] for e in self.events()), default=0)
            while True:
                final = folder / f"{number:06d}-{kind}.json"
                try:
                    os.link(str(tmp), str(final))
                    break
                except FileExistsError:  # another command appended the same number first
                    number += 1
        finally:
            tmp.unlink()
        _fsync_dir(folder)
        event["number"], event["kind"] = number, kind
        return event

    def file(self, sha256: str) -> bytes:
        """The bytes an event keeps under ``sha256`` (checked against it)."""
        if not isinstance(sha256, str) or not _SHA.fullmatch(sha256):
            raise RecordError("file", _shown(sha256), "must be a SHA-256 in hex")
        matches = sorted((self.path / "files").glob(sha256 + ".*"))
        if not matches:
            raise RecordError("file", sha256, f"is not kept in the record of {self.id}")
        data = bounded.read_bytes(matches[0], "a record's file", FILE_MAX_BYTES)
        if sha256_hex(data) != sha256:
            raise RecordError("file", str(matches[0]), "does not hold the bytes its name promises: the record "
                              "was edited by hand; restore it from a backup")
        return data

    def epoch(self) -> int:
        """The skin in use: 0 for the first, one more after each ``reskin`` event."""
        return sum(1 for e in self.events() if e["kind"] == "reskin")

    def calibrations(self, taxel: Optional[int] = None) -> Iterator[Dict[str, Any]]:
        """The calibration events (of ``taxel`` for an array's), oldest first, each with its ``epoch``."""
        epoch = 0
        for event in self.events():
            if event["kind"] == "reskin":
                epoch += 1
            elif event["kind"] == "calibration" and event.get("taxel") == taxel:
                yield dict(event, epoch=epoch)

    def current_calibration(self, taxel: Optional[int] = None) -> Tuple[Dict[str, Any], Dict[str, Any]]:
        """(event, calibration.json) of the newest calibration of the skin in use; :class:`RecordError` when this
        skin has none yet."""
        epoch = self.epoch()
        found = [e for e in self.calibrations(taxel) if e["epoch"] == epoch]
        if not found:
            what = "" if taxel is None else f" for taxel {taxel}"
            raise RecordError("sensor", self.id, "has no calibration{} {}yet: calibrate it with `magfab calibrate "
                              "SCAN --reference REF --sensor {}`".format(
                                  what, "since its new skin " if epoch else "", self.id))
        event = found[-1]
        sha = event["files"].get("calibration.json")
        if sha is None:
            raise RecordError("events/{:06d}-calibration.json: files".format(event["number"]), _shown(event["files"]),
                              "must keep the calibration.json of the calibration")
        return event, self.json_file(sha, "calibration.json")

    def json_file(self, sha256: str, what: str) -> Any:
        """The JSON file an event keeps under ``sha256`` (``what`` names it), parsed within bounds; :class:`RecordError`
        when it does not parse (a file stored by hand under its hash: magfab keeps only JSON it wrote)."""
        try:
            return bounded.loads_json(self.file(sha256), what, f"the record of {self.id}")
        except bounded.InputFileError:
            raise
        except ValueError as exc:  # json's error, or UnicodeDecodeError
            raise RecordError(f"{what} of {self.id}", sha256, f"is kept in the record but is not valid JSON ({exc})"
                              ) from None
