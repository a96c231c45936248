"""The wire protected in every mode: single-byte corruptions of the firmware's
text lines and binary frames never decode to a different force; values the firmware never means (non-finite,
beyond the force band, spelled as Python reads but C never prints) are refused even under a right checksum; a
frame with the chip-error bit never yields a force. Measured on the readout package's own decoder over lines
and frames from its simulated board (which the firmware tests hold byte-identical to the C core's output).

Sized for CI (3,000 corruptions per mode, the sample the unprotected wire was once measured with); ``-m slow`` tries
every byte value at every position of 40 lines and 40 frames."""

from __future__ import annotations

import math
import random
import struct

import pytest
from conftest import ref_crc16
from test_readout import calibration, design, pkg, rendered  # noqa: F401  (the readout package, rendered once)


def stream(readout, text: bool, n: int, chip_error_every: int = 0) -> list[bytes]:
    """``n`` samples of the simulated board, one wire item (line or frame) each."""
    sim = readout.SimulatedDevice(realtime=False, chunk=1, text=text, chip_error_every=chip_error_every)
    return [sim._sample_bytes(k) for k in range(n)]


def _same(a, b) -> bool:
    return all((x == y) or (math.isnan(x) and math.isnan(y)) for x, y in zip(a, b))


def corruptions(readout, items: list[bytes], trials) -> dict[str, int]:
    """Decode each single-byte corruption of ``items[k]`` between its neighbours; count what came out.

    ``trials(k, item)`` yields (position, new byte). 'silent' counts decoded samples whose force (or field,
    status or time) differs from what was sent under that sequence number: the failure the unprotected wire showed."""
    originals = readout.Decoder().feed(b"".join(items))
    sent = {(s.seq, s.t_us): s for s in originals}  # t_us is unique: the sequence number wraps at 256
    assert len(sent) == len(items)
    counts = {"tried": 0, "silent": 0, "silent_force": 0, "lost": 0, "intact": 0}
    for k, item in enumerate(items):
        before, after = items[k - 1] if k else b"", items[k + 1] if k + 1 < len(items) else b""
        for pos, value in trials(k, item):
            bad = item[:pos] + bytes([value]) + item[pos + 1:]
            got = [s for s in readout.Decoder().feed(before + bad + after) if isinstance(s, readout.Sample)]
            counts["tried"] += 1
            wrong = [s for s in got if (s.seq, s.t_us) not in sent or not (
                _same(s.force_N, sent[s.seq, s.t_us].force_N) and _same(s.B_uT, sent[s.seq, s.t_us].B_uT)
                and s.status == sent[s.seq, s.t_us].status)]
            counts["silent"] += bool(wrong)
            counts["silent_force"] += any((s.seq, s.t_us) not in sent
                                          or not _same(s.force_N, sent[s.seq, s.t_us].force_N) for s in wrong)
            counts["lost" if len(got) < 2 + bool(before and after) else "intact"] += not wrong
    return counts


def random_trials(seed: int, per_item: int):
    rng = random.Random(seed)

    def trials(k, item):
        for _ in range(per_item):
            pos = rng.randrange(len(item))
            yield pos, (item[pos] + rng.randrange(1, 256)) % 256  # always a different byte
    return trials


def every_trial(k, item):
    for pos in range(len(item)):
        for value in range(256):
            if value != item[pos]:
                yield pos, value


@pytest.mark.parametrize("text", [True, False], ids=["text", "binary"])
def test_single_byte_corruptions_never_decode_to_a_different_force(pkg, text, record_property):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    """3,000 random single-byte corruptions of 300 lines (frames): before the checksum, 534 of 3,000 text-line
    corruptions decoding silently to a different force; now none may, in either mode."""
    items = stream(pkg, text, 300, chip_error_every=37)
    counts = corruptions(pkg, items, random_trials(12, 10))
    record_property("corruptions", counts)
    print(("text" if text else "binary"), counts)
    assert counts["tried"] == 3000 and counts["silent"] == 0, counts


@pytest.mark.slow
@pytest.mark.parametrize("text", [True, False], ids=["text", "binary"])
def test_every_single_byte_corruption_exhaustive(pkg, text):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    items = stream(pkg, text, 40, chip_error_every=7)
    counts = corruptions(pkg, items, every_trial)
    print(("text" if text else "binary"), counts)
    assert counts["silent"] == 0, counts


def checked(body: bytes) -> bytes:
    return body + b"*%04X\n" % ref_crc16(body)


GOOD = b"F,9,5000,0,0.1000,0.2000,1.5000,60.08,-3.00,29824.08,25.02"


@pytest.mark.parametrize("force", [b"inf", b"-inf", b"1e999", b"Infinity", b"1_0", b"nan", b"1e3", b"+1.0",
                                   b" 1.0", b"\xd9\xa1", b"1000.0001", b"-2000.0000", b"1.5e+09", b"0x1"])
def test_a_force_the_firmware_never_means_is_refused_even_with_a_right_checksum(pkg, force):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    """inf, 1e999, Infinity and 1_0 were once accepted as forces. The grammar is what
    mf_format_float prints; a value beyond FORCE_LIMIT_N or not finite (without the chip-error bit) is refused
    and counted."""
    line = GOOD.replace(b"1.5000", force)
    decoder = pkg.Decoder()
    good = decoder.feed(checked(GOOD))
    assert [s.force_N for s in good] == [(0.1, 0.2, 1.5)]
    assert decoder.feed(checked(line)) == []
    assert decoder.stats.lines == 1
    if line.isascii():  # a non-ASCII byte is skipped as noise before the line is parsed
        assert decoder.stats.bad_lines + decoder.stats.refused == 1


def test_lines_without_a_right_checksum_are_refused(pkg):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    decoder = pkg.Decoder()
    body = GOOD
    cases = [body + b"\n", body + b"*\n", body + b"*12\n", checked(body).replace(b"*", b"*0", 1),
             checked(body).lower() if b"A" <= checked(body)[-2:-1] <= b"F" else checked(body)[:-2] + b"G\n",
             checked(body.replace(b"F,9,", b"F,19,"))[:-5] + checked(body)[-5:]]
    for wire in cases:
        assert decoder.feed(wire) == [], wire
    assert decoder.stats.bad_lines == len(cases) and decoder.stats.lines == 0
    assert len(decoder.feed(checked(body))) == 1


FRAME = struct.Struct("<BBBI3hH3f")


def frame(status: int, forces) -> bytes:
    body = FRAME.pack(1, 5, status, 1000, 100, -200, 3000, 46244, *forces)
    return b"\xa5\x5a" + body + struct.pack("<H", ref_crc16(body))


def test_a_chip_error_frame_never_yields_a_force(pkg):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    """A CRC-valid frame with the chip-error bit once passed its finite forces through. The host
    gives the sample (sequence, time, flags) with NaN forces and field, whatever the frame carries."""
    for status in (0x02, 0x03, 0x0A, 0xFE):
        (s,) = pkg.Decoder().feed(frame(status, (0.25, -0.5, 1.0)))
        assert s.chip_error and all(math.isnan(f) for f in s.force_N + s.device_force_N + s.B_uT)
        assert (s.seq, s.t_us, s.status, s.temperature_C) == (5, 1000, status, None)
    text = pkg.Decoder().feed(checked(GOOD.replace(b"F,9,5000,0,", b"F,9,5000,2,")))
    assert text[0].chip_error and all(math.isnan(f) for f in text[0].force_N + text[0].B_uT)
    (ok,) = pkg.Decoder().feed(frame(0x01, (0.25, -0.5, 1.0)))
    assert ok.force_N == (0.25, -0.5, 1.0) and not ok.chip_error


@pytest.mark.parametrize("forces", [(math.inf, 0.0, 0.0), (0.0, -math.inf, 0.0), (0.0, 0.0, math.nan),
                                    (1000.5, 0.0, 0.0), (0.0, 0.0, -3.4e38)])
def test_a_frame_with_a_force_out_of_band_is_refused(pkg, forces):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    decoder = pkg.Decoder()
    assert decoder.feed(frame(0x00, forces) + frame(0x04, (0.0, 0.0, 1000.0))) != []
    assert decoder.stats.refused == 1 and decoder.stats.frames == 1 and decoder.stats.crc_errors == 0


def _saturated_counts(readout, axes: str) -> tuple[int, ...]:
    """Counts with each axis of ``axes`` at the chip's full scale (the rest well inside it)."""
    full = readout._build.FULL_SCALE_COUNTS
    return tuple(full if a in axes else 100 * (i + 1) for i, a in enumerate(("Bx", "By", "Bz")))


@pytest.mark.parametrize("status", [0x04, 0x05, 0x0C])
@pytest.mark.parametrize("axes", ["Bz", "Bx", "ByBz"])
@pytest.mark.parametrize("forces", [(0.0, 0.0, 578.0), (0.1, -0.2, 3.0), (0.0, 0.0, 5000.0), (0.0, 0.0, math.inf)])
def test_a_full_scale_frame_never_yields_a_force(pkg, status, axes, forces):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    """A frame with an axis at the chip's full scale once passed its force (Fz = 578 N, flagged o and S) to stream
    as a number. Whatever force it carries, even one out of band, the host gives NaN forces, keeps the field and the
    counts, counts the frame, and names the fault with the axes at full scale."""
    counts = _saturated_counts(pkg, axes)
    body = FRAME.pack(1, 5, status, 1000, *counts, 46244, *forces)
    decoder = pkg.Decoder(lsb_xy_uT=3.004, lsb_z_uT=4.84)
    (s,) = decoder.feed(b"\xa5\x5a" + body + struct.pack("<H", ref_crc16(body)))
    assert s.full_scale and not s.chip_error and decoder.stats.frames == 1 and decoder.stats.refused == 0
    assert all(math.isnan(f) for f in s.force_N + s.device_force_N)
    assert s.counts == counts and s.B_uT == (counts[0] * 3.004, counts[1] * 3.004, counts[2] * 4.84)
    named = [a for a in ("Bx", "By", "Bz") if a in axes]
    assert s.fault_name == "full scale on " + "+".join(named) and "S" in s.flags


def test_a_full_scale_text_line_never_yields_a_force(pkg):  # noqa: F811 - pkg: the fixture imported from test_readout.py
    """The same in text mode: the line's field stands, its force is NaN, the fault says full scale; a force far out
    of band on a full-scale line is not refused (the field is the reading), on any other line it is."""
    for status, force in ((4, b"0.0000,0.0000,578.0000"), (5, b"0.0000,0.0000,5000.0000"), (4, b"nan,nan,nan")):
        decoder = pkg.Decoder()
        (s,) = decoder.feed(checked(b"F,9,5000,%d,%s,60.08,-3.00,106480.00,25.02" % (status, force)))
        assert s.full_scale and all(math.isnan(f) for f in s.force_N) and s.B_uT == (60.08, -3.0, 106480.0)
        assert s.fault_name == "full scale" and decoder.stats.refused == 0
    decoder = pkg.Decoder()
    assert decoder.feed(checked(b"F,9,5000,0,0.0000,0.0000,5000.0000,60.08,-3.00,106480.00,25.02")) == []
    assert decoder.stats.refused == 1
