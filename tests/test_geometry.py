"""Solids and meshes: exact volumes and boxes, watertight STLs, STEP round trips, and fits."""

from __future__ import annotations

import io
import math
from functools import partial

import numpy as np
import pytest

cq = pytest.importorskip("cadquery")
trimesh = pytest.importorskip("trimesh")

from magfab import derive, load_spec, parse_spec  # noqa: E402
from magfab.elastomer import elastomer_solid, envelope_solid  # noqa: E402
from magfab.jig import ANGLES_DEG, cap_solid, stand_solid  # noqa: E402
from magfab.mould import cup_solid, lid_solid  # noqa: E402
from magfab.pad import pad_solid  # noqa: E402

STANDS = {f"weigh_stand_{a:g}": partial(stand_solid, angle_deg=a) for a in ANGLES_DEG}
PRINTED = ("mould_cup", "mould_lid", "pad", "weigh_cap", *STANDS)
SOLIDS = {"elastomer": elastomer_solid, "mould_cup": cup_solid, "mould_lid": lid_solid, "pad": pad_solid,
          "weigh_cap": cap_solid, **STANDS}


def _mesh(result, stem):
    data = next(a.data for a in result.artifacts if a.path == f"{stem}.stl")
    return trimesh.load(io.BytesIO(data), file_type="stl")


@pytest.mark.parametrize("stem", ["elastomer", *PRINTED])
def test_every_stl_is_a_closed_oriented_solid(default_build, stem):
    mesh = _mesh(default_build, stem)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    tol = default_build.spec.mould.tessellation_tolerance_mm
    exact = SOLIDS[stem]
    volume = exact(default_build.design).val().Volume()
    assert abs(mesh.volume - volume) <= mesh.area * tol


def test_elastomer_solid_matches_closed_form():
    d = derive(load_spec(None))
    assert elastomer_solid(d).val().Volume() == pytest.approx(d.elastomer_volume_mm3, rel=1e-6)
    assert envelope_solid(d).val().Volume() == pytest.approx(d.envelope_volume_mm3, rel=1e-6)
    bb = elastomer_solid(d).val().BoundingBox()
    assert (bb.xlen, bb.ylen, bb.zmin, bb.zmax) == pytest.approx((12.0, 12.0, 0.0, 7.9), abs=1e-6)


def test_cup_and_lid_boxes_and_volumes():
    d = derive(parse_spec("[mould]\ncavities = 3"))
    cup = cup_solid(d).val()
    lx, ly, h = d.cup_size_mm
    pin_h = d.pin_height_mm
    pins = 2 * math.pi * (d.pin_diameter_mm / 2) ** 2 * pin_h
    assert cup.Volume() == pytest.approx(lx * ly * h - 3 * d.envelope_volume_mm3 + pins, rel=1e-6)
    lid = lid_solid(d).val()
    bb = lid.BoundingBox()
    assert (bb.xlen, bb.ylen, bb.zmin) == pytest.approx((d.lid_size_mm[0], d.lid_size_mm[1], 0.0), abs=1e-6)
    # Print pose: the cores stand up from the plate, as tall as the pocket's roof.
    assert bb.zmax == pytest.approx(d.lid_thickness_mm + d.pocket_roof_z_mm, abs=1e-6)


def test_step_files_reimport_with_the_same_volume(default_build, tmp_path):
    for stem in ("elastomer", *PRINTED):
        path = tmp_path / f"{stem}.step"
        path.write_bytes(next(a.data for a in default_build.artifacts if a.path == f"{stem}.step"))
        solid = cq.importers.importStep(str(path)).val()
        exact = SOLIDS[stem]
        assert solid.isValid()
        assert solid.Volume() == pytest.approx(exact(default_build.design).val().Volume(), rel=1e-9)


def _intersection_volume(a, b) -> float:
    common = a.intersect(b)
    return sum(s.Volume() for s in common.solids().vals()) if common.solids().size() else 0.0


def test_pocket_holds_the_magnet_at_the_rest_position():
    d = derive(load_spec(None))
    top = d.pocket_roof_z_mm
    magnet = (cq.Workplane("XY", origin=(0, 0, top - d.magnet_height_mm))
              .circle(d.magnet_radius_mm).extrude(d.magnet_height_mm))
    assert _intersection_volume(elastomer_solid(d), magnet) == pytest.approx(0.0, abs=1e-6)
    # ... and any larger magnet than the clearance allows would collide.
    fat = (cq.Workplane("XY", origin=(0, 0, top - d.magnet_height_mm))
           .circle(d.pocket_radius_mm + 0.02).extrude(d.magnet_height_mm))
    assert _intersection_volume(elastomer_solid(d), fat) > 0.0


def test_pad_recess_holds_the_chip_and_centres_the_elastomer():
    d = derive(load_spec(None))
    s, h = d.chip_body_max_mm, d.chip_height_max_mm
    chip = cq.Workplane("XY").rect(s, s).extrude(h)
    pad = pad_solid(d)
    assert _intersection_volume(pad, chip) == pytest.approx(0.0, abs=1e-6)
    # The elastomer, glued on the pad top, sits inside the lip without touching it.
    el = elastomer_solid(d).translate((0, 0, d.z_elastomer_base_mm))
    assert _intersection_volume(pad, el) == pytest.approx(0.0, abs=1e-6)
    assert d.lip_inner_radius_mm - d.elastomer_radius_mm == pytest.approx(d.spec.pad.lip_clearance_mm)


def test_assembled_mould_does_not_collide_and_leaves_the_cavity():
    d = derive(load_spec(None))
    h, t = d.cup_size_mm[2], d.lid_thickness_mm
    lid_assembled = lid_solid(d).translate((0, 0, -(h + t))).rotate((0, 0, 0), (1, 0, 0), 180)
    assert _intersection_volume(cup_solid(d), lid_assembled) == pytest.approx(0.0, abs=1e-6)
    # What cup and lid leave between them over each cavity is exactly one elastomer.
    part = elastomer_solid(d).rotate((0, 0, 0), (1, 0, 0), 180).translate((0, 0, h))
    assert _intersection_volume(cup_solid(d), part) == pytest.approx(0.0, abs=1e-6)
    assert _intersection_volume(lid_assembled, part) == pytest.approx(0.0, abs=1e-6)


def _top_flat_area(mesh) -> float:
    """Area of the upward facets at the mesh's highest point, mm^2: the tip's flat top (0 for a dome)."""
    top = mesh.bounds[1][2]
    up = (mesh.face_normals[:, 2] > 1 - 1e-9) & (np.abs(mesh.triangles_center[:, 2] - top) < 1e-6)
    return float(mesh.area_faces[up].sum())


def _solids_of(spec):
    """The parts as plan() makes them: its CAD branch (pipeline._solids: every solid, its STL and the mesh checks),
    without the physics branch, which these tests do not read."""
    from types import SimpleNamespace

    from magfab.check import preflight
    from magfab.pipeline import _solids

    design = preflight(derive(spec))
    solids = _solids(design, lambda _stage: None, {})
    return SimpleNamespace(spec=design.spec, design=design, artifacts=solids.artifacts)


def test_variants_make_closed_solids_of_their_own_shape(default_build):
    """plan() only promises no error-level finding; here the variants' meshes are closed, match their CAD
    solids, and carry the variant: a flat tip is flat on top (the default dome is not), two cavities make a
    cup with two cavities' volume taken out, a wider pad is as wide as asked."""
    flat = _solids_of(parse_spec('[elastomer]\ntip = "flat"'))
    wide = _solids_of(parse_spec("[mould]\ncavities = 2\nprinter = \"fdm\"\n[pad]\ndiameter_mm = 22.0\n"
                                 "alignment_hole_diameter_mm = 2.0\nalignment_hole_spacing_mm = 17.0"))
    solids = {"elastomer": elastomer_solid, "mould_cup": cup_solid, "mould_lid": lid_solid, "pad": pad_solid}
    for result in (flat, wide):
        tol = result.spec.mould.tessellation_tolerance_mm
        for stem, solid in solids.items():
            mesh = _mesh(result, stem)
            assert mesh.is_watertight and mesh.is_winding_consistent, stem
            assert abs(mesh.volume - solid(result.design).val().Volume()) <= mesh.area * tol, stem
    r = flat.design.elastomer_radius_mm
    assert _top_flat_area(_mesh(flat, "elastomer")) > 0.25 * math.pi * r * r
    assert _top_flat_area(_mesh(default_build, "elastomer")) < 0.01 * math.pi * r * r
    d = wide.design
    lx, ly, h = d.cup_size_mm
    pins = 2 * math.pi * (d.pin_diameter_mm / 2) ** 2 * d.pin_height_mm
    assert _mesh(wide, "mould_cup").volume == pytest.approx(lx * ly * h - 2 * d.envelope_volume_mm3 + pins, rel=1e-3)
    extent = _mesh(wide, "pad").extents
    assert min(extent[0], extent[1]) == pytest.approx(22.0, abs=wide.spec.mould.tessellation_tolerance_mm)


@pytest.mark.parametrize("tol", [0.05, 0.01, 0.002])
def test_tessellation_tolerance_is_absolute_mm(tol):
    from magfab.export.cad import tessellate

    d = derive(load_spec(None))
    mesh = tessellate(envelope_solid(d), tol, 10.0)
    centres = mesh.triangles_center
    cap = centres[:, 2] > d.base_height_mm + 1e-3
    deviation = d.elastomer_radius_mm - np.linalg.norm(centres[cap] - [0, 0, d.base_height_mm], axis=1)
    assert deviation.max() <= tol and deviation.min() >= -1e-9  # facets lie inside the sphere, within tol
    assert mesh.is_watertight
