"""An array's firmware: field frames (docs/bundle.md section 3), the array record (section 4), and the image
reading every chip on the simulated bus (tests/export/test_simbus_array.py does the bus)."""

from __future__ import annotations

import math

import pytest

from magfab import derive, load_spec
from magfab.export.readout import render

from conftest import ref_crc16
from readout_support import imported, make_calibration


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
    assert [(i.spec_name, i.taxels, i.settings) for i in infos] == [("strip,x", 5, (7, 0, 0, 2)), ("one", 1, (7, 0, 0, 2))]
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
