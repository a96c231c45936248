"""Design derivation: the stack-up reproduces d_max, closed forms hold, and impossible specs say why."""

from __future__ import annotations

import math

import pytest

from magfab import SpecError, derive, load_spec, parse_spec


def test_magone_stack_up():
    d = derive(load_spec(None))
    # Board frame: chip 0.9 mm tall (nominal), Hall point 0.5 mm below its top; pad 2.0 mm + 0.1 mm glue.
    assert d.z_sense_mm == pytest.approx(0.4)
    assert d.z_elastomer_base_mm == pytest.approx(2.1)
    assert d.d_rest_mm == pytest.approx(6.0)
    assert d.z_magnet_low_mm - d.z_sense_mm == pytest.approx(6.0)
    assert d.cover_mm == pytest.approx(7.9 - (6.0 - (2.1 - 2.0 - 0.4)))  # roof = d_max - (base - H_m - z_sense)
    assert d.d_rest_range_mm[0] < 6.0 < d.d_rest_range_mm[1]


@pytest.mark.parametrize("d_max", [3.0, 4.5, 6.0, 6.5])
def test_rest_distance_always_equals_d_max(d_max):
    d = derive(parse_spec(f"[sensor]\nd_max_mm = {d_max}"))
    assert d.z_magnet_low_mm - d.z_sense_mm == pytest.approx(d_max, abs=1e-12)


def test_explicit_cover_must_reproduce_d_max():
    assert derive(parse_spec("[elastomer]\ncover_mm = 1.6")).d_rest_mm == pytest.approx(6.0)
    with pytest.raises(SpecError) as info:
        derive(parse_spec("[elastomer]\ncover_mm = 1.2"))
    assert info.value.key == "elastomer.cover_mm" and "set it to 1.6" in str(info.value)


def test_hemisphere_volume_is_closed_form():
    d = derive(load_spec(None))
    R, H = 6.0, 7.9
    assert d.envelope_volume_mm3 == pytest.approx(math.pi * R * R * (H - R) + 2 / 3 * math.pi * R**3)
    pocket = math.pi * 2.55**2 * 2.05
    funnel = math.pi * 1.55 / 3 * (1.0 + 1.0 * 2.55 + 2.55**2)
    channel = math.pi * 1.0**2 * (6.3 - 2.05 - 1.55)
    assert d.core_volume_mm3 == pytest.approx(pocket + funnel + channel)


def test_flat_tip_and_clipped_funnel():
    d = derive(parse_spec('[elastomer]\ntip = "flat"\nheight_mm = 5.0\n[sensor]\nd_max_mm = 3.2'))
    assert d.base_height_mm == 5.0
    assert d.pocket_floor_z_mm < d.pocket_radius_mm - d.channel_radius_mm  # funnel would go below the base
    assert d.funnel_bottom_z_mm == 0.0 and d.core_base_radius_mm > d.channel_radius_mm
    assert d.core_volume_mm3 > 0 and d.elastomer_volume_mm3 > 0


@pytest.mark.parametrize(
    "text, key",
    [
        ("[magnet]\ndiameter_mm = 12.0", "magnet.diameter_mm"),  # wider than the elastomer
        ("[sensor]\nd_max_mm = 9.0", "sensor.d_max_mm"),  # pocket would break through the tip
        ("[sensor]\nd_max_mm = 1.0", "sensor.d_max_mm"),  # smaller than the stack under the elastomer
        ("[elastomer]\nheight_mm = 4.0", "elastomer.height_mm"),  # hemisphere taller than the part
        ("[elastomer]\ninsert_channel_diameter_mm = 6.0", "elastomer.insert_channel_diameter_mm"),
        ("[pad]\nthickness_mm = 1.0", "pad.thickness_mm"),  # recess deeper than the pad
        ("[pad]\ndiameter_mm = 13.0", "pad.diameter_mm"),  # elastomer and lip do not fit
        ("[pad]\nalignment_hole_spacing_mm = 19.0", "pad.alignment_hole_spacing_mm"),
        ("[sensor]\nd_min_mm = 6.5", "sensor.d_min_mm"),
        ("[sensor]\nsensing_depth_mm = 2.0", "sensor.sensing_depth_mm"),
    ],
)
def test_impossible_geometry_names_the_key(text, key):
    with pytest.raises(SpecError) as info:
        derive(parse_spec(text))
    assert info.value.key == key, str(info.value)
    assert str(info.value).startswith(key)
