"""The closed mould measured on its meshes (magfab/fit.py): exact on the shipped parts, and each check shown
to see a planted fault (a shifted part, a shrunk part, a lid pressed into the cup)."""

from __future__ import annotations

import numpy as np
import pytest

from magfab import derive, load_spec, parse_spec
from magfab.check import mould_fit_findings
from magfab.fit import mould_fit


def _meshes(design):
    from magfab.export.cad import tessellate
    from magfab.pipeline import PARTS

    tol, ang = design.spec.mould.tessellation_tolerance_mm, design.spec.mould.angular_tolerance_deg
    return {part.stem: tessellate(part.make(design), tol, ang) for part in PARTS if part.stem != "pad"}


@pytest.fixture(scope="module")
def magone():
    design = derive(load_spec(None))
    return design, _meshes(design)


@pytest.fixture(scope="module")
def three_cavities():
    design = derive(parse_spec('name = "three"\n[mould]\ncavities = 3\nwall_mm = 1.2\n'))
    return design, _meshes(design)


def _codes(design, fit):
    return {f.code for f in mould_fit_findings(design, fit) if f.severity.value == "error"}


def test_magone_mould_closes_on_a_cavity_equal_to_the_part(magone):
    design, meshes = magone
    fit = mould_fit(design, meshes, design.spec.mould.tessellation_tolerance_mm)
    assert fit.cup_lid_interference_mm3 < 1e-6
    # The cavity equals the cast part far inside the tessellation bound, and both agree with the closed form
    # within what the tessellation removes from a curved surface.
    assert fit.part_outside_mm3[0] < 1e-3 and fit.cavity_outside_mm3[0] < 1e-3
    assert fit.cavity_volume_mm3[0] == pytest.approx(fit.part_volume_mm3, abs=1e-3)
    assert abs(fit.part_volume_mm3 - design.elastomer_volume_mm3) < fit.allowed_mm3 / 2
    assert fit.cup_wall_mm == pytest.approx(design.wall_mm, abs=1e-6)
    assert fit.cavity_web_mm is None
    assert _codes(design, fit) == set()


def test_webs_between_cavities_are_measured(three_cavities):
    design, meshes = three_cavities
    fit = mould_fit(design, meshes, design.spec.mould.tessellation_tolerance_mm)
    assert len(fit.cavity_volume_mm3) == 3
    # The web between neighbouring hemispherical tips is narrowest at their equator: pitch - 2 R = wall.
    assert fit.cavity_web_mm == pytest.approx(design.wall_mm, abs=design.spec.mould.tessellation_tolerance_mm)
    assert max(fit.part_outside_mm3) < 1e-3 and max(fit.cavity_outside_mm3) < 1e-3


def _moved(mesh, dx=0.0, dz=0.0, scale=1.0):
    out = mesh.copy()
    out.vertices = np.asarray(out.vertices) * scale + np.array([dx, 0.0, dz])
    return out


@pytest.mark.parametrize("fault, code", [
    (lambda m: {**m, "elastomer": _moved(m["elastomer"], dx=0.5)}, "mould-part-overlap"),
    (lambda m: {**m, "elastomer": _moved(m["elastomer"], scale=0.97)}, "mould-cavity"),
    # The lid is in print pose (turned over): +z there presses it into the cup once closed.
    (lambda m: {**m, "mould_lid": _moved(m["mould_lid"], dz=0.5)}, "mould-interference"),
])
def test_planted_faults_are_errors(magone, fault, code):
    design, meshes = magone
    fit = mould_fit(design, fault(meshes), design.spec.mould.tessellation_tolerance_mm)
    assert code in _codes(design, fit)


def test_thin_wall_on_the_mesh_is_an_error(magone):
    """A cup whose cavity was cut 1.5 mm off centre has a 0.5 mm wall: the mesh check sees it."""
    design, meshes = magone
    cup = _moved(meshes["mould_cup"])
    tol = design.spec.mould.tessellation_tolerance_mm
    y = np.asarray(cup.vertices)[:, 1]
    inner = np.abs(y) < design.elastomer_radius_mm + 0.2  # the cavity's surface, not the outer faces
    cup.vertices[inner, 1] += 1.5
    fit = mould_fit(design, {**meshes, "mould_cup": cup}, tol)
    assert fit.cup_wall_mm == pytest.approx(design.wall_mm - 1.5, abs=0.05)
    assert "mould-wall-mesh" in _codes(design, fit)
