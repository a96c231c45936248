"""Decode throughput of the readout package's frame decoder against the fastest rate the board can send.

Run from anywhere::

    python bench/decode.py [--max-size 1M] [--repeat 3] [--compare REV [--compare-max 64K]]

The board's rates, from the package's constants (``frames.FRAME_LENGTH``, ``_build.SAMPLE_RATE_HZ``, ``_build.BAUD``
of the default spec's build) and the spec's bounds:

* **this build**: one 31-byte force frame per conversion, ``FRAME_LENGTH x SAMPLE_RATE_HZ`` bytes a second,
  within the UART's ``BAUD / 10`` (8N1: ten bits a byte);
* **the wire's ceiling**: ``baud / 10`` at the highest baud the spec allows (``[firmware] baud``, 2,000,000):
  no image, single taxel or array, sends faster than its UART.

For each input (sync pairs ``A5 5A`` repeated, ``0xA5`` alone, ``F,`` line starts, seeded random bytes, and a valid
stream of force frames) and each size from 1 KB to ``--max-size``, the bytes are fed at once to a new ``Decoder``
(``Device`` reads up to 64 KB at once), best of ``--repeat``. The table gives nanoseconds a byte, flat over the
sizes when the decoder is linear, and the throughput over each board rate: a ratio measured in this run, the
decoder's bytes a second over the board's. ``--compare REV`` decodes the same inputs, up to ``--compare-max``, with
the decoder of that git revision in the same run (``main``, or ``56aa429`` for the quadratic one).

Nothing here asserts on a time: the figures are for reading.
"""

from __future__ import annotations

import argparse
import importlib
import json
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType, SimpleNamespace

from magfab import derive, load_spec
from magfab.export.readout import _build_data, source_files
from magfab.spec import Firmware

ROOT = Path(__file__).resolve().parent.parent
FRAMES = "magfab/readout/src/magfab_readout/frames.py"
KINDS = ("sync", "a5", "line starts", "random", "valid")


def package(root: Path, compare: str | None) -> tuple[ModuleType, ModuleType, ModuleType | None]:
    """The readout package of the default spec written under ``root`` and imported: (frames, _build, the
    frames module of ``compare`` or None)."""
    src = root / "src"
    for name, data in source_files().items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(data)
    build = _build_data(derive(load_spec(None)), SimpleNamespace(sha256="0" * 64))  # no calibration is decoded
    (src / "magfab_readout" / "build.json").write_text(json.dumps(build), encoding="utf-8")
    if compare:
        old = subprocess.run(["git", "-C", str(ROOT), "show", f"{compare}:{FRAMES}"], capture_output=True, check=True)
        (src / "magfab_readout" / "frames_compared.py").write_bytes(old.stdout)
    sys.path.insert(0, str(src))
    frames = importlib.import_module("magfab_readout.frames")
    compared = importlib.import_module("magfab_readout.frames_compared") if compare else None
    return frames, importlib.import_module("magfab_readout._build"), compared


def flood(frames: ModuleType, kind: str, size: int) -> bytes:
    """``size`` bytes of one input kind (see the module's docstring)."""
    if kind == "valid":
        one = [frames.encode_frame(k, 1840 * k, 0, (120, -40, 21000 + k % 50), 46000, (0.01, -0.02, 0.5 + k % 7 / 10))
               for k in range(256)]
        stream = b"".join(one)
        return (stream * (size // len(stream) + 1))[:size]
    if kind == "random":
        return random.Random(size).randbytes(size)
    unit = {"sync": frames.SYNC, "a5": b"\xa5", "line starts": b"F,"}[kind]
    return (unit * (size // len(unit) + 1))[:size]


def seconds_per_byte(decoder_class, data: bytes, repeat: int) -> float:
    """The best of ``repeat`` timings of one decoder fed ``data`` at once (small inputs fed several times to take at
    least ~20 ms a timing), per byte."""
    rounds = max(1, (1 << 18) // len(data))
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(rounds):
            decoder_class().feed(data)
        best = min(best, (time.perf_counter() - start) / rounds)
    return best / len(data)


def size_label(n: int) -> str:
    return f"{n >> 20} MB" if n >= 1 << 20 else f"{n >> 10} KB"


def parse_size(text: str) -> int:
    units = {"K": 1 << 10, "M": 1 << 20}
    return int(text[:-1]) * units[text[-1].upper()] if text[-1:].upper() in units else int(text)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-size", type=parse_size, default=1 << 20, help="largest input (default 1M)")
    parser.add_argument("--repeat", type=int, default=3, help="timings per figure, the best kept (default 3)")
    parser.add_argument("--compare", metavar="REV", help="also time the decoder of this git revision")
    parser.add_argument("--compare-max", type=parse_size, default=1 << 16,
                        help="largest input for the compared decoder (default 64K: the quadratic one takes seconds)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        frames, build, compared = package(Path(tmp), args.compare)
        max_baud = next(m.le for m in Firmware.model_fields["baud"].metadata if hasattr(m, "le"))
        rates = {"this build": min(frames.FRAME_LENGTH * build.SAMPLE_RATE_HZ, build.BAUD / 10.0),
                 "wire ceiling": max_baud / 10.0}
        print(f"board: {frames.FRAME_LENGTH} B x {build.SAMPLE_RATE_HZ:.1f} Hz = {rates['this build']:.0f} B/s "
              f"at {build.BAUD} baud; the wire's ceiling {max_baud} baud / 10 = {rates['wire ceiling']:.0f} B/s")
        sizes = [1 << k for k in range(10, args.max_size.bit_length()) if 1 << k <= args.max_size]
        header = f"{'input':<12}{'size':>8}{'ns/B':>9}{'x build':>10}{'x ceiling':>11}"
        print(header + (f"{'ns/B ' + args.compare:>16}{'x build':>10}" if compared else ""))
        for kind in KINDS:
            for size in sizes:
                data = flood(frames, kind, size)
                per_byte = seconds_per_byte(frames.Decoder, data, args.repeat)
                row = (f"{kind:<12}{size_label(size):>8}{per_byte * 1e9:>9.0f}"
                       f"{1 / per_byte / rates['this build']:>10.0f}{1 / per_byte / rates['wire ceiling']:>11.1f}")
                if compared is not None and size <= args.compare_max:
                    old = seconds_per_byte(compared.Decoder, data, 1)
                    row += f"{old * 1e9:>16.0f}{1 / old / rates['this build']:>10.2f}"
                print(row, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
