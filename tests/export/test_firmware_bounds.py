"""The firmware's record check refuses the records whose formula the validator refuses: mf_calib.c,
compiled for the host with gcc against an EEPROM held in a buffer, loads the records eeprom.py packs from
generated calibration documents (tests/calibration_strategies.py: each number in bounds, combined badly or not)
and agrees with calibration_json.validate on every one; an accepted one gives finite forces wherever the
region and the chip's temperature range are sampled; a temperature outside that range is not divided by (the
sample is flagged)."""

from __future__ import annotations

import copy
import math
import subprocess
from pathlib import Path

import pytest
from calibration_strategies import calibration, region_points
from conftest import require_tool
from hypothesis import HealthCheck, assume, event, given, settings
from readout_support import ref_forces
from test_firmware import make_calibration

from magfab import derive, load_spec
from magfab.export import firmware, toolchain
from magfab.readout.src.magfab_readout import calibration_json, float32_bound
from magfab.readout.src.magfab_readout.calibration_json import AXES, THERMAL_REFERENCE_C, CalibrationError

SETTINGS = {"deadline": None, "derandomize": True,
            "suppress_health_check": [HealthCheck.too_slow, HealthCheck.function_scoped_fixture]}
#: The record check's thresholds (calibration_json's THERMAL_MIN_DENOMINATOR, INPUT_MAX, FORCE_MAX_N): a document
#: within this relative distance of one is left out of the agreement, where float32 and float64 may round apart.
EDGE = 1e-3

HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "mf_calib.h"
#include "mf_errors.h"
#include "mf_frame.h"
#include "mf_nv.h"

static uint8_t nv[MF_NV_SIZE];
uint8_t mf_nv_byte(uint16_t a) { return nv[a]; }
uint16_t mf_nv_u16(uint16_t a) { return (uint16_t)(nv[a] | (nv[a + 1] << 8)); }
uint32_t mf_nv_u32(uint16_t a) { return (uint32_t)mf_nv_u16(a) | ((uint32_t)mf_nv_u16((uint16_t)(a + 2)) << 16); }
float mf_nv_float(uint16_t a) { float f; memcpy(&f, &nv[a], 4); return f; }
void mf_nv_write(uint16_t a, const uint8_t *d, uint8_t n) { memcpy(&nv[a], d, n); }
uint16_t mf_crc16_update(uint16_t crc, const uint8_t *d, uint8_t n)
{
    uint8_t k, b;
    for (k = 0; k < n; ++k) {
        crc = (uint16_t)(crc ^ ((uint16_t)d[k] << 8));
        for (b = 0; b < 8; ++b) {
            crc = (uint16_t)((crc & 0x8000U) ? ((unsigned)crc << 1) ^ 0x1021U : (unsigned)crc << 1);
        }
    }
    return crc;
}

/* stdin: "R <hex>" loads a record and prints "L <status>"; "E bx by bz t" (t "nan": none) prints the forces */
int main(void)
{
    static char line[4096];
    while (fgets(line, sizeof line, stdin)) {
        if (line[0] == 'R') {
            size_t k = 0;
            const char *p = line + 2;
            memset(nv, 0xFF, sizeof nv);
            while (p[0] && p[1] && p[0] != '\n' && k < sizeof nv) {
                char byte[3] = {p[0], p[1], 0};
                nv[k++] = (uint8_t)strtoul(byte, NULL, 16);
                p += 2;
            }
            printf("L %d\n", mf_calib_load());
        } else if (line[0] == 'E') {
            mf_sample_t s;
            memset(&s, 0, sizeof s);
            s.b_uT[0] = strtof(line + 2, NULL);
            {
                char *q = line + 2;
                int k;
                for (k = 1; k <= 3; ++k) {
                    strtof(q, &q);
                    if (k < 3) {
                        s.b_uT[k] = strtof(q, NULL);
                    } else {
                        s.t_C = strtof(q, NULL);
                    }
                }
            }
            mf_calib_forces(&s);
            printf("F %.9g %.9g %.9g %u\n", (double)s.f_N[0], (double)s.f_N[1], (double)s.f_N[2], s.flags);
        }
        fflush(stdout);
    }
    return 0;
}
"""


@pytest.fixture(scope="module")
def harness(tmp_path_factory) -> Path:
    """mf_calib.c of the generic sources and the harness above, built with the host flags of the firmware tests."""
    require_tool("gcc")
    root = tmp_path_factory.mktemp("bounds")
    toolchain.write_tree(firmware.generic_sources(), root)
    core = root / firmware.CORE_DIR
    (root / "harness.c").write_text(HARNESS)
    exe = root / "harness"
    subprocess.run(["gcc", *firmware.HOST_CFLAGS, "-I", str(core), "-o", str(exe),
                    str(root / "harness.c"), str(core / "mf_calib.c"), "-lm"], check=True, capture_output=True)
    return exe


@pytest.fixture(scope="module")
def image_settings() -> dict:
    settings_ = firmware.image_settings(derive(load_spec(None)))
    ee = firmware._eeprom_module()
    assert settings_["flags"] & ee.FLAG_TEMPERATURE, "MagOne converts the temperature: its records carry thermal"
    return settings_


def _run(exe: Path, script: str) -> list[str]:
    out = subprocess.run([str(exe)], input=script, capture_output=True, text=True, timeout=60, check=True)
    return out.stdout.splitlines()


def _record(doc: dict, settings_: dict) -> bytes | None:
    """The record eeprom.py packs from the document's values, before the formula check (None: the record cannot
    hold them, e.g. a scale whose reciprocal is no float32; upload refuses those)."""
    ee = firmware._eeprom_module()
    values = getattr(calibration_json, "_values", calibration_json.validate)  # validate: the code before the check
    checked = values(copy.deepcopy(doc))
    try:
        return ee.pack(ee.layout(checked), "0" * 16, settings_)
    except ee.EepromError:
        return None


def _near_edge(doc: dict) -> bool:
    checked = calibration_json._values(copy.deepcopy(doc))
    margins = []
    if checked.thermal is not None:
        t = checked.thermal
        margins += [(1.0 + a * (temp - t.reference_C)) / calibration_json.THERMAL_MIN_DENOMINATOR
                    for a in t.coefficient_per_C for temp in THERMAL_REFERENCE_C]
    reach = []
    for k, (lo, hi) in enumerate(calibration_json.region_box(checked)):
        reach.append(max(abs(lo - checked.center[k]), abs(hi - checked.center[k])) / checked.scale[k])
    margins += [r / calibration_json.INPUT_MAX for r in reach]
    if all(r <= calibration_json.INPUT_MAX for r in reach):
        pu, pv = max(1.0, reach[0]), max(1.0, reach[1])
        margins += [sum(abs(c) * pu ** i * pv ** j for c, (i, j) in zip(checked.coefficients[f], checked.monomials))
                    / calibration_json.FORCE_MAX_N for f in calibration_json.FORCES]
    return any(math.isfinite(m) and abs(m - 1.0) < EDGE for m in margins)


def _samples(doc: dict) -> list[tuple[float, float, float, float]]:
    """(Bx, By, Bz, T) read by the chip whose corrected field lies in the region, over the temperature range."""
    temps = [math.nan] if "thermal" not in doc else [THERMAL_REFERENCE_C[0], 25.0, THERMAL_REFERENCE_C[1]]
    out = []
    for bz, br in region_points(doc):
        for t in temps:
            d = [1.0] * 3 if math.isnan(t) else [
                1.0 + doc["thermal"]["coefficient_per_C"][k] * (t - doc["thermal"]["reference_C"]) for k in AXES]
            out.append((0.6 * br * d[0], 0.8 * br * d[1], bz * d[2], t))
    return out


def test_the_issue_examples_are_refused_by_the_firmware(harness, image_settings):
    """T0 125 C with a +0.01/C (zero at 25 C), a scale of 1e-20 (its reciprocal a float32, the scaled input not),
    a centre of 1e30, and the same file unspoiled (loaded)."""
    docs = [make_calibration()]
    docs.append({**make_calibration(), "thermal": {"reference_C": 125.0, "source": "recipe",
                                        "coefficient_per_C": {"Bx_uT": 0.01, "By_uT": 0.0, "Bz_uT": 0.0}}})
    for key, value in (("scale", 1e-20), ("center", 1e30)):
        doc = make_calibration()
        doc["scaling"]["Bz_uT"][key] = value
        docs.append(doc)
    lines = _run(harness, "".join(f"R {_record(d, image_settings).hex()}\n" for d in docs))
    assert lines == ["L 0"] + ["L -10"] * 3, lines


def test_a_temperature_outside_the_range_is_flagged_not_divided(harness, image_settings):
    """A valid record (denominator 0.5 at 125 C) and a temperature word no chip sends (225 C: the denominator 0):
    the field is left uncorrected and the sample flagged outside, the forces finite."""
    doc = {**make_calibration(), "thermal": {"reference_C": 25.0, "source": "recipe",
                                  "coefficient_per_C": {"Bx_uT": -0.005, "By_uT": -0.005, "Bz_uT": -0.005}}}
    record = _record(doc, image_settings)
    lines = _run(harness, f"R {record.hex()}\nE 600 800 -3000 225\nE 600 800 -3000 nan\nE 600 800 -3000 25\n")
    assert lines[0] == "L 0"
    hot, none, t0 = (x.split() for x in lines[1:])
    assert all(math.isfinite(float(v)) for v in hot[1:4]) and int(hot[4]) & 1
    assert hot[1:4] == none[1:4] == t0[1:4] and int(none[4]) == int(t0[4]) == 0


@settings(max_examples=120, **SETTINGS)
@given(doc=calibration(max_order=8, mls=False))
def test_firmware_and_validator_agree_on_generated_records(harness, image_settings, doc):
    record = _record(doc, image_settings)
    if record is None:
        event("no record (eeprom refuses)")
        return
    assume(not _near_edge(doc))
    try:
        calibration_json.validate(copy.deepcopy(doc))
        accepted = True
    except CalibrationError:
        accepted = False
    samples = _samples(doc) if accepted else []
    script = f"R {record.hex()}\n" + "".join("E {:.9g} {:.9g} {:.9g} {}\n".format(*s) for s in samples)
    lines = _run(harness, script)
    assert lines[0] == ("L 0" if accepted else "L -10"), (lines[0], accepted)
    event("accepted by both" if accepted else "refused by both")
    for line, s in zip(lines[1:], samples):
        f = [float(v) for v in line.split()[1:4]]
        assert all(math.isfinite(v) for v in f), (s, line)


def _corrected(doc: dict, bx: float, by: float, bz: float, t: float) -> tuple:
    """The reading as at the calibration's temperature (docs/bundle.md section 2), in float64."""
    if not math.isnan(t) and "thermal" in doc:
        th = doc["thermal"]
        return tuple(b / (1.0 + th["coefficient_per_C"][axis] * (t - th["reference_C"]))
                     for b, axis in zip((bx, by, bz), AXES))
    return bx, by, bz


def _float64_forces(doc: dict, bx: float, by: float, bz: float, t: float) -> tuple:
    """docs/bundle.md section 2 in float64, the temperature correction first (tests/readout_support.ref_forces)."""
    return ref_forces(doc, *_corrected(doc, bx, by, bz, t))


@settings(max_examples=80, **SETTINGS)
@given(doc=calibration(max_order=8, mls=False))
def test_the_float32_forces_are_within_the_stated_bound_of_float64(harness, image_settings, doc):
    """mf_calib.c's forces (float32, compiled for the host) against float64 ones of the same document, at the
    region's vertices, corners and an interior grid and over the chip's temperature range, on generated records:
    every difference within float32_bound.float32_error_N (what the firmware README states for a build), save
    readings within direction_band of direction_min_uT."""
    record = _record(doc, image_settings)
    if record is None:
        return
    assume(not _near_edge(doc))
    try:
        checked = calibration_json.validate(copy.deepcopy(doc))
    except CalibrationError:
        return
    bound_z, bound_xy = float32_bound.float32_error_N(checked)
    band = float32_bound.direction_band(checked)
    # the direction's threshold is met by the corrected reading (the firmware corrects for temperature first)
    samples = [s for s in _samples(doc) if not band[0] <= math.hypot(*_corrected(doc, *s)[:2]) <= band[1]]
    script = f"R {record.hex()}\n" + "".join("E {:.9g} {:.9g} {:.9g} {}\n".format(*s) for s in samples)
    lines = _run(harness, script)
    assert lines[0] == "L 0"
    worst = 0.0
    for line, s in zip(lines[1:], samples):
        got = [float(v) for v in line.split()[1:4]]
        truth = _float64_forces(doc, *(float(f"{x:.9g}") for x in s))
        for axis, (g, w) in enumerate(zip(got, truth)):
            bound = bound_z if axis == 2 else bound_xy
            assert abs(g - w) <= bound, (axis, g, w, bound, s)
            worst = max(worst, abs(g - w) / bound if bound > 0 else 0.0)
    event(f"worst difference {worst:.0e} of the bound")
