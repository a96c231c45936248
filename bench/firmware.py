"""Per-sample cost of the readout firmware on the ATmega328P (Arduino Uno / Nano, 16 MHz), from simavr.

Run from anywhere::

    python bench/firmware.py [--spec SPEC] [--calibration calibration.json] [--orders 1,2,3,4,5,6]
                             [--hull N] [--build BUILD_DIR] [--no-rate] [--out DIR]

What it measures:

1. **Cycles**, counted by the CPU itself: the bundle's ``avr/bench.c`` (built with the same flags as the image)
   times each stage with Timer1 running at the CPU clock and prints the counts on its UART; simavr runs it
   cycle-accurately. Stages: raw words -> counts and microtesla (``convert``), forces with the direction split
   and the region test (``calibrate``), the binary frame with its CRC and the text line, and the whole
   per-sample path (``sample_binary`` = convert + calibrate + binary frame). Four field points: the hull's
   centre (accepted by the inner rectangle), near a hull vertex (the full O(log N) hull test), on the axis
   (no shear direction) and outside the box.
2. **Budget per sample** on the chip's clock: the worst ``sample_binary`` plus the UART interrupts that drain one
   31-byte frame (an estimate: cycles per interrupt below), or the RM transfer on the I2C bus at the spec's clock
   (computed from the bit count) if that is longer (the image reads the next sample from the TWI interrupt while it
   processes and sends the last), against the conversion wait the firmware paces itself by.
3. **Flash and RAM** of the real image (avr-size: text + data, data + bss).
4. **Generic against build-specific**: the image every build ships (settings from the EEPROM record) and one
   compiled with the spec's settings as constants (``firmware.render(generic=False)``): cycles per sample, flash
   and RAM of both, the measurement behind shipping the generic one.
5. **The shipped build, measured**: the cycles per sample with the build's own calibration.json, and the output
   rate of its .hex on the simulated I2C bus (tests/export/simbus: libsimavr with the build's MLX90393 model,
   which converts at the datasheet table's time; the bus timed like a real one at the image's SCL clock):
   frames per simulated second against the chip's conversions over the same time, at the tests' field and at
   fields across the calibrated region (``region_fields``: the worst, median and best are printed), and at each
   where the cycle goes, from a profile of the running image (its program counter every 37 cycles, grouped by
   function: float arithmetic, the calibration's own code, the frame, the interrupts, the I2C driver, and the
   spare time until the next conversion; the bus's busy time apart, as it overlaps them). The worst field is the
   one where the processor is busiest (a 1 s window's count can differ by one frame at the edge).
   ``--build`` names an existing build folder; without it the spec is built into a temporary one (a minute).
   ``--no-rate`` skips this part; ``--record-rate`` writes it (worst, median, best, and the settings it ran with)
   beside the generic image, ``magfab/export/generic_image/rate.json``, where every build with those settings quotes it
   in its firmware README, report and predictions.json (``firmware.measured_rate_for``; a build with others says how
   it differs, and no figure), and tests/export/test_simbus_timing.py holds it to a new measurement.

A synthetic calibration per order (random coefficients, an elliptical hull of N points) stands in unless
``--calibration`` gives a real one. Prints a table and writes ``<out>/firmware_bench.json``. Nothing here
asserts on a time: the figures are for reading.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import re
import sys
import tempfile
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH_DIR.parent))

from magfab import derive, load_spec  # noqa: E402 - imported after sys.path points at the repository
from magfab.export import firmware, toolchain  # noqa: E402 - imported after sys.path points at the repository

DEFAULT_OUT = BENCH_DIR / "out"
JSON_NAME = "firmware_bench.json"
#: Cycles per UDRE interrupt that moves one byte from the ring buffer to the UART (prologue, 8-bit index
#: arithmetic, epilogue), estimated from the ISR's size; 31 per binary frame.
UART_ISR_CYCLES = 60
#: Simulated seconds of streaming the rate is measured over (after the boot), and the boot allowance.
RATE_SECONDS = 1.0
SETTLE_US = 40_000


def synthetic_calibration(order: int, hull_points: int, seed: int = 0) -> dict:
    """A calibration.json dict of the documented shape with random coefficients and an elliptical hull."""
    import random

    rng = random.Random(seed)
    monomials = [[i, k - i] for k in range(order + 1) for i in range(k, -1, -1)]
    hull = [[-3000.0 + 2400.0 * math.cos(2 * math.pi * k / hull_points),
             2000.0 + 1700.0 * math.sin(2 * math.pi * k / hull_points)] for k in range(hull_points)]
    return {
        "format": "magfab-calibration/1", "method": "poly", "order": order, "monomials": monomials,
        "scaling": {"Bz_uT": {"center": -3000.0, "scale": 2400.0}, "Br_uT": {"center": 2000.0, "scale": 1700.0}},
        "coefficients": {"Fz_N": [rng.gauss(0.0, 1.0) for _ in monomials],
                         "Fr_N": [rng.gauss(0.0, 0.5) for _ in monomials]},
        "shear_sign": -1, "direction_min_uT": 5.0, "tare_N": {"Fz_N": 0.0, "Fr_N": 0.0},
        "valid_region": {"Bz_uT": [-5400.0, -600.0], "Br_uT": [300.0, 3700.0], "hull": hull},
    }


def rm_transfer_us(i2c_hz: float, words: int) -> float:
    """RM on the bus: START, address + command, repeated START, address + status + 2 bytes per word, STOP
    (9 clocks per byte, about one clock each for START, repeated START and STOP)."""
    bits = 9 * 2 + 9 * (2 + 2 * words) + 3
    return bits * 1e6 / i2c_hz


def measure(design, calibration: dict, generic: bool = True) -> dict:
    files = firmware.render(design, calibration, generic=generic)
    image = toolchain.build_hex(files)
    with tempfile.TemporaryDirectory(prefix="magfab-fw-bench-") as tmp:
        elf, _ = toolchain.build_avr_elf(files, tmp, "bench")
        uart = toolchain.run_simavr(elf)
    if uart is None:
        raise SystemExit("simavr is not installed (Debian package simavr)")
    cycles: dict[str, dict[str, int]] = {}
    for m in re.finditer(r"BENCH,(\w+),(\w+),(\d+)", uart):
        cycles.setdefault(m.group(1), {})[m.group(2)] = int(m.group(3))
    if "sample_binary" not in cycles:
        raise SystemExit(f"the bench image printed no cycle counts:\n{uart[-2000:]}")
    flags = {m.group(1): int(m.group(2)) for m in re.finditer(r"FLAGS,(\w+),(\d+)", uart)}
    return {"cycles": cycles, "flags": flags, "sizes": image[1] if image else None,
            "hull_points": len(calibration["valid_region"]["hull"])}


def shipped(spec_path: Path | None, build_dir: Path | None) -> dict:
    """The shipped build measured: cycles per sample with its calibration.json, and its .hex's output rate on the
    simulated bus timed like a real one, at fields across the calibrated region, against the chip's conversions
    (simulated time); at the slowest field, where the cycle goes (a profile of the image, by function group)."""
    sys.path.insert(0, str(BENCH_DIR.parent / "tests" / "export"))
    from simbus import Bus, build_library, functions, region_fields, steady  # the harness

    with tempfile.TemporaryDirectory(prefix="magfab-fw-rate-") as tmp:
        out = build_dir
        if out is None:
            from magfab import build

            out = Path(tmp) / "build"
            build(load_spec(spec_path), out)
        hex_path = out / "firmware" / firmware.HEX_NAME
        if not hex_path.exists():
            raise SystemExit(f"{hex_path} is missing: the build needs avr-gcc (Debian gcc-avr, avr-libc)")
        cal = json.loads((out / "calibration" / "calibration.json").read_text())
        design = derive(load_spec(spec_path))
        cycles = measure(design, cal)["cycles"]
        lib = build_library(out, Path(tmp))

        symbols = functions(toolchain.build_avr_elf(firmware.generic_sources(), Path(tmp) / "elf", "main")[0])

        def run(field) -> dict:
            with Bus(lib, hex_path, design.i2c_address, hex_path.with_suffix(".eep")) as bus:
                bus.set_field(*field)
                bus.real_timing()
                r = steady(bus, RATE_SECONDS, SETTLE_US, profile=True)
                frames = r.out.count(b"\xa5\x5a\x01")  # sync and frame type; the tests decode them fully
                per_frame_us = r.seconds * 1e6 / frames
                budget = r.budget_us(frames, symbols)
                return {"field_uT": list(field), "rate_Hz": frames / r.seconds, "chip_Hz": r.chip_Hz,
                        "delivered": frames / r.conversions, "frames": frames, "cycle_us": per_frame_us,
                        "busy_us": r.busy_us(frames, symbols), "budget_us": budget}

        rows = [run(f) for f in [(1200.0, -800.0, 20000.0), *region_fields(cal)]]  # the tests' field, the region
        image_sha256 = hashlib.sha256(hex_path.read_bytes()).hexdigest()  # read before a temporary build goes
    rows.sort(key=lambda r: -r["busy_us"])  # the busiest processor first (the share delivered is printed beside it)
    return {"sample_cycles": max(cycles["sample_binary"].values()), "fields": rows, "image_sha256": image_sha256,
            "calibration": {"spec": design.spec.name, "method": cal["method"], "order": cal["order"],
                            "hull_points": len(cal["valid_region"]["hull"])},
            "settings": firmware.rate_settings(design),
            "worst": rows[0], "median": rows[len(rows) // 2], "best": rows[-1], "seconds": RATE_SECONDS,
            "cycle_at_worst_us": rows[0]["cycle_us"], "budget_at_worst_us": rows[0]["budget_us"]}


def record_rate(m: dict, i2c_hz: float) -> Path:
    """``rate.json`` beside the generic image (:func:`magfab.export.firmware.measured_rate`) from :func:`shipped`'s
    measurement: only of the shipped image itself."""
    image, _ = firmware.shipped_image()
    if m["image_sha256"] != hashlib.sha256(image).hexdigest():
        raise SystemExit("the build's image is not the shipped one (rebuilt since?): rebuild the build first")

    def row(r: dict) -> dict:
        return {"field_uT": [round(b, 1) for b in r["field_uT"]], "rate_Hz": round(r["rate_Hz"], 1),
                "delivered": round(r["delivered"], 4), "busy_us": round(r["busy_us"], 1),
                "cycle_us": round(r["cycle_us"], 1)}

    record = {"image_sha256": hashlib.sha256(image).hexdigest(), "calibration": m["calibration"],
              "settings": m["settings"],
              "fields": len(m["fields"]), "seconds": m["seconds"], "i2c_Hz": i2c_hz,
              "chip_Hz": round(m["worst"]["chip_Hz"], 3), **{k: row(m[k]) for k in ("worst", "median", "best")}}
    path = BENCH_DIR.parent / "magfab" / "export" / firmware.GENERIC_DIR / firmware.GENERIC_RATE
    path.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    return path


def generic_vs_own(design, calibration: dict, f_mhz: float) -> dict:
    """The generic image against one with the spec's settings compiled in: worst cycles per sample, flash, RAM."""
    out = {}
    for name, generic in (("generic", True), ("own", False)):
        r = measure(design, calibration, generic)
        sizes = r["sizes"] or {}
        out[name] = {"sample_cycles": max(r["cycles"]["sample_binary"].values()),
                     "flash_bytes": sizes.get("flash_bytes"), "ram_bytes": sizes.get("ram_bytes")}
    g, o = out["generic"], out["own"]
    print(f"generic image (settings from EEPROM) against build-specific (order {calibration['order']}): "
          f"{g['sample_cycles']} vs {o['sample_cycles']} cycles per sample "
          f"({(g['sample_cycles'] - o['sample_cycles']) / f_mhz:+.0f} us, "
          f"{g['sample_cycles'] / o['sample_cycles'] - 1:+.1%}), "
          f"flash {g['flash_bytes']} vs {o['flash_bytes']} B, RAM {g['ram_bytes']} vs {o['ram_bytes']} B")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spec", type=Path, help="spec TOML (default: the embedded MagOne design)")
    parser.add_argument("--calibration", type=Path, help="a calibration.json to time instead of synthetic ones")
    parser.add_argument("--orders", default="1,2,3,4,5,6", help="polynomial orders of the synthetic calibrations")
    parser.add_argument("--hull", type=int, default=28,
                        help="points on the synthetic hull (the EEPROM record holds 1 KB: 28 fit up to order 6 "
                             "with the settings)")
    parser.add_argument("--build", type=Path, help="an existing build folder to measure (default: build the spec)")
    parser.add_argument("--no-rate", action="store_true", help="skip the shipped build's rate on the simulated bus")
    parser.add_argument("--record-rate", action="store_true",
                        help="write the shipped build's measured rate beside the generic image in the source tree "
                             "(magfab/export/generic_image/rate.json), which builds quote; the build must run the "
                             "shipped image")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)

    design = derive(load_spec(args.spec))
    chip = firmware.chip_config(design)
    f_mhz = firmware.F_CPU_HZ / 1e6
    _, _, i2c_hz = firmware.twi_settings(design.spec.firmware.i2c_hz)
    bus_us = rm_transfer_us(i2c_hz, 4 if chip.temperature else 3)
    uart_us = 31 * UART_ISR_CYCLES / f_mhz
    if args.calibration:
        calibrations = [json.loads(args.calibration.read_text())]
    else:
        calibrations = [synthetic_calibration(int(n), args.hull) for n in args.orders.split(",")]

    print(f"ATmega328P at {f_mhz:g} MHz, simavr cycle counts; chip: GAIN_SEL {chip.gain_sel} RES {chip.resolution} "
          f"OSR {chip.osr} DIG_FILT {chip.dig_filt}, {'T+' if chip.temperature else ''}XYZ conversion "
          f"{chip.tconv_us} us by the datasheet's table, one read per conversion ({chip.sample_rate_Hz:.1f} Hz)")
    print(f"per sample besides the computation: RM on the bus {bus_us:.0f} us at {i2c_hz / 1e3:.0f} kHz, "
          f"UART interrupts ~{uart_us:.0f} us (estimate, {UART_ISR_CYCLES} cycles x 31 bytes)")
    header = (f"{'order':>5} {'hull':>4} {'convert':>8} {'calib ctr':>9} {'calib edge':>10} {'frame bin':>9} "
              f"{'frame txt':>9} {'sample':>7} {'sample us':>9} {'+bus+uart':>9} {'CPU Hz':>7} {'rate Hz':>7} "
              f"{'flash B':>7} {'RAM B':>5}")
    print(header)
    rows = []
    for cal in calibrations:
        r = measure(design, cal)
        c = r["cycles"]
        worst = max(c["sample_binary"].values())
        sample_us = worst / f_mhz
        busy_us = max(sample_us + uart_us, bus_us)  # the RM runs from the TWI interrupt while the last sample is sent
        rate = 1e6 / max(busy_us, chip.tconv_us)
        sizes = r["sizes"] or {}
        row = {
            "order": cal["order"], "hull_points": r["hull_points"], "cycles": c, "flags": r["flags"],
            "sample_cycles_worst": worst, "sample_us": sample_us, "bus_us": bus_us, "uart_us_estimate": uart_us,
            "busy_us": busy_us, "cpu_bound_rate_Hz": 1e6 / busy_us, "calibrated_rate_Hz": rate,
            "conversion_us": chip.tconv_us, "share_of_conversion": busy_us / chip.tconv_us,
            "flash_bytes": sizes.get("flash_bytes"), "ram_bytes": sizes.get("ram_bytes"),
        }
        rows.append(row)
        print(f"{cal['order']:>5} {r['hull_points']:>4} {max(c['convert'].values()):>8} "
              f"{c['calibrate']['centre']:>9} {c['calibrate']['edge']:>10} {max(c['frame_binary'].values()):>9} "
              f"{max(c['frame_text'].values()):>9} {worst:>7} {sample_us:>9.0f} {busy_us:>9.0f} "
              f"{1e6 / busy_us:>7.0f} {rate:>7.0f} {sizes.get('flash_bytes', '-'):>7} {sizes.get('ram_bytes', '-'):>5}")
    print("cycles are per call (best of 4 repeats; the run is deterministic); 'sample' is the worst point; "
          "'rate' = 1 / max(busy time, the conversion).")
    result = {"f_cpu_Hz": firmware.F_CPU_HZ, "spec": design.spec.name, "i2c_Hz": i2c_hz, "rows": rows,
              "generic_vs_own": generic_vs_own(design, calibrations[0], f_mhz)}
    if not args.no_rate:
        m = shipped(args.spec, args.build)
        result["shipped"] = m
        print(f"shipped build: {m['sample_cycles']} cycles per sample ({m['sample_cycles'] / f_mhz:.0f} us); on the "
              f"simulated bus timed at the image's I2C clock, over {len(m['fields'])} fields of the calibrated "
              f"region ({m['seconds']:g} simulated s each), frames against the chip's conversions:")
        for which in ("worst", "median", "best"):
            r = m[which]
            print("  {:6s} ({:8.1f}, {:8.1f}, {:8.1f}) uT: {:6.1f} Hz of {:.1f} Hz ({:.1%}); CPU busy {:.0f} of "
                  "{:.0f} us a frame".format(which, *r["field_uT"], r["rate_Hz"], r["chip_Hz"], r["delivered"],
                                             r["busy_us"], r["cycle_us"]))
        print(f"  where a cycle goes at the worst field ({m['cycle_at_worst_us']:.0f} us a frame; a profile of the "
              "image, every 37 cycles; the bus's busy time overlaps the CPU's):")
        for group, us in sorted(m["budget_at_worst_us"].items(), key=lambda kv: -kv[1]):
            print(f"    {group:46s} {us:7.1f} us")
        if args.record_rate:
            print(f"wrote {record_rate(m, i2c_hz)}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / JSON_NAME).write_text(json.dumps(result, indent=2, sort_keys=True) + "\n")
    print(f"wrote {args.out / JSON_NAME}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
