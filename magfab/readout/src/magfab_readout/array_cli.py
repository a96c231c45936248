"""``magfab-readout stream``, ``record`` and ``info`` for an array build's package (:mod:`.taxels`): the same
options as a single taxel's, every taxel of every cycle.

``stream`` prints one line per taxel per cycle (its index in the third column), forces in N, the field as its chip
read it, and five flag letters (o outside the calibrated region, E chip error, S full scale, R recovered, M the
frame is missing); ``--count`` counts cycles, ``--zero N`` zeroes each taxel on N of its readings. When this
computer cannot evaluate every cycle as fast as the board sends them, ``stream`` leaves cycles out to stay live and
says how many. ``record`` writes one row per taxel reading with a ``taxel`` column (docs/bundle.md section 1) and
every cycle, however long it takes. ``info`` lists the array: each taxel's position, address, order code, straps,
magnet and calibration.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import List

from . import _build, array_check, array_sensor, board_sensor, eeprom, identity, record_formats
from .array_sim import SimulatedArray
from .cli_shared import (
    CSV_COLUMNS,
    Interrupt,
    Span,
    UsageError,
    at_fallback_baud,
    check_link,
    format_csv,
    format_number,
    record_header,
)
from .device import Device, DeviceError, UploadFailed
from .taxels import ArrayCalibration, ArrayReader, Cycle

__all__ = ["run", "RECORD_COLUMNS"]

#: ``record``'s columns for an array: a single taxel's, with the taxel after the two clocks.
RECORD_COLUMNS = (*CSV_COLUMNS[:2], "taxel", *CSV_COLUMNS[2:])
#: Lag behind the board after which ``record`` warns (it keeps every cycle), s.
RECORD_LAG_WARNING_S = 2.0


def open_device(args: argparse.Namespace, array: ArrayCalibration, text, pattern=None) -> Device:
    check_link(args)
    transport = None
    if args.simulate:
        transport = SimulatedArray(array, seed=args.simulate_seed, corrupt_fraction=args.simulate_corrupt,
                                   eeprom_file=args.simulate_eeprom, pattern=pattern)
    elif args.simulate_corrupt or args.simulate_seed or args.simulate_eeprom:
        raise DeviceError("--simulate-corrupt, --simulate-seed and --simulate-eeprom need --simulate")
    return Device(args.port, args.baud, text=text, timeout_s=args.timeout, calibration=array.calibrations[0],
                  transport=transport)


def _title(array: ArrayCalibration) -> str:
    return "array of {} taxels ({}), compensation {} (array.json {})".format(
        array.taxels, " ".join(f"0x{a:02X}" for a in array.addresses),
        "of the neighbours' motion" if array.dynamic else "of the neighbours at rest", array.short_hash)


def _row(cycle: Cycle, t, raw: bool) -> str:
    time_s = t.time_s if t.time_s is not None else cycle.time_s
    row = [format_number(time_s, 10, 4, False), f"{cycle.seq:3d}", f"{t.taxel:2d}"]
    row += [format_number(f, 8, 4) for f in t.force_N] + [format_number(b, 9, 2) for b in t.B_uT]
    row += [format_number(t.temperature_C, 6, 2, False), t.flags, (t.fault_name or "-").replace(" ", "_")]
    if raw:
        counts = t.counts or (0, 0, 0)
        row += [f"{c:6d}" for c in counts] + [f"{t.temperature_raw or 0:5d}"]
    return "  ".join(row)


def stream(args: argparse.Namespace, array: ArrayCalibration, out) -> int:
    if args.zero < 0:
        raise DeviceError("--zero needs a positive number of samples")
    if args.raw and args.text:
        raise DeviceError("--raw needs binary frames: text lines carry microtesla, not raw counts")
    if args.check:
        raise DeviceError("--check compares the firmware's forces with the host's: an array's firmware sends only "
                          "fields, and every force is the host's")
    with open_device(args, array, bool(args.text)) as device:
        linked = array_sensor.link(device, device.info(), args, array)
        array = linked.array
        reader = ArrayReader(device, array)
        out.write(f"# magfab-readout {_build.VERSION}: spec {json.dumps(_build.SPEC_NAME)}, {_title(array)}, "
                  f"{device.port}{_sensor_note(linked)}\n")
        if args.zero:
            for k, offset in enumerate(reader.zero(args.zero)):
                out.write("# zero: taxel {} offset Fx {:+.4f} N, Fy {:+.4f} N, Fz {:+.4f} N from {} samples\n".format(
                    k, *offset, args.zero))
        columns = ["t_s", "seq", "taxel", "Fx_N", "Fy_N", "Fz_N", "Bx_uT", "By_uT", "Bz_uT", "T_C", "flags", "fault"]
        if args.raw:
            columns += ["Bx_lsb", "By_lsb", "Bz_lsb", "T_raw"]
        out.write("# " + " ".join(columns) + "\n")
        span = Span()
        stop = Interrupt()  # Ctrl-C ends the stream on a whole cycle, and the summary follows it
        with stop:
            for cycle in reader.cycles(count=args.count, seconds=args.seconds, keep_up=True):
                stop.writing = True
                out.write("".join(_row(cycle, t, args.raw) + "\n" for t in cycle))
                span.add(cycle.time_s)
                stop.writing = False
                if stop.requested:
                    break
        _summary(reader, span)
    return 0


def _summary(reader: ArrayReader, span: Span) -> None:
    """The stream's or recording's end: its cycles, the rate they came at (each taxel's: a frame a cycle) against
    the chips' conversions, what was missing or lost."""
    s = reader.device.stats
    text = (f"{span.n} cycles of {reader.calibration.taxels} taxels{span.rate('cycles')}; {reader.incomplete} "
            f"incomplete ({reader.missing} frames missing)")
    if reader.skipped:
        text += f", {reader.skipped} left out to keep up"
    if reader.cost is not None:
        text += f"; this computer takes {1e3 * reader.cost:.2g} ms a cycle"
    text += (f"; {s.lost} lost (sequence gaps), {s.crc_errors} CRC errors, {s.bad_lines} bad lines, "
             f"{s.skipped_bytes} bytes skipped")
    print("magfab-readout: " + text, file=sys.stderr)


def record(args: argparse.Namespace, array: ArrayCalibration) -> int:
    if args.seconds is not None and not args.seconds > 0:
        raise DeviceError("--seconds must be positive")
    fmt, path = record_formats.prepare(args.format, args.out)
    with open_device(args, array, bool(args.text)) as device:
        info = device.info()
        linked = array_sensor.link(device, info, args, array)
        array = linked.array
        array_sensor.checked_info(device, array, info)
        temperature = _build.TEMPERATURE_ENABLED
        columns = [c for c in RECORD_COLUMNS if temperature or c != "temperature_C"]
        reader = ArrayReader(device, array)
        written = skipped = 0
        stop = Interrupt()
        span = Span()
        warned = False
        extra = [f"# array: {_title(array)}",
                 "# taxel: the chip each row was read from; Bx_uT, By_uT, Bz_uT as that chip read it (the other "
                 "magnets' field included); F*_sensor_N that taxel's force after the compensation of array.json"]
        extra += [f"# taxel {k} calibration_sha256: {c.sha256}" for k, c in enumerate(array.calibrations)]
        extra += [] if linked.sensor is None else [f"# sensor: {linked.sensor.id}"]
        with open(path, "w", encoding="utf-8", newline="") as f:
            record_header(f, device, info, columns, extra)
            with stop:
                for cycle in reader.cycles(seconds=args.seconds):
                    stop.writing = True
                    span.add(cycle.time_s)
                    rows = _record_rows(cycle, time.time(), temperature)
                    f.write("".join(r + "\n" for r in rows))
                    written += len(rows)
                    skipped += len(cycle) - len(rows)
                    stop.writing = False
                    if reader.lag_s > RECORD_LAG_WARNING_S and not warned:
                        warned = True
                        print("magfab-readout: warning: this computer falls behind the board "
                              f"({1e3 * (reader.cost or 0.0):.2g} ms a cycle): the recording keeps every cycle, late",
                              file=sys.stderr)
                    if stop.requested:
                        break
        print("magfab-readout: wrote {} rows to {}{} ({} chip-error, missing or full-scale readings left out)".format(
            written, path, " (Ctrl-C)" if stop.requested else "", skipped), file=sys.stderr)
        _summary(reader, span)
    record_formats.finish(path, args.out, fmt, lambda: {str(k): c.to_dict() for k, c in enumerate(array.calibrations)},
                          written)
    return 0


def _record_rows(cycle: Cycle, host: float, temperature: bool) -> List[str]:
    rows = []
    for t in cycle:
        values = list(t.B_uT) + list(t.force_N)
        if not t.ok or not all(math.isfinite(v) for v in values) or (temperature and t.temperature_C is None):
            continue
        row = [format_csv(t.time_s, 6), format_csv(host, 6), str(t.taxel)] + [format_csv(b, 4) for b in t.B_uT]
        if temperature:
            row.append(format_csv(t.temperature_C, 3))
        row += [format_csv(x, 6) for x in t.force_N] + [str(t.status), str(t.seq)]
        rows.append(",".join(row))
    return rows


def _sensor_note(linked: array_sensor.ArrayLink) -> str:
    if linked.sensor is None or linked.calibrations is None:
        return ""
    return f", sensor {linked.sensor.id}'s taxel calibrations {linked.calibrations.sha256[:16]}"


def info(args: argparse.Namespace, array: ArrayCalibration, out) -> int:
    with open_device(args, array, None) as device:
        line = device.info()
        linked = array_sensor.link(device, line, args, array)
        out.write(f"device:  {line.line}\n")
        out.write("  spec {}, calibration {}, gain_sel {}, resolution {}, osr {}, dig_filt {}, {} taxel(s)\n".format(
            json.dumps(line.spec_name), line.calibration_hash, *line.settings, line.taxels))
        out.write(f"package: magfab-readout {_build.VERSION}, spec {json.dumps(_build.SPEC_NAME)}, "
                  f"calibration {device.calibration.short_hash}\n")
        out.write(board_sensor.sensor_line(linked.identity, line.calibration_hash))
        array = linked.array
        out.write(f"array:   {_title(array)}\n")
        events = linked.calibrations.events if linked.calibrations is not None else (None,) * array.taxels
        for t, cal, event in zip(array.layout, array.calibrations, events):
            straps = t.get("address_straps") or ["?", "?"]
            source = t["calibration"] if event is None else f"calibration of {event.get('date', '?')}"
            out.write("  taxel {:2d}  at x {:+6.1f} y {:+6.1f} mm  address 0x{:02X}  option code {}  A1 {} A0 {}  "
                      "magnet north {}  {} {}\n".format(
                          t["index"], t.get("x_mm", math.nan), t.get("y_mm", math.nan), t["i2c_address"],
                          t.get("option_code", "?"), straps[0], straps[1], "up" if t["polarity"] == 1 else "down",
                          source, cal.short_hash))
        array_sensor.checked_info(device, array, line)
        if linked.sensor is not None and linked.calibrations is not None:
            out.write(f"calibration: match (sensor {linked.sensor.id}'s current taxel calibrations, the newest of "
                      f"{linked.calibrations.date}, from its record in {linked.sensor.root})\n")
        else:
            out.write("calibration: match\n")
    return 0


def upload(args: argparse.Namespace, array: ArrayCalibration, out) -> int:
    """Write the array's record (docs/bundle.md section 4, version 3: the settings and every chip's address, no
    calibration) into the board's EEPROM, read it back, and check the board's info line. With ``--sensor ID`` the
    record carries the set hash of the sensor's current taxel calibrations, the identity block names the sensor,
    and the record gets an ``upload`` event (:mod:`.array_sensor`); without it a board that names a sensor is
    refused unless ``--force``."""
    if args.calibration:
        raise UsageError("an array's board holds no calibration (the host computes every force): a new taxel "
                         "calibration reaches the readout by reinstalling this build's readout package, or by "
                         "magfab calibrate --sensor ID --taxel K and upload --sensor ID")
    sensor, current, ident = None, None, None
    if args.sensor:
        sensor = board_sensor.open_record(args, args.sensor)
        current = array_sensor.sensor_set(sensor, array.taxels)
        ident = current.identity(sensor.id)
        try:
            identity.pack(ident)  # checks the block's fields before anything is written
        except identity.IdentityError as exc:
            raise UsageError(f"sensor {sensor.id}: {exc}") from None
        array = array.with_calibrations(current.data, current.sha256[:16])  # each one checked before the board
    settings = _build.IMAGE_SETTINGS
    record = eeprom.pack_array(settings["taxel_addresses"], array.board_hash, settings)

    def write(device: Device):
        if sensor is None:
            found = board_sensor.refuse_named_board(device, args.force)
        else:
            found = device.read_identity()
            if not args.force:
                board_sensor.refuse_other_sensor(device, found, sensor.id, f"connect sensor {sensor.id}'s board, or "
                                                 "pass --force to make this board carry it")
        last = device.eeprom_write(0, record)
        if device.eeprom_read(0, len(record)) != record:
            raise UploadFailed("the EEPROM read back differs from the array record written")
        if last.record != 0:
            raise UploadFailed("the board does not accept the array record (a firmware older than record version "
                               f"{eeprom.VERSION_ARRAY}?)")
        if ident is not None:
            device.write_identity(ident)
        return array_sensor.checked_info(device, array), found
    info, found = at_fallback_baud(args, out, lambda a: open_device(a, array, None), write)
    out.write(f"uploaded {len(record)} bytes, read back equal; the board reads {info.taxels} chips "
              f"(spec {json.dumps(info.spec_name)}, calibration {info.calibration_hash})")
    if sensor is None or current is None:
        out.write("\n")
        return 0
    note: dict = {"calibration_sha256": current.sha256, "taxel": None, "taxel_calibrations": list(current.shas)}
    if found is not None and found.sensor_id != sensor.id:
        note["replaced_sensor"] = found.sensor_id
    sensor.append("upload", note)
    out.write(f" and carries sensor {sensor.id}'s ID, taxel calibrations {current.sha256[:16]} (the newest of "
              f"{current.date}); noted in {sensor.path}\n")
    return 0


def run(args: argparse.Namespace, array: ArrayCalibration, out) -> int:
    """``stream``, ``record``, ``info``, ``upload`` or ``check`` of an array build (``args`` as the command
    line parsed them)."""
    if args.command == "stream":
        return stream(args, array, out)
    if args.command == "record":
        return record(args, array)
    if args.command == "upload":
        return upload(args, array, out)
    if args.command == "check":
        return array_check.run(args, array, out, lambda a, text, pattern: open_device(a, array, text, pattern))
    return info(args, array, out)
