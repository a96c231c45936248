"""check.prediction_findings reads the normal range's limit labels (predict.py): the note names what ended the range
and the spec key that moves it."""

from __future__ import annotations

from dataclasses import replace

import pytest

from magfab.check import prediction_findings


@pytest.mark.parametrize("label, key", [("stretch", "predict.max_stretch"), ("scan depth", "calibration.scan_z_mm"),
                                        ("material data", ""),
                                        ("model", ""), ("chip full scale", "")])
def test_the_range_limit_note_names_its_key(magone_design, magone_prediction, label, key):
    """On the default law (Yeoh) the material data's end is the furthest law the recipes hold: no key to move it
    (the neo-Hookean case, which points to predict.material_law, is the test below)."""
    pred = magone_prediction
    normal = replace(pred.normal, range_limit=label)
    found = [f for f in prediction_findings(magone_design, replace(pred, normal=normal)) if f.code == "range-limit"]
    assert len(found) == 1 and found[0].key == key
    assert f"({label})" in found[0].message and "before the magnet reaches d_min" in found[0].message


def test_no_note_when_d_min_ends_the_range(magone_design, magone_prediction):
    pred = magone_prediction
    normal = replace(pred.normal, range_limit="d_min")
    assert not [f for f in prediction_findings(magone_design, replace(pred, normal=normal)) if f.code == "range-limit"]


@pytest.mark.parametrize("fitted", [True, False])
def test_a_model_reach_says_at_least_and_points_to_a_law_only_where_one_reaches(magone_neo_hookean, fitted):
    """MagOne's neo-Hookean range ends at the material data: the note calls it a model's reach, and names
    predict.material_law only where the silicone has a Yeoh law (sylgard-184 has none)."""
    from magfab.check.predict import _range_limit

    normal = magone_neo_hookean[1].normal
    assert normal.range_limit == "material data"
    note = _range_limit(normal, fitted)
    assert "a model's reach" in note.message and "at least" in note.message
    assert ("'yeoh'" in note.message) == fitted and note.key == ("predict.material_law" if fitted else "")
