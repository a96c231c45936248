"""An array's printed and cast parts, measured on the STL files a user gets: a pocket that takes the magnet under
every taxel of a continuous skin and silicone between them, a chip recess under every taxel of the one pad, the
mould closing on one skin or on a tip per taxel, and the printed parts slicing in PrusaSlicer."""

from __future__ import annotations

import math

import manifold3d
import pytest
import trimesh
from conftest import require_tool
from test_slicer import _slice

from magfab import outline
from magfab.fit import to_manifold


def _solid(build, stem):
    mesh = trimesh.load(build.out_dir / f"{stem}.stl")
    assert mesh.is_watertight and mesh.is_winding_consistent
    return to_manifold(mesh)


def _overlap(solid, body) -> float:
    return (solid ^ body).volume()


def _cylinder(x, y, z0, r, h):
    return manifold3d.Manifold.cylinder(h, r, r, 96).translate((x, y, z0))


def test_the_skin_takes_a_magnet_under_every_taxel_and_holds_silicone_between(array_builds):
    b = array_builds["fingertip_2x2"]
    d, skin = b.design, _solid(b, "elastomer")
    assert len(d.part_centres_mm) == 4 and d.cavities == 1
    r, h = d.magnet_radius_mm, d.magnet_height_mm
    for x, y in d.part_centres_mm:
        assert _overlap(skin, _cylinder(x, y, d.pocket_floor_z_mm + 0.01, r, h)) < 1e-3  # the magnet goes in
        # above the pocket's roof: the cover (silicone all round the axis)
        cover = _cylinder(x, y, d.pocket_roof_z_mm + 0.05, 0.5, d.cover_mm - 0.1)
        assert _overlap(skin, cover) == pytest.approx(cover.volume(), rel=1e-3)
    # between two neighbours' pockets, at their floors: silicone, not a merged hole (the valley between the domes
    # dips below the pockets' roofs: the union of the tips keeps each tip's own skin round its pocket)
    (x0, y0), (x1, y1) = d.part_centres_mm[:2]
    web = _cylinder((x0 + x1) / 2, (y0 + y1) / 2, d.pocket_floor_z_mm, 0.3, 0.5)
    assert _overlap(skin, web) == pytest.approx(web.volume(), rel=1e-3)
    # one part: its volume is the design's closed form (slab, dome union, four cores) within the tessellation
    assert skin.volume() == pytest.approx(d.elastomer_volume_mm3, rel=0.01)
    assert manifold3d.Manifold.decompose(skin).__len__() == 1


@pytest.mark.parametrize("example", ["fingertip_2x2", "strip_1x5"])
def test_one_pad_has_a_chip_recess_under_every_taxel_and_its_holes_inside(array_builds, example):
    b = array_builds[example]
    d, pad = b.design, _solid(b, "pad")
    side, depth = d.chip_body_max_mm, d.chip_height_max_mm
    chip = manifold3d.Manifold.cube((side, side, depth - 0.02), True)
    for t in d.taxels:
        assert _overlap(pad, chip.translate((t.x_mm, t.y_mm, depth / 2))) < 1e-3  # the package fits
        # over the chip, the pad's roof
        roof = _cylinder(t.x_mm, t.y_mm, d.recess_depth_mm + 0.02, 1.0, d.pad_roof_mm - 0.04)
        assert _overlap(pad, roof) == pytest.approx(roof.volume(), rel=1e-3)
    assert len(manifold3d.Manifold.decompose(pad)) == 1
    # the outline is the taxels' hull grown by the pad radius: its area at the glue face
    hull = list(d.array.hull_mm)
    lo = pad.trim_by_plane((0, 0, -1), -d.pad_thickness_mm / 2)  # the lower half
    area = lo.volume() / (d.pad_thickness_mm / 2)
    holes = sum(math.pi * dia * dia / 4 for _, _, dia in d.alignment_holes) + len(d.taxels) * d.recess_side_mm ** 2
    assert area == pytest.approx(outline.area(hull, d.pad_radius_mm) - holes, rel=0.01)


def test_the_mould_closes_on_one_skin_or_a_tip_per_taxel(array_builds):
    for name, cavities in (("fingertip_2x2", 1), ("strip_1x5", 5)):
        fit = [f for f in array_builds[name].findings if f.code == "mould-fit"]
        word = "cavity" if cavities == 1 else "cavities"
        assert len(fit) == 1 and f"{cavities} {word} equal to the cast part" in fit[0].message
        assert not [f for f in array_builds[name].findings if f.severity.value == "error"]
    # a separate tip is the single fingertip: the strip casts five of it per pour
    strip = array_builds["strip_1x5"]
    assert strip.design.cavities == 5 and strip.design.parts_per_sensor == 5


@pytest.mark.parametrize("example", ["fingertip_2x2", "strip_1x5"])
def test_array_mould_and_pad_slice(array_builds, example, tmp_path):
    slicer = require_tool("prusa-slicer")
    stems = ("mould_cup", "mould_lid", "pad") if example == "fingertip_2x2" else ("pad",)
    for stem in stems:
        _slice(slicer, array_builds[example].out_dir / f"{stem}.stl", "sla", tmp_path)
