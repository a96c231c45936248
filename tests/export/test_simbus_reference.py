"""The reference chip on the simulated bus: the shipped image with a version-5 record reads a second MLX90393 model
(the reference, 0x0D) and subtracts its averaged change; a uniform field (the sensor turned in the Earth's field) and
a dipole passing by, with and without it, against magfab's predicted rejection (magfab/models/reference.py)."""

from __future__ import annotations

import numpy as np
import pytest
from simbus import Bus
from test_simbus import Sim, sim  # noqa: F401  (the module fixture: the default build on the bus)

from magfab.reference_chip import reference_chip

REF_ADDR = 0x0D
SAMPLE_US = 2_000  # a field step per simulated 2 ms: slower than a sample (1.84 ms), as a real disturbance
FRAME_S = 1.84e-3  # MagOne's frame period (one conversion)
START_S = 0.08  # steady until then (boot, the reference's first reading, the average settled)
RUN_S = 0.55  # the turn held 270 ms: the average (about 30 ms) settled to 1e-4
MISMATCH = 0.06  # the reference chip reads 6 % high: twice the datasheet's SENSTHD band, the prediction's mismatch


@pytest.fixture(scope="module")
def setup(sim, tmp_path_factory):  # noqa: F811
    """(records: {"off": the build's .eep, "on": the same calibration with the reference block}, the design, the
    prediction's reference section)."""
    from magfab import derive, parse_spec
    from magfab.export import firmware
    from magfab.models.predict import predict

    design = derive(parse_spec("[reference]\n"))
    record = firmware.eeprom_record(design, sim.cal)
    assert record[2] == 5 and firmware._eeprom_module().reference(record) == (REF_ADDR, 3)
    on = tmp_path_factory.mktemp("reference") / "v5.eep"
    on.write_bytes(firmware._eeprom_module().intel_hex(record))
    return {"off": sim.hex_path.with_suffix(".eep"), "on": on}, design, predict(design).reference


def _run(sim: Sim, eep, disturbance, base_sense, base_ref) -> np.ndarray:  # noqa: F811
    """Fz of every frame (N) while ``disturbance(t_s) -> (dB at the sensing chip, dB at the reference)`` (uT) is
    added to the steady fields, one step per SAMPLE_US, from START_S on."""
    with Bus(sim.lib, sim.hex_path, sim.addr7, eep) as bus:
        k = bus.add_chip(REF_ADDR)
        decoder = sim.frames.Decoder()
        out = []
        steps = int(RUN_S * 1e6 / SAMPLE_US)
        for i in range(steps):
            t = i * SAMPLE_US * 1e-6
            d_s, d_r = disturbance(t) if t >= START_S else (np.zeros(3), np.zeros(3))
            bus.target(0).set_field(*(np.add(base_sense, d_s)))
            bus.target(k).set_field(*(np.add(base_ref, d_r) * (1 + MISMATCH)))
            out += [s.force_N[2] for s in sim.samples(decoder, bus.run_us(SAMPLE_US)) if not s.chip_error]
        assert decoder.stats.crc_errors == 0 and len(out) > 0.9 * RUN_S / FRAME_S
    return np.array(out)


def _errors_mN(fz: np.ndarray, held_s: float = 0.06) -> tuple[float, float]:
    """(the largest departure from the steady force once the disturbance starts, the departure averaged over the
    run's last ``held_s``), mN; steady: the median of the frames before it, after the first 30 ms."""
    steady = np.median(fz[int(0.03 / FRAME_S):int(START_S / FRAME_S)])
    after = fz[int(START_S / FRAME_S) + 1:] - steady
    return float(1000 * np.max(np.abs(after))), float(1000 * abs(np.mean(after[-int(held_s / FRAME_S):])))


FIELD = (0.0, 0.0, 18000.0)  # the sensing chip's steady field (near MagOne's rest), uT
REF_FIELD = (0.0, -23.0, -43.0)  # the magnet's field at the reference chip (predictions.json's rest_G), uT


@pytest.mark.parametrize("step_uT", [130.0, 1000.0])
def test_a_uniform_field_turned_on(sim, setup, step_uT):  # noqa: F811
    """A uniform change on z at both chips over 200 ms, then held: 130 uT is the sensor turned over in the strongest
    Earth field (1.3 G on an axis), 1 mT a far magnet's (z alone: at rest Br = |Bx|, so a lateral part would read
    nonlinearly at zero). Without the reference the force moves by the drift budget's figure; with it, what is left
    held is the chips' 6 % mismatch (within the predicted rejection, 1 / (mismatch + cross-axis)), plus a count's
    rounding on each chip (4.84 uT on z at MagOne's gain: at 130 uT as large as the mismatch); while it turns, the
    average's lag (8 readings every other sample, about 30 ms) adds rate x lag."""
    records, _design, section = setup
    step = np.array([0.0, 0.0, step_uT])

    def turn(t: float):
        b = step * min(1.0, (t - START_S) / 0.2)
        return b, b

    off = _errors_mN(_run(sim, records["off"], turn, FIELD, REF_FIELD))
    on = _errors_mN(_run(sim, records["on"], turn, FIELD, REF_FIELD))
    ratio = off[1] / on[1]
    count_mN = off[1] / step_uT * sim.build_info["lsb_z_uT"]  # one z count as force
    print(f"{step_uT:g} uT uniform on z over 200 ms: held {off[1]:.1f} mN without the reference, {on[1]:.2f} mN with "
          f"it ({ratio:.0f}x; predicted at least {section['rejection']['uniform']:.0f}x, one count {count_mN:.2f} mN); "
          f"while turning at most {off[0]:.1f} and {on[0]:.1f} mN")
    assert on[1] <= off[1] / section["rejection"]["uniform"] + count_mN
    if step_uT >= 1000:  # the mismatch well above a count: the ratio is the mismatch's
        assert ratio == pytest.approx(1 / MISMATCH, rel=0.15)
    else:
        assert off[1] > 20.0  # turned over in 1.3 G: about 23 mN at this field without the reference
    assert on[0] < off[0] / 3


def test_a_dipole_passing_by(sim, setup):  # noqa: F811
    """A 0.5 A m^2 dipole (moment along z) passing the sensing chip 100 mm away along x, on the far side from the
    reference: the force error with and without the reference against the exact field difference at the two chips
    (the model's rejection for that pass)."""
    from magfab.models.drift import dipole_field_G

    records, design, _section = setup
    sense = np.array([0.0, 0.0, design.z_sense_mm])
    ref = np.array([reference_chip(design).x_mm, reference_chip(design).y_mm, design.z_sense_mm])

    def where(t: float) -> np.ndarray:
        return np.array([-150.0 + 900.0 * (t - START_S), -100.0, 0.0])  # 0.9 m/s along x

    def passing(t: float):
        at = where(t)
        m = np.array([0.0, 0.0, 0.5])
        return dipole_field_G(m, at, sense) * 100.0, dipole_field_G(m, at, ref) * 100.0  # G -> uT

    off = _errors_mN(_run(sim, records["off"], passing, FIELD, REF_FIELD))[0]
    on = _errors_mN(_run(sim, records["on"], passing, FIELD, REF_FIELD))[0]
    ts = np.linspace(START_S, RUN_S, 400)
    b = np.array([passing(t) for t in ts])
    left = b[:, 0, 2] - b[:, 1, 2] * (1 + MISMATCH)
    predicted = np.max(np.abs(b[:, 0, 2])) / np.max(np.abs(left))
    print(f"a 0.5 A m^2 dipole passing 100 mm away: {off:.1f} mN without, {on:.1f} mN with the reference "
          f"({off / on:.2f}x; the field difference predicts {predicted:.2f}x)")
    # the two chips are read a conversion apart while the field sweeps past, so what the reference leaves depends on
    # where the reads fall in the pass: the boot's phase moved it from 1.67x to 2.00x (predicted 1.58x)
    assert off > 5.0 and 0.75 * predicted <= off / on <= 1.35 * predicted


def test_a_missing_reference_chip_costs_no_force_frame(sim, setup):  # noqa: F811
    """The reference chip off the bus (unsoldered, a broken trace): every frame still carries the sensing chip's
    force, uncompensated; it comes back and the compensation resumes, no frame flagged."""
    records, _, _ = setup
    with Bus(sim.lib, sim.hex_path, sim.addr7, records["on"]) as bus:
        k = bus.add_chip(REF_ADDR)
        bus.target(0).set_field(*FIELD)
        bus.target(k).absent(True)
        decoder = sim.frames.Decoder()
        gone = sim.samples(decoder, bus.run_us(200_000))
        bus.target(k).absent(False)
        bus.target(k).set_field(*REF_FIELD)
        back = sim.samples(decoder, bus.run_us(300_000))  # restarted within MF_LOST_RETRY_US, its average settled
        bus.target(0).set_field(*np.add(FIELD, (0.0, 0.0, 500.0)))
        bus.target(k).set_field(*np.add(REF_FIELD, (0.0, 0.0, 500.0)))
        moved = sim.samples(decoder, bus.run_us(200_000))
    assert len(gone) >= 90 and not any(s.chip_error or s.recovered for s in gone + back + moved)
    assert len({round(s.force_N[2], 6) for s in gone + back}) == 1  # the same field, the same force throughout
    change = 1000 * abs(moved[-1].force_N[2] - back[-1].force_N[2])
    assert change < 2.0, change  # 500 uT uniform: about 88 mN uncompensated, a count's rounding with it
