"""Design's fields in the groups :func:`magfab.design.derive` computes them, one TypedDict per step.

Each step returns its group; ``derive`` unpacks every group into :class:`~magfab.design.Design`, so a type checker
holds each name and type against Design's own fields (a misspelt or mistyped field fails there, not at run time).
Plain dicts at run time. Units as in Design: mm, board frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypedDict

if TYPE_CHECKING:
    from .spec import Tip

__all__ = ["Part", "Stack", "Pocket", "Pad", "Address", "Mould"]


class Part(TypedDict):
    """The magnet, the elastomer's envelope and the pocket's size."""

    magnet_radius_mm: float
    magnet_height_mm: float
    elastomer_radius_mm: float
    elastomer_height_mm: float
    base_height_mm: float
    tip: Tip
    pocket_radius_mm: float
    pocket_height_mm: float
    channel_radius_mm: float


class Stack(TypedDict):
    """Heights from the chip's sensing point up to the elastomer's base, and the pad's chip recess."""

    chip_body_max_mm: float
    chip_height_nominal_mm: float
    chip_height_max_mm: float
    sensing_depth_mm: float
    z_sense_mm: float
    z_pad_top_mm: float
    z_elastomer_base_mm: float
    recess_side_mm: float
    recess_depth_mm: float
    pad_roof_mm: float
    pad_thickness_mm: float


class Pocket(TypedDict):
    """Where the pocket sits, and the distances that follow from it."""

    pocket_roof_z_mm: float
    pocket_floor_z_mm: float
    funnel_bottom_z_mm: float
    core_base_radius_mm: float
    cover_mm: float
    skin_mm: float
    z_magnet_low_mm: float
    z_magnet_top_mm: float
    d_rest_mm: float
    d_rest_range_mm: tuple[float, float]


class Pad(TypedDict):
    """The pad's disc, centring lip and alignment holes ((x, y, diameter) each)."""

    pad_radius_mm: float
    lip_inner_radius_mm: float
    lip_outer_radius_mm: float
    lip_height_mm: float
    alignment_holes: tuple[tuple[float, float, float], ...]


class Address(TypedDict):
    """The chip's 7-bit I2C address and the (A1, A0) straps that set it."""

    i2c_address: int
    address_straps: tuple[int, int]


class Mould(TypedDict):
    """The cup, its cavities and pins, and the lid with its fill and vent holes."""

    cavity_centres_x_mm: tuple[float, ...]
    cavity_pitch_mm: float
    wall_mm: float
    cup_size_mm: tuple[float, float, float]
    lid_thickness_mm: float
    lid_size_mm: tuple[float, float, float]
    pin_diameter_mm: float
    pin_hole_diameter_mm: float
    pin_positions_x_mm: tuple[float, float]
    pin_height_mm: float
    core_root_mm: float
    sprue_diameter_mm: float
    sprue_offset_mm: float
    vent_diameter_mm: float
    vent_offset_mm: float
    vent_angles_deg: tuple[float, ...]
