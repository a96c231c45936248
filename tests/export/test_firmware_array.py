"""An array's firmware: field frames (docs/bundle.md section 3), the array record (section 4), and the image
reading every chip on the simulated bus (tests/export/test_simbus_array.py does the bus)."""

from __future__ import annotations

import itertools
import math
import struct
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import _missing, ref_crc16, require_tool
from readout_support import imported, make_calibration
from simbus import Bus, HarnessUnavailable, build_library

from magfab import derive, load_spec
from magfab.export.readout import render


@pytest.fixture(scope="module")
def pkg(tmp_path_factory):
    """The default build's readout package, imported from its rendered source."""
    with imported(render(derive(load_spec(None)), make_calibration()), tmp_path_factory.mktemp("pkg")) as module:
        yield module


@pytest.fixture(scope="module")
def frames(pkg):
    return pkg.frames


def test_field_frames_decode_to_samples_with_their_taxel_mixed_with_text_and_noise(frames):
    f = frames
    stream = b"\x00\xa5" + f.encode_field_frame(3, 7, 1234, 0, (10, -20, 300), 46000)
    stream += f.encode_field_line(4, 7, 1300, 0, (1.5, -2.25, 300.0), 25.5)
    stream += f.encode_field_frame(1, 8, 1400, f.STATUS_CHIP_ERROR | f.STATUS_RECOVERED, (0, 0, 0), 0x0101)
    stream += f.encode_field_line(2, 8, 1500, f.STATUS_CHIP_ERROR, (math.nan,) * 3, None, fault=0x0104)
    stream += f.encode_frame(9, 1600, 0, (1, 2, 3), 46000, (0.1, 0.2, 0.3))
    stream += f.encode_info_line("strip,x", "0123456789abcdef", 7, 0, 0, 2, taxels=5)
    stream += f.encode_info_line("one", "0123456789abcdef", 7, 0, 0, 2)
    frame = f.encode_field_frame(3, 7, 1234, 0, (10, -20, 300), 46000)
    assert len(frame) == f.FIELD_FRAME_LENGTH and frame[2] == f.FRAME_FIELD
    assert int.from_bytes(frame[-2:], "little") == ref_crc16(frame[2:-2])
    decoder = f.Decoder(lsb_xy_uT=0.5, lsb_z_uT=0.25, temperature=True)
    out = []
    for k in range(0, len(stream), 7):  # in pieces: a frame or line split across reads
        out += decoder.feed(stream[k:k + 7])
    samples = [x for x in out if isinstance(x, f.Sample)]
    assert [s.taxel for s in samples] == [3, 4, 1, 2, 0]
    a, b, c, d, e = samples
    assert a.B_uT == (5.0, -10.0, 75.0) and a.counts == (10, -20, 300) and a.seq == 7 and a.t_us == 1234
    assert all(math.isnan(x) for x in a.force_N) and a.temperature_C is not None and a.source == "binary"
    assert b.B_uT == (1.5, -2.25, 300.0) and b.temperature_C == 25.5 and all(math.isnan(x) for x in b.force_N)
    assert c.chip_error and c.recovered and c.fault_name == "nack at read" and all(math.isnan(x) for x in c.B_uT)
    assert d.chip_error and d.fault_name == "chip ERROR bit at read" and d.source == "text"
    assert e.force_N == pytest.approx((0.1, 0.2, 0.3)) and e.taxel == 0
    infos = [x for x in out if isinstance(x, f.DeviceInfo)]
    assert [(i.spec_name, i.taxels, i.settings) for i in infos] == [("strip,x", 5, (7, 0, 0, 2)),
                                                                    ("one", 1, (7, 0, 0, 2))]
    assert decoder.stats.frames == 3 and decoder.stats.lines == 2 and decoder.stats.crc_errors == 0
    assert decoder.stats.lost == 0  # one sequence per taxel: 7 and 8 on different taxels lose nothing


def test_a_corrupt_field_frame_is_refused_and_the_next_decodes(frames):
    f = frames
    good = f.encode_field_frame(0, 1, 10, 0, (1, 2, 3), 0)
    bad = bytearray(f.encode_field_frame(1, 1, 10, 0, (1, 2, 3), 0))
    bad[12] ^= 0x40
    decoder = f.Decoder()
    out = decoder.feed(bytes(bad) + good + f.encode_field_frame(0, 3, 20, 0, (1, 2, 3), 0))
    assert [s.taxel for s in out] == [0, 0] and decoder.stats.crc_errors == 1 and decoder.stats.lost == 1


def test_a_cycle_frame_decodes_to_every_chips_sample_and_a_corrupt_one_is_refused_whole(frames):
    """One cycle frame gives each chip's sample in taxel order, at the head's time plus its own offset, a chip error
    with its fault and NaN field; a bit flipped anywhere in a frame refuses the whole cycle (every taxel of it is
    then lost, counted) and the next decodes; a head claiming no chips or more than 16 is noise."""
    f = frames
    chips = [(0, 0, (10, -20, 300), 46000), (f.STATUS_CHIP_ERROR | f.STATUS_RECOVERED, 250, (0, 0, 0), 0x0101),
             (f.STATUS_FULL_SCALE, 65535, (32767, 0, -5), 46100)]
    frame = f.encode_cycle_frame(7, 1000, chips)
    assert len(frame) == f.cycle_frame_length(3) == 9 + 33 + 2 and frame[2] == f.FRAME_CYCLE
    decoder = f.Decoder()
    out = decoder.feed(b"\x00\xa5" + frame + b"noise" + frame[:20]) + decoder.feed(frame[20:])
    assert [(s.taxel, s.seq, s.t_us, s.counts) for s in out] == [
        (k, 7, 1000 + dt, c) for _ in range(2) for k, (_, dt, c, _) in enumerate(chips)]
    assert out[1].chip_error and out[1].fault == 0x0101 and math.isnan(out[1].B_uT[0]) and out[1].recovered
    assert out[2].full_scale and out[0].temperature_raw == 46000 and decoder.stats.crc_errors == 0
    for at in range(2, len(frame)):
        bad = bytearray(frame)
        bad[at] ^= 0x10
        decoder = f.Decoder()
        later = f.encode_cycle_frame(9, 5000, chips)
        got = decoder.feed(bytes(bad) + later)
        assert [s.seq for s in got] == [9, 9, 9], at
        assert decoder.stats.crc_errors + decoder.stats.skipped_bytes > 0
    for n in (0, 17):
        noise = f.SYNC + bytes([f.FRAME_CYCLE, 1, 0, 0, 0, 0, n]) + bytes(30)
        assert f.Decoder().feed(noise + frame)[0].seq == 7


# ---- the array's record ---------------------------------------------------------------------------------------

EXAMPLES = Path(__file__).resolve().parents[2] / "magfab" / "examples"
ARRAYS = ("fingertip_2x2", "strip_1x5")


@pytest.fixture(scope="module")
def designs():
    return {name: derive(load_spec(EXAMPLES / f"{name}.toml")) for name in ARRAYS}


@pytest.mark.parametrize("name", ARRAYS)
def test_the_array_record_carries_every_address_and_the_settings_no_calibration(designs, name):
    from magfab.export import firmware

    design, cal = designs[name], make_calibration()
    record = firmware.eeprom_record(design, cal)
    addresses = [t.i2c_address for t in design.taxels]
    settings = firmware.image_settings(design)
    ee = firmware._eeprom_module()
    n = len(addresses)
    assert record[:4] == b"MF\x03" + bytes([n]) and struct.unpack_from("<H", record, 4)[0] == len(record)
    assert record[8:24].decode() == firmware.calibration_sha256(cal)[:16]
    assert record[92:92 + n] == bytes(addresses) and settings["taxel_addresses"] == addresses
    assert record[92 + n:-2] == design.spec.name.encode() and ee.check(record) and ee.addresses(record) == addresses
    assert int.from_bytes(record[-2:], "little") == ref_crc16(record[:-2])
    assert ee.unpack_header(record)["image"]["i2c_address"] == addresses[0]
    assert len(record) == 92 + n + len(design.spec.name.encode()) + 2  # no calibration: ~100 B, not ~450 per taxel
    assert firmware.render(design, cal)[firmware.EEP_NAME] == ee.intel_hex(record)
    single = derive(load_spec(None))
    assert "taxel_addresses" not in firmware.image_settings(single)
    assert firmware.eeprom_record(single, cal)[2] == 2  # a single taxel's record as before
    for bad in ([], addresses + addresses[:1], [0x07], list(range(0x20, 0x31))):
        with pytest.raises(ee.EepromError):
            ee.pack_array(bad, "0" * 16, settings)
    assert ee.buses(record) == 0  # every taxel on the one bus
    split = ee.pack_array(addresses, "0" * 16, settings, 1 << (n - 1))
    assert ee.buses(split) == 1 << (n - 1) and split[6:8] == (1 << (n - 1)).to_bytes(2, "little") and ee.check(split)
    for mask in (-1, 1 << n):
        with pytest.raises(ee.EepromError):
            ee.pack_array(addresses, "0" * 16, settings, mask)


# ---- the shipped image reading every chip on the simulated bus -------------------------------------------------

SETTLE_US = 80_000  # every chip started (about 8 ms each: exit, reset, configure, burst) and streaming


def chip_field(k: int) -> tuple:
    """A field per chip, different on every axis, so a frame carrying another chip's counts is caught."""
    return (150.0 * k - 300.0, 40.0 - 90.0 * k, 21000.0 + 700.0 * k)


@dataclass
class ArraySim:
    lib: object
    hex_path: Path
    eep: Path
    addresses: list
    settings: dict
    frames: object

    def boot(self, eep=None) -> Bus:
        bus = Bus(self.lib, self.hex_path, self.addresses[0], eep or self.eep)
        for a in self.addresses[1:]:
            bus.add_chip(a)
        for k in range(len(self.addresses)):
            bus.target(k).set_field(*chip_field(k))
        return bus.target(0)

    def decoder(self):
        return self.frames.Decoder(self.settings["lsb_xy_uT"], self.settings["lsb_z_uT"])

    def counts(self, k: int) -> tuple:
        lsb = (self.settings["lsb_xy_uT"], self.settings["lsb_xy_uT"], self.settings["lsb_z_uT"])
        return tuple(round(b / q) for b, q in zip(chip_field(k), lsb))


def samples_of(decoder, data: bytes) -> list:
    return [s for s in decoder.feed(data) if isinstance(s, frames_module(decoder).Sample)]


def frames_module(decoder):
    return sys.modules[type(decoder).__module__]


def cycles(samples: list) -> list:
    """The samples grouped by sequence number (one group per cycle), whole cycles only."""
    out, group = [], []
    for s in samples:
        if group and s.seq != group[0].seq:
            out.append(group)
            group = []
        group.append(s)
    return out[1:]  # the first may have started before the window


@pytest.fixture(scope="module")
def harness(tmp_path_factory, designs, frames):
    """The shipped image, the harness library, and per example its rendered .eep."""
    from magfab.export import firmware, toolchain

    require_tool("cc")
    root = tmp_path_factory.mktemp("array-bus")
    out = {}
    for name, design in designs.items():
        toolchain.write_tree(firmware.render(design, make_calibration()), root / name / "firmware")
        hex_path = root / name / "firmware" / firmware.HEX_NAME
        hex_path.write_bytes(firmware.shipped_image()[0])
        out[name] = (hex_path, design)
    try:
        lib = build_library(root / ARRAYS[0], root)
    except HarnessUnavailable as exc:
        _missing(str(exc))
    return {name: ArraySim(lib, hex_path, hex_path.with_suffix(".eep"), [t.i2c_address for t in design.taxels],
                           firmware.image_settings(design), frames) for name, (hex_path, design) in out.items()}


@pytest.mark.parametrize("name", ARRAYS)
def test_every_chip_is_read_every_cycle_with_its_own_counts(harness, name):
    sim = harness[name]
    n = len(sim.addresses)
    with sim.boot() as bus:
        decoder = sim.decoder()
        samples_of(decoder, bus.run_us(SETTLE_US))
        got = samples_of(decoder, bus.run_us(60_000))
        bus.send(b"i")
        infos = [x for x in decoder.feed(bus.run_us(20_000)) if isinstance(x, sim.frames.DeviceInfo)]
    whole = cycles(got)
    assert len(whole) >= 10
    assert all([s.taxel for s in c] == list(range(n)) for c in whole)  # every chip, in taxel order, once
    assert all(s.counts == sim.counts(s.taxel) and s.status == 0 for s in got)
    assert all(math.isnan(s.force_N[0]) for s in got) and all(c[0].t_us < c[-1].t_us for c in whole)
    assert [(i.taxels, i.spec_name) for i in infos] == [(n, name)]
    assert decoder.stats.lost == 0 and decoder.stats.crc_errors == 0


def test_text_mode_sends_a_field_line_per_chip(harness):
    sim = harness["fingertip_2x2"]
    with sim.boot() as bus:
        decoder = sim.decoder()
        samples_of(decoder, bus.run_us(SETTLE_US))
        bus.send(b"t")
        bus.run_us(10_000)
        got = samples_of(decoder, bus.run_us(30_000))
    assert got and all(s.source == "text" for s in got)
    assert {s.taxel for s in got} == {0, 1, 2, 3}
    lsb = (sim.settings["lsb_xy_uT"], sim.settings["lsb_xy_uT"], sim.settings["lsb_z_uT"])
    for s in got:
        assert s.B_uT == pytest.approx([c * q for c, q in zip(sim.counts(s.taxel), lsb)], abs=0.006)


ONE_CHIP_FAULTS = {
    "address NACK": (lambda bus: bus.nack(addr_phases=1), "nack at read", 30_000),
    "chip reset": (lambda bus: bus.chip_fault("reset"), "chip reset at read", 30_000),
    "off the bus 150 ms": (lambda bus: bus.absent(True), "nack at read", 150_000),
}


def assert_whole_and_back(got: list, sim: ArraySim, decoder, chips) -> None:
    """After faults on ``chips``: every good reading has its chip's own counts, every cycle has every chip, each of
    ``chips`` comes back after its last error (a reading flagged recovered, then no more errors), and no frame was
    lost or corrupt."""
    n = len(sim.addresses)
    assert all(s.counts == sim.counts(s.taxel) for s in got if not s.chip_error)
    assert all([s.taxel for s in c] == list(range(n)) for c in cycles(got))
    for k in chips:
        back = [s for s in got[max(i for i, s in enumerate(got) if s.chip_error and s.taxel == k):] if s.taxel == k]
        assert back[1].recovered and not any(s.chip_error for s in back[1:]), k
    assert decoder.stats.lost == 0 and decoder.stats.crc_errors == 0


@pytest.mark.parametrize("real", [False, True], ids=["simavr's bus", "real-timed bus"])
@pytest.mark.parametrize("which", ["first", "middle", "last"])
@pytest.mark.parametrize("fault", list(ONE_CHIP_FAULTS))
@pytest.mark.parametrize("name", ARRAYS)
def test_a_fault_on_one_chip_flags_only_that_taxel_and_it_recovers(harness, name, fault, which, real):
    """One chip fails (NACKed once, reset in burst, or off the bus for a while): only its taxel's frames carry the
    error, every cycle still has a frame of every chip, the others' counts stay right, and it comes back flagged
    recovered with its own counts. The chip is the cycle's first (its read chained behind the last cycle's last chip),
    a middle one, or the last (whose read has the next cycle's first chained behind it), on simavr's bus and on one
    timed like a real 400 kHz bus, where each read starts behind the one before."""
    from magfab.export.firmware import LOST_RETRY_US

    inject, named, during_us = ONE_CHIP_FAULTS[fault]
    sim = harness[name]
    n = len(sim.addresses)
    k = {"first": 0, "middle": n // 2, "last": n - 1}[which]
    with sim.boot() as bus:
        bus.real_timing(real)
        decoder = sim.decoder()
        samples_of(decoder, bus.run_us(SETTLE_US))
        inject(bus.target(k))
        during = samples_of(decoder, bus.run_us(during_us))
        bus.target(k).absent(False)
        after = samples_of(decoder, bus.run_us(LOST_RETRY_US + 30_000))
    got = during + after
    errors = [s for s in got if s.chip_error]
    assert errors and {s.taxel for s in errors} == {k} and errors[0].fault_name == named
    assert_whole_and_back(got, sim, decoder, [k])
    assert not any(s.recovered for s in got if s.taxel != k)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("name", ARRAYS)
def test_drawn_faults_on_a_real_timed_bus_touch_only_their_chips(harness, name, seed):
    """Faults drawn at random (seeded): six NACKed reads and chip resets, each on a drawn chip at a drawn time, 12 to
    20 ms apart (a chip's restart, about 8 ms, done before the next: a fault during a restart fails the start, and
    the chip is tried again 100 ms later), on the bus timed like a real one, where every read is chained behind the
    one before and the last chip's behind the next cycle's first. No frame is lost or corrupt, every cycle has every
    chip, every good reading has its chip's own counts, only the chips struck give error readings (at most one a
    fault), and each comes back (a reading flagged recovered, then no more errors)."""
    import numpy as np

    sim = harness[name]
    n = len(sim.addresses)
    rng = np.random.default_rng([seed, n])
    struck: dict[int, int] = {}
    with sim.boot() as bus:
        bus.real_timing(True)
        decoder = sim.decoder()
        samples_of(decoder, bus.run_us(SETTLE_US))
        got = []
        for _ in range(6):
            k = int(rng.integers(n))
            target = bus.target(k)
            target.nack(addr_phases=1) if rng.random() < 0.5 else target.chip_fault("reset")
            struck[k] = struck.get(k, 0) + 1
            got += samples_of(decoder, bus.run_us(float(rng.uniform(12_000, 20_000))))
        got += samples_of(decoder, bus.run_us(30_000))
    errors = [s for s in got if s.chip_error]
    assert {s.taxel for s in errors} <= set(struck)
    assert all(sum(s.taxel == k for s in errors) <= m for k, m in struck.items())
    assert_whole_and_back(got, sim, decoder, {s.taxel for s in errors})


# ---- the rate, in simulated time ---------------------------------------------------------------------------------

#: (chips, baud): the 1x1, 2x2 and 1x5 arrays at the default baud, where the UART binds from 3 chips on; five and
#: sixteen chips at 1 Mbaud (exact with U2X at 16 MHz), where the chips' conversions bind (simavr's TWI takes about
#: 9 us a byte, faster than a real 400 kHz bus: test_simbus_timing.py holds the real bus's rates).
RATE_CASES = [(1, 250_000), (4, 250_000), (5, 250_000), (5, 1_000_000), (16, 250_000),
              pytest.param(16, 1_000_000, marks=pytest.mark.slow)]


@pytest.mark.parametrize("chips, baud", RATE_CASES)
def test_per_taxel_and_total_rate_in_simulated_time(harness, designs, tmp_path, chips, baud):
    """Every chip's readings at the rate the tightest of three bounds allows: the chips' conversions (each chip read
    on its own grid, so every conversion is read while a cycle fits in one), the UART (baud / 10 bits a byte over a
    cycle frame of the chips) and the loop (a chip's read and its piece of the frame, times the chips: simavr's TWI
    keeps its own byte time whatever TWBR says: the cycles' own period, so this bound says only that no cycle
    stalls beyond its work); at least 97 % of it, no error, every chip equally often, never a conversion twice."""
    sim = _array_sim(harness, designs, tmp_path, chips, baud)
    with sim.boot() as bus:
        decoder = sim.decoder()
        samples_of(decoder, bus.run_us(SETTLE_US + 10_000 * chips))
        t0, c0 = bus.time_us, [bus.target(k).conversions for k in range(chips)]
        got = samples_of(decoder, bus.run_us(300_000))
        elapsed = (bus.time_us - t0) * 1e-6
        converted = [bus.target(k).conversions - c0[k] for k in range(chips)]
    counts = [sum(s.taxel == k for s in got) for k in range(chips)]
    per_taxel = [c / elapsed for c in counts]
    cycle_hz = converted[0] / elapsed
    uart_hz = baud / 10 / sim.frames.cycle_frame_length(chips)
    # the loop: a cycle from its first chip's read to the next cycle's (the reads, the frames, the cycle's own work)
    periods = [b[0].t_us - a[0].t_us for a, b in itertools.pairwise(cycles(got))]
    loop_hz = 1e6 * len(periods) / sum(periods) if periods else math.inf
    bound = min(cycle_hz, uart_hz, loop_hz)
    print(f"{chips} chips at {baud} baud: per taxel {min(per_taxel):.1f} Hz, total {len(got) / elapsed:.0f} frames/s; "
          f"bounds per taxel: cycle {cycle_hz:.1f} Hz, UART {uart_hz:.1f} Hz, loop {loop_hz:.1f} Hz "
          f"({1e6 / loop_hz / chips if periods else 0:.0f} us a chip); "
          f"chips convert at {converted[0] / elapsed:.1f} Hz "
          f"({min(per_taxel) * elapsed / converted[0]:.0%} of conversions read)")
    assert not any(s.chip_error for s in got) and all(s.counts == sim.counts(s.taxel) for s in got)
    assert max(counts) - min(counts) <= 1  # one frame apart at most: the window's edge
    assert 0.97 * bound <= min(per_taxel) <= 1.01 * bound + 1 / elapsed  # one cycle more at the window's edges
    assert all(p * elapsed <= c + 1 for p, c in zip(per_taxel, converted))  # never a conversion twice


def _array_sim(harness, designs, tmp_path, chips: int, baud: int, buses: int = 0) -> ArraySim:
    """The shipped image with an array record of ``chips`` chips (option codes 011 to 014 with every strap: 0x0C to
    0x1B) at ``baud``, fingertip_2x2's chip settings; ``buses`` its mask of taxels on a second bus."""
    from magfab.export import firmware

    ee = firmware._eeprom_module()
    base = designs["fingertip_2x2"].spec
    settings = firmware.image_settings(derive(base.model_copy(
        update={"firmware": base.firmware.model_copy(update={"baud": baud})})))
    addresses = [0x0C + k for k in range(chips)]
    eep = tmp_path / firmware.EEP_NAME
    eep.write_bytes(ee.intel_hex(ee.pack_array(addresses, "0" * 16, settings, buses)))
    return ArraySim(harness[ARRAYS[0]].lib, harness[ARRAYS[0]].hex_path, eep, addresses, settings,
                    harness[ARRAYS[0]].frames)


#: The most a chip's read may take in a cycle on the real-timed bus (12 bytes at 400 kHz, 233 us, the repeated START
#: that chains it behind the read before, and the TWI interrupt's turn at each step), and what a cycle takes besides:
#: the temperature word one chip a cycle reads (two bytes more). Sixteen chips then read at 201 Hz a taxel, over the
#: goal of 200 Hz, and five chips fit in one conversion (docs/bundle.md section 3).
CHIP_READ_US, CYCLE_EXTRA_US = 307.5, 50.0


def real_bus_share(chips: int) -> float:
    """The least share of a chip's conversions (543.5 Hz, MagOne's settings) a taxel of ``chips`` is read at on the
    real-timed bus at 1 Mbaud: every conversion (99 %) while the cycle's reads fit in one, else a cycle of
    ``chips`` reads of CHIP_READ_US and CYCLE_EXTRA_US."""
    return min(0.99, 1e6 / (chips * CHIP_READ_US + CYCLE_EXTRA_US) / 543.5)


def test_the_real_bus_bounds_hold_the_goals():
    """The bounds the rate test holds every array size to are the goals at five and sixteen chips, or stricter."""
    assert real_bus_share(5) == 0.99 and real_bus_share(16) * 543.5 >= 200.0


#: (chips, baud, the least share of the chips' conversions read a taxel on a bus timed like a real 400 kHz one): every
#: array size at 1 Mbaud, and one chip at the default 250000 baud.
REAL_BUS_CASES = [(1, 250_000, 0.99), *((n, 1_000_000, real_bus_share(n)) for n in range(1, 17))]


@pytest.mark.parametrize("chips", [3, 5, 7])
def test_every_reading_carries_its_chips_temperature_word_past_the_sequence_wrap(harness, designs, tmp_path, chips):
    """Over more than 256 cycles (the sequence number wraps; a cycle reads the temperature word of one chip in turn,
    the turn from the sequence number, and the next cycle's first chip is queued with its turn's channels), every
    reading of every chip carries its chip's temperature word (25 C here), for chip counts that do not divide 256."""
    sim = _array_sim(harness, designs, tmp_path, chips, 1_000_000)
    with sim.boot() as bus:
        bus.real_timing(True)
        decoder = sim.decoder()
        samples_of(decoder, bus.run_us(SETTLE_US + 10_000 * chips))
        got = samples_of(decoder, bus.run_us(270 * max(1840, chips * 320)))  # 270 cycles or more
    assert len({s.seq for s in got}) == 256 and len(got) > 256 * chips
    assert not any(s.chip_error for s in got)
    assert {s.temperature_raw for s in got} == {sim.settings["t_raw_25c"]}


def test_the_one_bus_image_refuses_a_record_that_names_a_second_bus(harness, designs, tmp_path):
    """The ATmega328P has one I2C bus: an array record with a taxel on a second (an RP2040 board's split) is refused
    as a missing record is, so the image reads no chip and sends no reading, only its error lines (the missing
    calibration's fault); the same record with every taxel on the one bus streams."""
    for buses, streams in ((0b10, False), (0, True)):
        sim = _array_sim(harness, designs, tmp_path, 2, 250_000, buses)
        with sim.boot() as bus:
            out = bus.run_us(SETTLE_US + 40_000)
            got = samples_of(sim.decoder(), out)
            reads = [bus.target(k).conversions for k in range(2)]
        good = [s for s in got if not s.chip_error and all(math.isfinite(b) for b in s.B_uT)]
        assert got and bool(good) == streams and (min(reads) > 0) == streams, (buses, len(good), reads, out[:80])


@pytest.mark.parametrize("chips, baud, share", REAL_BUS_CASES)
def test_the_share_of_conversions_read_on_a_real_timed_bus(harness, designs, tmp_path, chips, baud, share):
    """On the bus timed like a real 400 kHz one (9 SCL periods a byte, START, repeated START, STOP and the bus's free
    time), every chip's readings come at least at ``share`` of its conversions, every chip equally often, with its
    own counts and never a conversion twice."""
    sim = _array_sim(harness, designs, tmp_path, chips, baud)
    with sim.boot() as bus:
        bus.real_timing(True)
        decoder = sim.decoder()
        samples_of(decoder, bus.run_us(SETTLE_US + 10_000 * chips))
        t0, c0 = bus.time_us, [bus.target(k).conversions for k in range(chips)]
        got = samples_of(decoder, bus.run_us(300_000))
        converted = [bus.target(k).conversions - c0[k] for k in range(chips)]
        elapsed = (bus.time_us - t0) * 1e-6
    counts = [sum(s.taxel == k for s in got) for k in range(chips)]
    print(f"{chips} chips at {baud} baud, real-timed bus: {min(counts) / elapsed:.1f} Hz a taxel, "
          f"{min(c / v for c, v in zip(counts, converted)):.1%} of the conversions")
    assert not any(s.chip_error for s in got) and all(s.counts == sim.counts(s.taxel) for s in got)
    assert max(counts) - min(counts) <= 1 and decoder.stats.lost == 0 and decoder.stats.crc_errors == 0
    assert all(c <= v + 1 for c, v in zip(counts, converted))  # never a conversion twice
    assert min(c / v for c, v in zip(counts, converted)) >= share


# ---- the readout package of an array build: what it knows, and upload ---------------------------------------------


@contextmanager
def other_package(rendered: dict, root: Path):
    """A second rendered readout package imported while the module's own is loaded (its modules set aside)."""
    kept = {n: m for n, m in sys.modules.items() if n == "magfab_readout" or n.startswith("magfab_readout.")}
    for name in kept:
        del sys.modules[name]
    try:
        with imported(rendered, root) as module:
            yield module
    finally:
        sys.modules.update(kept)


def test_an_array_build_readout_knows_its_chips_and_uploads_their_record(harness, designs, tmp_path):
    """The 1x5 build's readout package: its addresses from build.json, the record it packs equal to magfab's .eep,
    and Device.upload writing it to an erased board over serial, after which every chip streams its own field."""
    from test_simbus import BusTransport

    from magfab.export import firmware, readout

    sim, design, cal = harness["strip_1x5"], designs["strip_1x5"], make_calibration()
    with other_package(readout.render(design, cal), tmp_path / "pkg") as pkg:
        assert tuple(sim.addresses) == pkg.device.TAXEL_ADDRESSES and pkg.device.TAXELS == 5
        assert pkg.device.calibration_record(cal) == firmware.eeprom_record(design, cal)
        bus = Bus(sim.lib, sim.hex_path, sim.addresses[0], None)
        for a in sim.addresses[1:]:
            bus.add_chip(a)
        for k in range(5):
            bus.target(k).set_field(*chip_field(k))
        with bus:
            bus.run_us(30_000)
            info = pkg.device.Device(transport=BusTransport(bus), timeout_s=20.0).upload(cal)
            assert bus.eeprom(0, 120)[:len(firmware.eeprom_record(design, cal))] == firmware.eeprom_record(design, cal)
            bus.send(b"b")
            bus.run_us(20_000)
            decoder = pkg.frames.Decoder()
            got = [s for s in decoder.feed(bus.run_us(40_000)) if isinstance(s, pkg.frames.Sample)]
    assert info.taxels == 5 and info.calibration_hash == firmware.calibration_sha256(cal)[:16]
    assert {s.taxel for s in got} == set(range(5)) and not any(s.chip_error for s in got)
    assert all(s.counts == sim.counts(s.taxel) for s in got)
