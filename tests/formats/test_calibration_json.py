"""calibration.json and acceptance.json: one validator each, and every reader refuses a bad file through it
with the same key path (the calibration model, the firmware renderer, the readout package)."""

from __future__ import annotations

import copy
import json

import pytest

from magfab import derive, load_spec
from magfab.errors import CalibrationFormatError, InputError, SpecError
from magfab.export import firmware, readout
from magfab.formats import acceptance_json, calibration_json
from magfab.models import acceptance as acceptance_model
from magfab.models.calibration import Calibration


def good() -> dict:
    """An order-2 calibration over a square region (a hand-made, valid file)."""
    return {
        "format": "magfab-calibration/1", "method": "poly", "order": 2,
        "monomials": [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]],
        "scaling": {"Bz_uT": {"center": 20000.0, "scale": 8000.0}, "Br_uT": {"center": 3000.0, "scale": 3000.0}},
        "coefficients": {"Fz_N": [0.5, 1.0, 0.0, 0.1, 0.0, 0.02], "Fr_N": [0.2, 0.0, 0.6, 0.0, 0.05, 0.0]},
        "shear_sign": 1, "direction_min_uT": 30.0, "tare_N": {"Fz_N": 0.0, "Fr_N": 0.0},
        "valid_region": {"Bz_uT": [12000.0, 28000.0], "Br_uT": [0.0, 6000.0],
                         "hull": [[12000.0, 0.0], [28000.0, 0.0], [28000.0, 6000.0], [12000.0, 6000.0]]},
        "errors": {"folds": 5}, "scan": {"sha256": "0" * 64, "rows": 100, "source": "hand"},
        "chip": {"gain_sel": 0, "resolution": 2, "osr": 0, "dig_filt": 1, "lsb_xy_uT": 3.0, "lsb_z_uT": 4.8},
    }


def _set(doc: dict, path: str, value: object) -> None:
    *parents, last = path.split(".")
    for p in parents:
        doc = doc[p]
    if value is _DELETE:
        del doc[last]
    else:
        doc[last] = value


_DELETE = object()
SPOILED = [  # (path changed, new value, key path named, words of the reason)
    ("format", "magfab-calibration/2", "format", "knows only 'magfab-calibration/1'"),
    ("method", "spline", "method", "'poly' or 'mls'"),
    ("order", 13, "order", "from 0 to 12"),
    ("order", 3, "monomials", "documented order"),
    ("scaling.Bz_uT.scale", 0.0, "scaling.Bz_uT.scale", "greater than 0"),
    ("coefficients.Fz_N", [1.0, 2.0], "coefficients.Fz_N", "list of 6 numbers"),
    ("coefficients.Fr_N", [0.0, 0.0, float("nan"), 0.0, 0.0, 0.0], "coefficients.Fr_N[2]", "finite"),
    ("shear_sign", 0, "shear_sign", "+1 or -1"),
    ("direction_min_uT", -1.0, "direction_min_uT", "at least 0"),
    ("tare_N", _DELETE, "tare_N.Fz_N", "is missing"),
    ("valid_region.Bz_uT", [3.0, 1.0], "valid_region.Bz_uT", "lo <= hi"),
    ("valid_region.hull", [[12000.0, 6000.0], [28000.0, 6000.0], [28000.0, 0.0], [12000.0, 0.0]],
     "valid_region.hull", "clockwise"),
    ("valid_region.hull", [[12000.0, 0.0], [28000.0, 0.0], [20000.0, 3000.0], [28000.0, 6000.0], [12000.0, 6000.0]],
     "valid_region.hull", "convex"),
    ("method", "mls", "mls", "is missing"),
    ("chip", [], "chip", "an object"),
]


@pytest.mark.parametrize("path, value, key, reason", SPOILED, ids=[f"{s[2]}-{n}" for n, s in enumerate(SPOILED)])
def test_the_validator_names_the_key_path(path, value, key, reason):
    doc = good()
    _set(doc, path, value)
    with pytest.raises(calibration_json.CalibrationError) as info:
        calibration_json.validate(doc)
    err = info.value
    assert err.key == key and reason in err.allowed, str(err)
    assert isinstance(err, CalibrationFormatError) and isinstance(err, InputError)  # exit 2
    assert str(err).startswith(f"calibration.json: {key} = ") and "\n" not in str(err)


@pytest.fixture(scope="module")
def design():
    return derive(load_spec(None))


@pytest.mark.parametrize("path, value, key, reason", SPOILED[::2], ids=[s[2] for s in SPOILED[::2]])
def test_every_reader_refuses_through_the_same_validator(design, path, value, key, reason):
    doc = good()
    _set(doc, path, value)
    with pytest.raises(calibration_json.CalibrationError) as model:
        Calibration.from_json(doc)
    with pytest.raises(calibration_json.CalibrationError) as fw:
        firmware.render(design, copy.deepcopy(doc))
    with pytest.raises(SpecError) as host:  # the readout's renderer keys its SpecError by file and path
        readout.render(design, copy.deepcopy(doc))
    assert model.value.key == fw.value.key == key and host.value.key == f"calibration.json:{key}"


def test_a_closed_ring_and_collinear_hull_points_are_accepted():
    doc = good()
    hull = doc["valid_region"]["hull"]
    doc["valid_region"]["hull"] = [hull[0], [20000.0, 0.0], *hull[1:], hull[0]]
    checked = calibration_json.validate(doc)
    assert len(checked.hull) == 5 and checked.span == 16000.0
    assert checked.sha256 == calibration_json.calibration_sha256(doc)
    assert calibration_json.loads(json.dumps(doc)) == checked


def test_nan_outside_the_checked_keys_and_broken_json_are_refused():
    doc = good()
    doc["errors"]["rms"] = float("nan")
    with pytest.raises(calibration_json.CalibrationError, match="finite numbers"):
        calibration_json.validate(doc)
    with pytest.raises(calibration_json.CalibrationError, match="not valid JSON"):
        calibration_json.loads("{")


def test_a_valid_file_round_trips_through_the_model():
    doc = good()
    assert Calibration.from_json(doc).to_json() == {**doc, "errors": {"folds": 5}}


# ---- thermal: optional, checked when present -------------------------------------------------------------------


def thermal() -> dict:
    return {"reference_C": 25.0, "source": "recipe", "note": "recipe values",
            "coefficient_per_C": {"Bx_uT": -0.0012, "By_uT": -0.0012, "Bz_uT": -0.0015}}


THERMAL_SPOILED = [
    ("thermal", [], "thermal", "an object"),
    ("thermal.reference_C", 200.0, "thermal.reference_C", "-40 to 125"),
    ("thermal.coefficient_per_C.Bz_uT", -0.12, "thermal.coefficient_per_C.Bz_uT", "a fraction"),
    ("thermal.coefficient_per_C.By_uT", _DELETE, "thermal.coefficient_per_C.By_uT", "is missing"),
    ("thermal.source", "guess", "thermal.source", "'fit' or 'recipe'"),
]


@pytest.mark.parametrize("path, value, key, reason", THERMAL_SPOILED, ids=[s[2] for s in THERMAL_SPOILED])
def test_a_thermal_object_is_checked_by_key(design, path, value, key, reason):
    doc = {**good(), "thermal": thermal()}
    _set(doc, path, value)
    with pytest.raises(calibration_json.CalibrationError) as info:
        calibration_json.validate(doc)
    assert info.value.key == key and reason in info.value.allowed, str(info.value)
    with pytest.raises(calibration_json.CalibrationError) as fw:
        firmware.render(design, copy.deepcopy(doc))
    assert fw.value.key == key


def test_a_calibration_with_and_without_thermal_reads_and_packs():
    """Without ``thermal`` (every file before it): no correction, a version-2 record; with it the model, the
    validator and a version-4 record carry the same coefficients; a build that does not convert the temperature
    packs version 2."""
    plain = calibration_json.validate(good())
    assert plain.thermal is None and Calibration.from_json(good()).thermal is None
    doc = {**good(), "thermal": thermal()}
    checked = calibration_json.validate(doc)
    assert checked.thermal == calibration_json.Thermal(25.0, (-0.0012, -0.0012, -0.0015), "recipe")
    model = Calibration.from_json(doc)
    assert model.to_json()["thermal"]["coefficient_per_C"] == doc["thermal"]["coefficient_per_C"]
    design = derive(load_spec(None))
    assert firmware.eeprom_record(design, good())[2] == 2
    record = firmware.eeprom_record(design, doc)
    ee = firmware._eeprom_module()
    assert record[2] == 4 and ee.check(record) and \
        ee.thermal(record) == pytest.approx((25.0, -0.0012, -0.0012, -0.0015))
    assert len(record) == len(firmware.eeprom_record(design, good())) + 16
    cold = derive(load_spec(None).model_copy(update={"firmware": load_spec(None).firmware.model_copy(
        update={"temperature": False})}))
    assert firmware.eeprom_record(cold, doc)[2] == 2


# ---- acceptance.json ---------------------------------------------------------------------------------------


def acceptance() -> dict:
    return {
        "format": acceptance_json.FORMAT,
        "rest": {"Bz_uT": {"min": 18000.0, "nominal": 20000.0, "max": 22000.0}, "Bxy_max_uT": 900.0,
                 "earth_field_uT": 65.0},
        "weight": {"weight_g": 20.0, "max_weight_g": 100.0,
                   "table": {"force_N": [0.0, 0.5, 1.0], "delta_Bz_min_uT": [0.0, 400.0, 800.0],
                             "delta_Bz_nominal_uT": [0.0, 500.0, 1000.0], "delta_Bz_max_uT": [0.0, 600.0, 1200.0]}},
        "measurement": {"noise_z_uT": 5.0, "noise_xy_uT": 3.0, "allowance_sigmas": 4.0},
        "magnet": {"grade": "N42", "remanence_T": {"low": 1.28, "nominal": 1.3, "high": 1.32}},
    }


def test_acceptance_format_is_the_models():
    assert acceptance_json.FORMAT == acceptance_model.FORMAT


@pytest.mark.parametrize("path, value, key", [
    ("format", "magfab-acceptance/0", "format"),
    ("rest.Bxy_max_uT", "wide", "rest.Bxy_max_uT"),
    ("weight.table.force_N", [1.0, 0.5, 0.0], "weight.table.force_N"),
    ("weight.table.delta_Bz_max_uT", [0.0], "weight.table"),
    ("rest.Bz_uT.min", 30000.0, "rest.Bz_uT"),
    ("magnet.grade", 42, "magnet.grade"),
    ("measurement", _DELETE, "measurement.noise_z_uT"),
])
def test_acceptance_validator_names_the_key_path(path, value, key):
    doc = acceptance()
    assert acceptance_json.validate(doc) is doc
    _set(doc, path, value)
    with pytest.raises(acceptance_json.AcceptanceError) as info:
        acceptance_json.loads(json.dumps(doc).encode())
    assert info.value.key == key and isinstance(info.value, CalibrationFormatError)
    assert str(info.value).startswith(f"acceptance.json: {key} = ")
