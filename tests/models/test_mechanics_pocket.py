"""The magnet's pocket in the FE: the bonded default unchanged, a sliding magnet and the open
insertion channel measured against it (bench/pocket.py prints the full comparison)."""

from __future__ import annotations

import numpy as np
import pytest

import magfab.models.mechanics as mech
from magfab.models.mechanics.mesh import _VOID, _body_mesh, check_void

D = np.array([0.0, 0.25, 0.5, 0.75, 1.0])

# MagOne, mu 23 kPa, mesh 1.0 mm, bonded: the FE before the interface option existed (same load steps), N and mm.
BEFORE_F = [0.0, 0.07651440481699538, 0.2514209685268123, 0.4850231162779266, 0.7606732254392022]
BEFORE_TRAVEL = [0.0, 0.059341392171563596, 0.19101210109325184, 0.3581772963496105, 0.5434559321394902]


@pytest.fixture(scope="module")
def magone(magone_design):
    return mech.Body.from_design(magone_design)


@pytest.fixture(scope="module")
def bonded(magone):
    return mech.fe(magone, 23.0, D, mesh_mm=1.0)


def test_default_curve_is_unchanged(magone, bonded):
    np.testing.assert_allclose(bonded.force_N, BEFORE_F, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(bonded.magnet_displacement_mm, BEFORE_TRAVEL, rtol=1e-9, atol=1e-12)
    assert "interface" not in bonded.info  # the default path records nothing new
    explicit = mech.fe(magone, 23.0, D, mesh_mm=1.0, interface=mech.MagnetInterface.BONDED, void=None)
    assert np.array_equal(explicit.force_N, bonded.force_N)


def test_sliding_magnet_gives_less_force(magone, bonded):
    """Measured (bench/pocket.py, 0.75 and 1.0 mm meshes agree within 0.1 point): -16.0 % force at 1 mm, -21.4 % at
    0.5 mm, +12.8 % travel per N at 1 mm. Tolerance 1 point: well above the mesh's effect, well below the effect."""
    s = mech.fe(magone, 23.0, D, mesh_mm=1.0, interface="sliding")
    F, F0 = s.force_N[1:], bonded.force_N[1:]  # (at rest both are 0)
    dF = 100.0 * (F / F0 - 1.0)
    per = 100.0 * ((s.magnet_displacement_mm[1:] / F) / (bonded.magnet_displacement_mm[1:] / F0) - 1.0)
    assert dF[-1] == pytest.approx(-16.0, abs=1.0)
    assert dF[1] == pytest.approx(-21.4, abs=1.0)
    assert per[-1] == pytest.approx(12.8, abs=1.0)
    assert s.info["interface"] == "sliding" and 0.1 < s.info["max_slide_mm"][-1] < 0.5


def test_open_channel_removes_the_silicone_under_the_magnet(magone, magone_design, bonded):
    """The design's channel and funnel left open: -23.0 % force and +54 % travel per N at 0.5 mm (1.0, 0.75 and
    0.5 mm meshes within 0.3 point)."""
    wall = mech.channel_wall(magone, magone_design.core_profile)
    assert wall[0] == (magone_design.channel_radius_mm, 0.0)
    assert wall[-1][1] == pytest.approx(magone.magnet_z_mm)
    mesh = _body_mesh(magone, 1.0, 0, 0.0, check_void(magone, wall))
    c = mesh.p[:, mesh.t].mean(axis=1)
    assert not np.any((c[1] < magone.magnet_z_mm) & (c[0] < magone_design.channel_radius_mm))  # no silicone inside
    assert np.count_nonzero(mesh.tags & _VOID) > 10
    v = mech.fe(magone, 23.0, D[:3], mesh_mm=1.0, void=wall)
    b = bonded
    assert 100.0 * (v.force_N[2] / b.force_N[2] - 1.0) == pytest.approx(-23.0, abs=1.5)
    per = (v.magnet_displacement_mm[2] / v.force_N[2]) / (b.magnet_displacement_mm[2] / b.force_N[2])
    assert 100.0 * (per - 1.0) == pytest.approx(54.0, abs=3.0)


def test_pocket_options_are_checked(magone):
    with pytest.raises(mech.MechanicsError, match="interface"):
        mech.fe(magone, 23.0, [0.0, 0.1], mesh_mm=1.0, interface="glued")
    with pytest.raises(mech.MechanicsError, match="void"):
        mech.fe(magone, 23.0, [0.0, 0.1], mesh_mm=1.0, void=((1.0, 0.0), (1.0, 2.0)))  # stops below the magnet
    plate = mech.Body(radius_mm=3.0, height_mm=4.0, base_height_mm=4.0, tip="flat", magnet_radius_mm=3.0,
                      magnet_height_mm=1.0, magnet_z_mm=3.0)
    with pytest.raises(mech.MechanicsError, match="top plate"):
        mech.fe(plate, 23.0, [0.0, 0.1], mesh_mm=1.0, interface="sliding")
