"""``magfab-readout``: stream calibrated forces, record scans, ask the board what it runs, write a new
calibration into its EEPROM (``upload``), run the acceptance test (``check``) against the bands magfab
predicted for this build (acceptance.json), and walk the weight plan of a calibration without a force sensor
(``weigh``).

Exit status: 0 done (``check``: passed); 2 a problem with what was given or with the bench (a usage error, a file
refused, a calibration the record cannot hold, an unknown sensor, no board or no data on the port: one line on
stderr); 3 ``check`` ran and the sensor failed a step; 1 only for a bug of ours (one line naming it); 130 Ctrl-C.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pkgutil
import sys
import time
from typing import List, NoReturn, Optional

from . import _build, array_cli, board_sensor, bounded, check, identity, record_formats, records, view, weigh
from .calibration import Calibration, CalibrationError, calibration_sha256
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
from .device import Device, DeviceError, calibration_record, cross_check
from .eeprom import EepromError
from .identity import Identity
from .json_checks import FormatError
from .rest import RestTracker
from .simulate import WARM_RATE_C_PER_S, SimulatedDevice, TemperatureRamp
from .taxels import ArrayCalibration, ArrayReader


class _Parser(argparse.ArgumentParser):
    """argparse's own errors (an unknown option, a missing argument: its usage line and the error) as one line, as
    every other refusal; its subcommands' parsers are of this class too."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"magfab-readout: error: {' '.join(message.split())} (`{self.prog} --help` lists what is "
                     "allowed)\n")


def _common() -> _Parser:
    """The options every command that talks to a board takes: the serial link and the simulated board."""
    common = _Parser(add_help=False)
    link = common.add_argument_group("connection")
    link.add_argument("--port", help="serial port (default: $MAGFAB_READOUT_PORT when set, else the one USB serial "
                      "port present)")
    link.add_argument("--baud", type=int, default=_build.BAUD, help="baud rate (default: %(default)s, the firmware's)")
    link.add_argument("--timeout", type=float, default=3.0, metavar="S",
                      help="seconds to wait for data before giving up (default: %(default)s)")
    sim = common.add_argument_group("simulated device")
    sim.add_argument("--simulate", action="store_true",
                     help="no hardware: a simulated board sends the firmware's frames")
    sim.add_argument("--simulate-seed", type=int, default=0, metavar="N", help="noise seed of the simulated board")
    sim.add_argument("--simulate-corrupt", type=float, default=0.0, metavar="FRACTION",
                     help="fraction of simulated frames with a flipped bit (to see the CRC checks at work)")
    sim.add_argument("--simulate-warm", type=float, metavar="C",
                     help="the simulated chip warms by C degrees (stream, record: from the first second on, "
                     f"{WARM_RATE_C_PER_S:g} C/s; check: when the warm-up step asks)")
    sim.add_argument("--simulate-no-thermal", action="store_true",
                     help="the simulated board runs the calibration without its temperature correction (the "
                     "field still follows the temperature: a board with an old calibration record, whose hash "
                     "record refuses)")
    sim.add_argument("--simulate-eeprom", metavar="FILE",
                     help="keep the simulated board's EEPROM in FILE between commands (upload, then info or check, as "
                     "on a board; created when missing)")
    return common


def _parser() -> argparse.ArgumentParser:
    common = _common()
    parser = _Parser(
        prog="magfab-readout",
        description=f"Host readout for the magfab tactile sensor built from spec {json.dumps(_build.SPEC_NAME)}.",
    )
    parser.add_argument("--version", action="version",
                        version=f"magfab-readout {_build.VERSION} (calibration {_build.CALIBRATION_SHA256[:16]})")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    stream = commands.add_parser("stream", parents=[common], help="print calibrated forces as they arrive",
                                 description="Print Fx Fy Fz (N), the field B (uT), the temperature and the status "
                                 "flags (o outside the calibrated region, E chip error, S full scale, R recovered), "
                                 "and on an error row which fault struck where (e.g. nack_at_read). At the end, on "
                                 "stderr, how the rest level moved while nothing touched the tip (mN, and mN per C "
                                 "of the chip's temperature): start with nothing touching the tip.")
    stream.add_argument("--text", action="store_true", help="ask the firmware for text lines instead of binary frames")
    stream.add_argument("--zero", type=int, default=0, metavar="N",
                        help="average N samples at rest first and subtract that force from the rest (tare)")
    stream.add_argument("--raw", action="store_true",
                        help="also print the raw counts and raw temperature (binary only)")
    stream.add_argument("--check", action="store_true",
                        help="also recompute each force from the field on the host and print the difference")
    stream.add_argument("--count", type=int, metavar="N", help="stop after N samples (an array: N cycles)")
    stream.add_argument("--seconds", type=float, metavar="S", help="stop after S seconds of device time")
    board_sensor.add_options(stream, _SENSOR_HELP + " (with --check)")

    record = commands.add_parser("record", parents=[common], help="record the field during a scan, until Ctrl-C",
                                 description="Write the device's and the host's time, the field, the temperature and "
                                 "this sensor's own calibrated force (Fx_sensor_N, Fy_sensor_N, Fz_sensor_N) as CSV "
                                 "with a # comment header (docs/bundle.md section 1), until Ctrl-C or --seconds. "
                                 "Samples with a chip error or an axis at the chip's full scale are left out. To "
                                 "calibrate, log a reference force sensor on this computer's clock during the scan "
                                 "and pass its log to magfab calibrate --reference.")
    record.add_argument("out", metavar="OUT", help="file to write")
    record.add_argument("--format", choices=record_formats.FORMATS,
                        help="csv (default), parquet (units and the calibration in its metadata) or mcap (ROS 2 "
                        "messages: WrenchStamped, MagneticField, Temperature); default: from OUT's suffix "
                        "(.parquet, .mcap), else csv. parquet and mcap need the package's extra of that name")
    record.add_argument("--seconds", type=float, metavar="S",
                        help="stop after S seconds of device time (default: record until Ctrl-C)")
    record.add_argument("--text", action="store_true", help="ask the firmware for text lines instead of binary frames")
    board_sensor.add_options(record, _SENSOR_HELP)

    info = commands.add_parser("info", parents=[common],
                               help="ask the board which sensor, spec and calibration it runs",
                               description="Send 'i', print the board's answer and the sensor its EEPROM names, and "
                               "check its calibration against this package's (or the sensor's current one, from its "
                               "record).")
    board_sensor.add_options(info, _SENSOR_HELP)

    upload = commands.add_parser(
        "upload", parents=[common], help="write a calibration into the board's EEPROM (no compiler, no reflash)",
        description="Check a calibration.json, write it into the board's EEPROM over serial (docs/bundle.md section "
        "4), read it back, and check that the board now reports its hash. Without a file: this package's own "
        "calibration (what the build's .eep holds).")
    upload.add_argument("calibration", nargs="?", metavar="CALIBRATION.json",
                        help="the calibration to write (default: the one embedded in this package)")
    board_sensor.add_options(upload, "write this sensor's current calibration from its record (not the package's) "
                             "and its ID (docs/bundle.md section 4), and note the upload in its record")
    upload.add_argument("--force", action="store_true",
                        help="write even when the board names another sensor (with --sensor), or names a sensor at "
                        "all (without: the package's calibration over that sensor's)")

    board_sensor.add_options(check.add_parser(commands, common), _SENSOR_HELP + "; the check's result is appended "
                             "to its record")
    weigh.add_parser(commands, common)
    view.add_parser(commands, common)
    return parser


_SENSOR_HELP = ("the sensor on the board: check the board against its current calibration from its record "
                "(default: the sensor the board's EEPROM names, when its record is found)")


def _simulated(args: argparse.Namespace, calibration: Calibration, pattern) -> SimulatedDevice:
    """The simulated board the options ask for: its firmware's calibration without ``thermal`` under
    --simulate-no-thermal (the field still follows the package calibration's coefficients), warming under
    --simulate-warm (stream and record: from the first second on)."""
    firmware = calibration
    thermal_per_C = None
    if args.simulate_no_thermal:
        if calibration.thermal is None:
            raise UsageError("--simulate-no-thermal: this package's calibration carries no temperature "
                                   "correction to leave out")
        data = json.loads(pkgutil.get_data("magfab_readout", "calibration.json").decode("utf-8"))  # type: ignore[union-attr]
        data.pop("thermal")
        firmware, thermal_per_C = Calibration(data), calibration.thermal.coefficient_per_C
    temperature = None
    warm = args.simulate_warm
    if warm is not None and not math.isfinite(warm):
        raise UsageError("--simulate-warm must be a number of degrees")
    if warm and args.command != "check":
        temperature = TemperatureRamp(25.0, 25.0 + warm, duration_s=abs(warm) / WARM_RATE_C_PER_S, delay_s=1.0)
    return SimulatedDevice(firmware, seed=args.simulate_seed, corrupt_fraction=args.simulate_corrupt, pattern=pattern,
                           temperature=temperature, thermal_per_C=thermal_per_C, eeprom_file=args.simulate_eeprom)


def _device(args: argparse.Namespace, text: Optional[bool], pattern=None) -> Device:
    calibration = Calibration.embedded()
    check_link(args)
    transport = None
    if args.simulate:
        transport = _simulated(args, calibration, pattern)
    elif (args.simulate_corrupt or args.simulate_seed or args.simulate_warm is not None or args.simulate_no_thermal
          or args.simulate_eeprom):
        raise DeviceError("--simulate-corrupt, --simulate-seed, --simulate-warm, --simulate-no-thermal and "
                          "--simulate-eeprom need --simulate")
    return Device(args.port, args.baud, text=text, timeout_s=args.timeout, calibration=calibration, transport=transport)


def _stream(args: argparse.Namespace, out) -> int:
    if args.zero < 0:
        raise DeviceError("--zero needs a positive number of samples")
    if args.raw and args.text:
        raise DeviceError("--raw needs binary frames: text lines carry microtesla, not raw counts")
    with _device(args, text=bool(args.text)) as device:
        if args.check or args.sensor:  # the host's forces need the calibration the board runs
            board_sensor.link(device, device.info(), args)
        out.write(f"# magfab-readout {_build.VERSION}: spec {json.dumps(_build.SPEC_NAME)}, "
                  f"calibration {device.calibration.short_hash}, {device.port}\n")
        if args.zero:
            offset = device.zero(args.zero)
            out.write("# zero: offset Fx {:+.4f} N, Fy {:+.4f} N, Fz {:+.4f} N from {} samples\n".format(
                *offset, args.zero))
        columns = ["t_s", "seq", "Fx_N", "Fy_N", "Fz_N", "Bx_uT", "By_uT", "Bz_uT", "T_C", "flags", "fault"]
        if args.raw:
            columns += ["Bx_lsb", "By_lsb", "Bz_lsb", "T_raw"]
        if args.check:
            columns.append("dF_N")
        out.write("# " + " ".join(columns) + "\n")
        rest = _rest_tracker(device)
        span = Span()
        stop = Interrupt()  # Ctrl-C ends the stream on a whole line, and the summary follows it
        worst = [0.0]  # kept however the rows end
        with stop:
            _stream_rows(args, device, out, rest, span, stop, worst)
        _summary(device, span, worst[0] if args.check else None, rest)
    return 0


def _stream_rows(args: argparse.Namespace, device: Device, out, rest: RestTracker, span: Span,
                 stop: Interrupt, worst: List[float]) -> None:
    """``stream``'s rows until ``--count``, ``--seconds`` or Ctrl-C (``stop``), each written whole; the largest
    host-firmware force difference so far (``--check``) in ``worst[0]``."""
    for sample in device.samples(count=args.count, seconds=args.seconds):
        stop.writing = True
        rest.add(sample)
        span.add(sample.time_s)
        row = [format_number(sample.time_s, 10, 4, False), f"{sample.seq:3d}"]
        row += [format_number(f, 8, 4) for f in sample.force_N]
        row += [format_number(b, 9, 2) for b in sample.B_uT]
        row += [format_number(sample.temperature_C, 6, 2, False), sample.flags,
                (sample.fault_name or "-").replace(" ", "_")]
        if args.raw:
            counts = sample.counts or (0, 0, 0)
            row += [f"{c:6d}" for c in counts] + [f"{sample.temperature_raw or 0:5d}"]
        if args.check:
            diff = cross_check(sample, device.calibration)
            worst[0] = max(worst[0], diff) if not math.isnan(diff) else worst[0]
            row.append(f"{diff:.2e}" if not math.isnan(diff) else "nan")
        out.write("  ".join(row) + "\n")
        stop.writing = False
        if stop.requested:
            break


def _rest_tracker(device: Device) -> RestTracker:
    """The rest level's tracker (rest.py), its force noise from the predicted field noise (acceptance.json)."""
    data = check.load_acceptance()
    noise = float(data["measurement"]["noise_z_uT"]) if data is not None else _build.LSB_Z_UT
    return RestTracker(device.calibration, noise)


def _summary(device: Device, span: Span, worst: Optional[float], rest: Optional[RestTracker] = None) -> None:
    s = device.stats
    text = (f"{span.n} samples{span.rate()}; {s.lost} lost (sequence gaps), {s.crc_errors} CRC errors, "
            f"{s.bad_lines} bad lines, {s.refused} refused values, {s.skipped_bytes} bytes skipped")
    if worst is not None:
        text += f"; host vs firmware force: max |dF| = {worst:.3g} N"
    print("magfab-readout: " + text, file=sys.stderr)
    if rest is not None:
        print("magfab-readout: " + rest.summary(), file=sys.stderr)


def _record(args: argparse.Namespace) -> int:
    if args.seconds is not None and not args.seconds > 0:
        raise DeviceError("--seconds must be positive")
    fmt, path = record_formats.prepare(args.format, args.out)
    with _device(args, text=bool(args.text)) as device:
        info = device.info()
        linked = board_sensor.link(device, info, args)
        for warning in [*device.check_info(info), linked.running_note(info.calibration_hash)]:
            if warning:
                print("magfab-readout: warning: " + warning, file=sys.stderr)
        sensor = [] if linked.sensor is None else [f"# sensor: {linked.sensor.id}"]
        temperature = _build.TEMPERATURE_ENABLED
        columns = [c for c in CSV_COLUMNS if temperature or c != "temperature_C"]
        written = skipped = full = 0
        stop = Interrupt()
        rest = _rest_tracker(device)
        span = Span()
        with open(path, "w", encoding="utf-8", newline="") as f:
            record_header(f, device, info, columns, sensor)
            with stop:
                for sample in device.samples(seconds=args.seconds):
                    stop.writing = True
                    rest.add(sample)
                    span.add(sample.time_s)
                    host = time.time()
                    values = list(sample.B_uT) + list(sample.force_N)
                    if sample.full_scale and not sample.chip_error:
                        full += 1  # a clipped field: no force to record
                    elif sample.chip_error or not all(math.isfinite(v) for v in values) or (
                            temperature and sample.temperature_C is None):
                        skipped += 1
                    else:
                        row = [format_csv(sample.time_s, 6), format_csv(host, 6)]
                        row += [format_csv(b, 4) for b in sample.B_uT]
                        if temperature:
                            row.append(format_csv(sample.temperature_C, 3))
                        row += [format_csv(x, 6) for x in sample.force_N] + [str(sample.status), str(sample.seq)]
                        f.write(",".join(row) + "\n")
                        written += 1
                    stop.writing = False
                    if stop.requested:
                        break
        print("magfab-readout: wrote {} rows to {}{} ({} chip-error samples and {} with an axis at the chip's full "
              "scale left out)".format(written, path, " (Ctrl-C)" if stop.requested else "", skipped, full),
              file=sys.stderr)
        _summary(device, span, None, rest)
        calibration = device.calibration
    record_formats.finish(path, args.out, fmt, calibration.to_dict, written)
    return 0


def _info(args: argparse.Namespace, out) -> int:
    with _device(args, text=None) as device:
        info = device.info()
        out.write(f"device:  {info.line}\n")
        out.write("  spec {}, calibration {}, gain_sel {}, resolution {}, osr {}, dig_filt {}\n".format(
            json.dumps(info.spec_name), info.calibration_hash, *info.settings))
        out.write(f"package: magfab-readout {_build.VERSION}, spec {json.dumps(_build.SPEC_NAME)}, "
                  f"calibration {device.calibration.short_hash}\n")
        linked = board_sensor.link(device, info, args)
        out.write(board_sensor.sensor_line(linked.identity, info.calibration_hash))
        warnings = device.check_info(info)
        for warning in warnings:
            out.write(f"warning: {warning}\n")
        if linked.superseded:
            out.write(f"calibration: match, superseded ({linked.superseded_note()})\n")
        elif linked.event is not None and linked.sensor is not None:
            out.write(f"calibration: match (sensor {linked.sensor.id}'s current calibration of "
                      f"{linked.event.get('date', '?')}, from its record in {linked.sensor.root})\n")
        else:
            out.write("calibration: match\n")
    return 0


def _upload(args: argparse.Namespace, out) -> int:
    if args.sensor:
        return _upload_sensor(args, out)
    if args.calibration:
        try:
            data = bounded.loads_json(bounded.read_bytes(args.calibration, "calibration.json"), "calibration.json",
                                      args.calibration)
        except bounded.InputFileError:
            raise
        except ValueError as exc:
            raise CalibrationError("", args.calibration, f"is not valid JSON ({exc})") from None
    else:
        data = json.loads(pkgutil.get_data("magfab_readout", "calibration.json").decode("utf-8"))  # type: ignore[union-attr]
    record = calibration_record(data)

    def write(device: Device):
        board_sensor.refuse_named_board(device, args.force)
        return device.upload(data)
    info = at_fallback_baud(args, out, lambda a: _device(a, text=None), write)
    out.write(f"uploaded {len(record)} bytes, read back equal; the board runs calibration {info.calibration_hash} "
              f"(spec {json.dumps(info.spec_name)})\n")
    return 0


def _upload_sensor(args: argparse.Namespace, out) -> int:
    """``upload --sensor ID``: the sensor's current calibration from its record and its identity onto the board,
    then an ``upload`` event in the record. Every guard runs before anything is written."""
    if args.calibration:
        raise UsageError("upload takes a CALIBRATION.json or --sensor ID, not both")
    sensor = board_sensor.open_record(args, args.sensor)
    event, data = board_sensor.current_calibration(sensor)
    record = calibration_record(data)  # what the EEPROM cannot hold is refused before the board is touched
    sha = calibration_sha256(data)
    ident = Identity(sensor.id, str(event.get("date")), sha[:16])
    try:
        identity.pack(ident)  # checks the block's fields before anything is written
    except identity.IdentityError as exc:
        raise UsageError(f"sensor {sensor.id}: {exc}") from None

    def write(device: Device):
        found = device.read_identity()
        if not args.force:
            board_sensor.refuse_other_sensor(device, found, sensor.id, f"connect sensor {sensor.id}'s board, or "
                                             "pass --force to make this board carry it")
        info = device.upload(data)
        device.write_identity(ident)
        return info, found

    info, found = at_fallback_baud(args, out, lambda a: _device(a, text=None), write)
    note: dict = {"calibration_sha256": sha, "taxel": None}
    if found is not None and found.sensor_id != sensor.id:
        note["replaced_sensor"] = found.sensor_id
    sensor.append("upload", note)
    out.write(f"uploaded {len(record)} bytes, read back equal; the board runs calibration {info.calibration_hash} "
              f"(spec {json.dumps(info.spec_name)}) and carries sensor {sensor.id}'s ID, calibration of "
              f"{ident.calibration_date}; noted in {sensor.path}\n")
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``magfab-readout`` command."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "weigh":  # an array's package has no weight plan, which weigh says
            return weigh.run(args, sys.stdout, _device)
        if (array := ArrayCalibration.embedded()) is not None:  # an array build's package: every taxel
            if args.simulate_warm is not None or args.simulate_no_thermal:
                raise UsageError("--simulate-warm and --simulate-no-thermal simulate a single taxel's board; this "
                                 "package reads an array")
            if args.command == "view":
                return view.array(args, array, lambda a, text: array_cli.open_device(a, array, text),
                                  lambda device: ArrayReader(device, array))
            return array_cli.run(args, array, sys.stdout)
        if args.command == "view":
            return view.single(args, _device)
        if args.command == "stream":
            return _stream(args, sys.stdout)
        if args.command == "record":
            return _record(args)
        if args.command == "check":
            return check.run(args, sys.stdout, _device)
        if args.command == "upload":
            return _upload(args, sys.stdout)
        return _info(args, sys.stdout)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # stdout's reader went away (| head): stop quietly
        return 0
    except (UsageError, bounded.InputFileError, DeviceError, CalibrationError, FormatError, EepromError,
            identity.IdentityError, records.RecordError, OSError) as exc:  # what was given, or the bench: exit 2
        print(f"magfab-readout: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # anything else is a bug of ours: one line naming it, exit 1, no traceback
        print(f"magfab-readout: internal error: {type(exc).__name__}: {exc} (a bug: please report it)", file=sys.stderr)
        return 1
