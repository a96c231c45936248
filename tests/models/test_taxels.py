"""An array's taxels through each other's chips (magfab.models.taxels): the neighbours' field against magpylib's
own superposition, the first-order compensation of a pressed neighbour, and per-taxel calibration."""

from __future__ import annotations

from dataclasses import replace

import magpylib as magpy
import numpy as np
import pytest

from magfab.design import derive
from magfab.models import taxels
from magfab.models.calibration import fit
from magfab.spec import parse_spec

STRIP = '[array]\nrows = 1\ncols = 5\npitch_mm = 14.0\npolarity = "alternating"\n'


@pytest.fixture(scope="module")
def strip():
    design = derive(parse_spec(STRIP, "strip"))
    return design, taxels.array_field(design)


def _magpylib_fields(design, centres):
    """(chips, 3) uT: every magnet as a magpylib Cylinder in the board frame, summed by magpylib (a Collection)."""
    from magfab.recipes import catalogue

    br = catalogue("magnets")[design.spec.magnet.grade]["remanence_T"].nominal
    magnets = [magpy.magnet.Cylinder(polarization=(0, 0, t.polarity * br),
                                     dimension=(2 * design.magnet_radius_mm / 1000, design.magnet_height_mm / 1000),
                                     position=np.asarray(c) / 1000) for t, c in zip(design.taxels, centres)]
    chips = np.array([[t.x_mm, t.y_mm, design.z_sense_mm] for t in design.taxels]) / 1000
    return magpy.getB(magpy.Collection(*magnets), chips) * 1e6


def test_the_neighbours_field_is_magpylibs_superposition(strip):
    design, field = strip
    centres = taxels._magnet_centres(design)
    total = _magpylib_fields(design, centres)
    np.testing.assert_allclose(field.offset_uT + field.rest_uT, total, rtol=0, atol=1e-6 * np.abs(total).max())
    # the physics the compensation exists for: an end taxel sees a lateral field of ~10 G from its neighbours
    assert abs(field.offset_uT[0, 0]) > 500.0 and abs(field.offset_uT[2, 0]) < 1e-6 * abs(field.offset_uT[0, 0])


def test_a_pressed_neighbour_is_compensated(strip):
    """Taxel 1 pressed and sheared while 2 rests: the host's compensation (the array.json it ships) removes what
    taxel 2's chip sees of it; with ``dynamic`` false only the offsets go."""
    design, field = strip
    calibrated = taxels.ArrayCalibration(field, (), (), True)
    moved = taxels._magnet_centres(design).copy()
    for press in ((0.0, 0.0, -1.0), (0.15, 0.1, -1.0), (0.3, 0.0, -2.5)):
        moved[1] = taxels._magnet_centres(design)[1] + press
        B = _magpylib_fields(design, moved)
        raw_error = np.abs(B[2] - field.offset_uT[2] - field.rest_uT[2]).max()
        left = np.abs(np.array(calibrated.compensator(design).apply(B.tolist())[2]) - field.rest_uT[2]).max()
        assert raw_error > 50.0  # the neighbour moves taxel 2's field by more than a few counts
        assert left < raw_error / 10.0, press
    static = replace(calibrated, dynamic=False).compensator(design).apply(B.tolist())
    np.testing.assert_allclose(static, B - field.offset_uT)


def test_each_taxel_is_fitted_to_its_compensated_scan(strip):
    from magfab.models.predict import predict

    design, field = strip
    pred = predict(design)
    scans = [taxels.simulate_taxel_scan(design, pred, k, field) for k in (0, 1)]
    assert np.median(scans[0].B_uT[:, 2]) > 0 > np.median(scans[1].B_uT[:, 2])  # alternating polarity
    assert scans[0].sha256 != scans[1].sha256  # own noise seed per taxel
    plain = fit(scans[0], design, mls=False).calibration.errors["Fr_N"]["rms_holdout"]
    compensated = fit(taxels.compensated(scans[0], field, 0), design,
                      mls=False).calibration.errors["Fr_N"]["rms_holdout"]
    assert compensated < 0.6 * plain  # the neighbours' lateral field bends the axisymmetric fit until removed
    whole = taxels.calibrate_taxels(design, pred, tuple(scans) + tuple(
        taxels.simulate_taxel_scan(design, pred, k, field) for k in (2, 3, 4)))
    doc = whole.as_json(design)
    assert [t["calibration"] for t in doc["taxels"]] == [f"taxel_{k:02d}.json" for k in range(5)]
    assert [t["i2c_address"] for t in doc["taxels"]] == [0x0C, 0x0D, 0x0E, 0x0F, 0x10]
    assert all(f.meets_tolerance for f in whole.fits)


def test_one_taxel_is_calibrated_from_its_rows_of_a_recording(strip, tmp_path):
    """An array recording holds every taxel's rows (its taxel column): --taxel K fits K's rows, the build keeps that
    scan for the next calibration, and the other taxels keep theirs."""
    from magfab import pipeline
    from magfab.array_bench import check_taxel, taxel_scans
    from magfab.errors import ScanError, SpecError
    from magfab.formats.scan_csv import read_scan_csv, scan_csv
    from magfab.models.predict import predict

    design, field = strip
    pred = predict(design)
    measured = [taxels.simulate_taxel_scan(design, pred, k, field) for k in range(5)]
    lines = [scan_csv(s).splitlines() for s in measured]
    header = lines[0][0] + ",taxel"
    rows = [f"{line},{k}" for k, rows in enumerate(lines) for line in rows[1:] if not line.startswith("#")]
    path = tmp_path / "rec.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    scan = read_scan_csv(path, taxel=2)
    np.testing.assert_allclose(scan.B_uT, measured[2].B_uT, atol=1e-3)
    with pytest.raises(ScanError, match="no rows of taxel 7; the file holds taxel"):
        read_scan_csv(path, taxel=7)
    with pytest.raises(SpecError, match="give the taxel the scan pressed, 0 to 4"):
        check_taxel(design.spec, None)
    with pytest.raises(SpecError, match="is a single taxel"):
        check_taxel(parse_spec(""), 0)

    arrayed = pipeline._taxel_calibrations(design, pred, taxel_scans(None, design.spec, 2, scan), False)
    files = {a.path: a for a in arrayed.artifacts}
    # the simulated scan stays beside the measured one (it may be what was calibrated on)
    assert "calibration/scan_taxel_02.csv" in files and "calibration/scan_simulated_taxel_02.csv" in files
    assert "calibration/scan_simulated_taxel_01.csv" in files
    kept = tmp_path / "calibration"
    kept.mkdir()
    (kept / "scan_taxel_02.csv").write_bytes(files["calibration/scan_taxel_02.csv"].data)
    again = taxel_scans(tmp_path, design.spec, 3, read_scan_csv(path, taxel=3))
    assert sorted(again) == [2, 3] and again[2].rows == scan.rows
    assert any("taxel 2: measured scan" in f.message for f in arrayed.findings)
