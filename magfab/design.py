"""Spec -> Design: every derived dimension and distance, in one place.

Coordinates, all in millimetres:

* **board**: z = 0 on the top face of the PCB, the chip's centre on the z axis. The stack-up
  (chip, sensing point, pad, glue, elastomer, magnet) is given in this frame.
* **elastomer**: z = 0 on the elastomer's flat base (the glued face), the axis on z. Profiles are
  (r, z) pairs in this frame; the elastomer's base sits at ``z_elastomer_base_mm`` in the board frame.

The magnet rests against the pocket's roof (it is pushed up the insertion channel until it stops),
so the rest distance is fixed by the roof: d = z_magnet_low - z_sense.

Geometric impossibilities raise :class:`SpecError` naming the key to change; rules that depend on the
printer or on robustness are left to :mod:`magfab.check` as findings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from . import outline
from .design_fields import Address, Mould, Pad, Part, Pocket, Stack
from .errors import SpecError, shown
from .errors import number_text as _fmt
from .plausible import plausible
from .recipes import Recipe, resolve
from .spec import Array, Polarity, Skin, Spec, Tip

__all__ = ["Design", "Taxel", "ArrayLayout", "derive", "DISTANCE_TOLERANCE_MM"]

#: How closely an explicit ``elastomer.cover_mm`` must reproduce ``sensor.d_max_mm``.
DISTANCE_TOLERANCE_MM = 1e-3

#: Fixed mould features (not spec keys; each is checked against the printer's minimums).
REGISTRATION_PIN_MM = 3.0  # diameter of the cup's registration pins
PRY_LIP_MM = 3.0  # lid overhang at each end of the cup, to lever the lid off
#: Separate tips: one cavity per taxel by default, up to this many (a row of five MagOne tips is an 82 mm cup and
#: within the triangle budget of magfab/limits.py; more taxels pour more than once).
ARRAY_CAVITIES_DEFAULT_MAX = 5
SPRUE_MAX_MM = 3.0  # fill/overflow hole per cavity
VENT_MIN_MM = 1.0  # vent hole per cavity at the rim, at least this or the printer's minimum hole
SECOND_HOLE_EXTRA_MM = 0.5  # the pad's second alignment hole is larger by this: one way round only


@dataclass(frozen=True)
class Taxel:
    """One magnet over one chip. Position in the board frame (the chip's centre, the magnet's axis), mm."""

    index: int  # the order the firmware reads the chips in, and the frames' taxel index
    x_mm: float
    y_mm: float
    polarity: int  # +1: magnetised along +z (north up, as the single taxel); -1: flipped
    i2c_address: int  # 7-bit
    option_code: str  # the chip to order: MLX90393SLW-ABA-<code>
    address_straps: tuple[int, int]  # (A1, A0): 0 = GND, 1 = supply

    def as_dict(self) -> dict[str, object]:
        return {"index": self.index, "x_mm": _rounded(self.x_mm), "y_mm": _rounded(self.y_mm),
                "polarity": self.polarity, "i2c_address": self.i2c_address, "option_code": self.option_code,
                "address_straps": list(self.address_straps)}


@dataclass(frozen=True)
class ArrayLayout:
    """Where an array's taxels stand and how they are addressed (board frame, mm)."""

    taxels: tuple[Taxel, ...]
    skin: Skin
    polarity: Polarity
    pitch_mm: float  # the smallest centre-to-centre distance
    min_pitch_mm: float  # the smallest the geometry allows (lips, pockets, recesses); the crosstalk budget may ask more
    hull_mm: tuple[tuple[float, float], ...]  # convex hull of the taxel centres, counter-clockwise (1 or 2 points too)
    # (x_min, y_min, x_max, y_max) of the pad: the hull grown by its radius
    pad_extent_mm: tuple[float, float, float, float]
    part_centres_mm: tuple[tuple[float, float], ...]  # the magnets in one cast part's frame: every taxel of a
    # continuous skin (its outline's extent centred on the origin), or one tip's axis for separate tips

    @property
    def option_codes(self) -> tuple[str, ...]:
        return tuple(sorted({t.option_code for t in self.taxels}))

    def as_dict(self) -> dict[str, object]:
        return {"taxels": [t.as_dict() for t in self.taxels], "skin": self.skin.value, "polarity": self.polarity.value,
                "pitch_mm": _rounded(self.pitch_mm), "min_pitch_mm": _rounded(self.min_pitch_mm),
                "hull_mm": _rounded(self.hull_mm), "pad_extent_mm": _rounded(self.pad_extent_mm),
                "part_centres_mm": _rounded(self.part_centres_mm)}


@dataclass(frozen=True)
class Design:
    """All derived geometry. Lengths in mm, volumes in mm^3, positions in the frame their name says."""

    spec: Spec
    printer: Recipe
    chip: Recipe
    magnet_grade: resolve.MagnetGrade  # spec.magnet.grade, resolved once (recipes/magnets.toml)
    material: resolve.Material  # spec.elastomer.material, resolved once (recipes/materials.toml)
    adhesive: Recipe  # spec.fabrication.adhesive (recipes/adhesives.toml)
    release_agent: Recipe  # spec.fabrication.release_agent (recipes/adhesives.toml)
    # magnet
    magnet_radius_mm: float
    magnet_height_mm: float
    # elastomer (elastomer frame)
    elastomer_radius_mm: float
    elastomer_height_mm: float
    base_height_mm: float  # height of the cylindrical part; equals the total height for a flat tip
    tip: Tip
    pocket_radius_mm: float
    pocket_height_mm: float
    pocket_roof_z_mm: float
    pocket_floor_z_mm: float
    channel_radius_mm: float
    funnel_bottom_z_mm: float  # where the 45-degree funnel from the channel meets the pocket's floor
    core_base_radius_mm: float  # radius of the channel (or clipped funnel) at the base, z = 0
    cover_mm: float
    skin_mm: float  # thinnest silicone between the pocket and the outer surface
    # stack-up (board frame)
    chip_body_max_mm: float
    chip_height_nominal_mm: float
    chip_height_max_mm: float
    sensing_depth_mm: float
    z_sense_mm: float
    z_pad_top_mm: float
    z_elastomer_base_mm: float
    z_magnet_low_mm: float
    z_magnet_top_mm: float
    d_rest_mm: float
    d_rest_range_mm: tuple[float, float]  # what d_max could be with this elastomer, pad and chip
    # pad (board frame)
    pad_radius_mm: float
    pad_thickness_mm: float
    recess_side_mm: float
    recess_depth_mm: float
    pad_roof_mm: float
    lip_inner_radius_mm: float
    lip_outer_radius_mm: float
    lip_height_mm: float
    alignment_holes: tuple[tuple[float, float, float], ...]  # (x, y, diameter)
    i2c_address: int  # 7-bit
    address_straps: tuple[int, int]  # (A1, A0) pin levels the board wires: 0 = GND, 1 = supply
    # mould (cup print frame: bottom on the bed at z = 0, cavities open upwards)
    cavity_centres_x_mm: tuple[float, ...]
    cavity_pitch_mm: float
    wall_mm: float
    cup_size_mm: tuple[float, float, float]
    lid_thickness_mm: float
    lid_size_mm: tuple[float, float, float]
    pin_diameter_mm: float
    pin_hole_diameter_mm: float
    pin_positions_x_mm: tuple[float, float]
    pin_height_mm: float  # how far the cup's pins stand into the lid's holes
    core_root_mm: float  # how far each core reaches into the lid plate, so the two fuse solidly
    sprue_diameter_mm: float
    sprue_offset_mm: float  # radial distance of the sprue from the cavity axis (+y in the assembled mould)
    vent_diameter_mm: float
    vent_offset_mm: float
    vent_angles_deg: tuple[float, ...]
    array: ArrayLayout | None = None  # None: one taxel at the origin
    # the [pcb] sides the spec left unstated and the board's fit chose, because the default did not hold the parts
    # (magfab.board.fit; the chosen values are in spec.pcb); () where the stated or default size holds them
    pcb_sized: tuple[str, ...] = ()

    @property
    def taxels(self) -> tuple[Taxel, ...]:
        """Every taxel (one at the origin for a single-taxel design)."""
        if self.array is not None:
            return self.array.taxels
        return (Taxel(0, 0.0, 0.0, 1, self.i2c_address, self.spec.sensor.option_code, self.address_straps),)

    @property
    def continuous(self) -> bool:
        """True for one cast skin holding every magnet."""
        return self.array is not None and self.array.skin is Skin.CONTINUOUS

    @property
    def part_centres_mm(self) -> tuple[tuple[float, float], ...]:
        """The magnets' axes in one cast part's frame (one at the origin unless the part is a continuous skin)."""
        return self.array.part_centres_mm if self.array is not None and self.continuous else ((0.0, 0.0),)

    @property
    def parts_per_sensor(self) -> int:
        """Cast parts one sensor needs: a tip per taxel of separate tips, else one (a tip, or the skin)."""
        return len(self.array.taxels) if self.array is not None and not self.continuous else 1

    @property
    def cavities(self) -> int:
        """Cast parts per mould: the spec's count, or for an array that does not set it the parts one array needs
        (a tip per taxel up to ARRAY_CAVITIES_DEFAULT_MAX, or one skin)."""
        return len(self.cavity_centres_x_mm)

    # ---- profiles (r, z) in the elastomer frame ----------------------------------------------

    @property
    def envelope_profile(self) -> list[tuple[float, float]]:
        """Outer outline from the axis at the base, round the tip, back to the axis (arc given by 3 points)."""
        R, hb, H = self.elastomer_radius_mm, self.base_height_mm, self.elastomer_height_mm
        if self.tip is Tip.FLAT:
            return [(0.0, 0.0), (R, 0.0), (R, H), (0.0, H)]
        return [(0.0, 0.0), (R, 0.0), (R, hb), (R * math.sqrt(0.5), hb + R * math.sqrt(0.5)), (0.0, H)]

    @property
    def core_profile(self) -> list[tuple[float, float]]:
        """The pocket, funnel and insertion channel: what the mould's core occupies (z from 0 to the roof)."""
        pts = [(0.0, 0.0), (self.core_base_radius_mm, 0.0)]
        if self.funnel_bottom_z_mm > 0.0:
            pts.append((self.channel_radius_mm, self.funnel_bottom_z_mm))
        if self.pocket_floor_z_mm > pts[-1][1]:
            pts.append((self.pocket_radius_mm, self.pocket_floor_z_mm))
        pts += [(self.pocket_radius_mm, self.pocket_roof_z_mm), (0.0, self.pocket_roof_z_mm)]
        return pts

    @property
    def lid_holes(self) -> list[tuple[float, float, float]]:
        """(x, y, diameter) of every through hole in the lid, assembled frame: pin holes, sprues, vents."""
        holes = [(x, 0.0, self.pin_hole_diameter_mm) for x in self.pin_positions_x_mm]
        gap = self.printer["min_wall_mm"].nominal
        for x, y in self.core_centres_mm:
            holes.append((x, y + self.sprue_offset_mm, self.sprue_diameter_mm))
            for a in self.vent_angles_deg:
                ang = math.radians(a)
                vent = (x + self.vent_offset_mm * math.cos(ang), y + self.vent_offset_mm * math.sin(ang),
                        self.vent_diameter_mm)
                # in a continuous skin two neighbours' vents may meet: one does for both (the skin's base, under
                # the lid, is the inverted cavity's top everywhere, so any vent on it lets the air out)
                if all(math.dist(vent[:2], h[:2]) >= (vent[2] + h[2]) / 2.0 + gap for h in holes):
                    holes.append(vent)
        return holes

    @property
    def core_centres_mm(self) -> list[tuple[float, float]]:
        """(x, y) of every core in the assembled mould (each cast part lies upside down: its y turned over)."""
        return [(x + px + 0.0, -py + 0.0) for x in self.cavity_centres_x_mm for px, py in self.part_centres_mm]

    # ---- closed-form volumes -----------------------------------------------------------------

    @cached_property
    def envelope_volume_mm3(self) -> float:
        R, hb = self.elastomer_radius_mm, self.base_height_mm
        if self.continuous:
            return _skin_volume(self.part_centres_mm, R, hb, self.tip is Tip.HEMISPHERE)
        v = math.pi * R * R * hb
        return v + (2.0 / 3.0) * math.pi * R**3 if self.tip is Tip.HEMISPHERE else v

    @cached_property
    def core_volume_mm3(self) -> float:
        """Volume of pocket + funnel + channel, by Pappus over the polygonal core profile."""
        return _revolved_polygon_volume(self.core_profile)

    @cached_property
    def elastomer_volume_mm3(self) -> float:
        """Silicone in one cast part: the mould cavity less the core (each core, for a continuous skin)."""
        return self.envelope_volume_mm3 - len(self.part_centres_mm) * self.core_volume_mm3

    @property
    def magnet_volume_mm3(self) -> float:
        return math.pi * self.magnet_radius_mm**2 * self.magnet_height_mm

    def as_dict(self) -> dict[str, object]:
        """Every derived number (for design.json), rounded to 1 nm so the text is stable."""
        out: dict[str, object] = {}
        for name in self.__dataclass_fields__:
            if name in {"spec", "printer", "chip", "magnet_grade", "material", "adhesive", "release_agent", "array",
                        "pcb_sized"}:
                continue
            out[name] = _rounded(getattr(self, name))
        out["tip"] = self.tip.value
        out["printer"] = self.printer.key
        out["chip"] = self.chip.key
        if self.array is not None:  # a single taxel's design.json is what it was before arrays
            out["array"] = self.array.as_dict()
        if self.pcb_sized:  # a board of the stated or default size leaves design.json as it was
            out["pcb_sized"] = {k: _rounded(getattr(self.spec.pcb, k)) for k in self.pcb_sized}
        for name in ("envelope_volume_mm3", "core_volume_mm3", "elastomer_volume_mm3", "magnet_volume_mm3"):
            out[name] = _rounded(getattr(self, name))
        return out


def _rounded(value: object) -> object:
    if isinstance(value, float):
        return round(value, 6) + 0.0
    if isinstance(value, (tuple, list)):
        return [_rounded(v) for v in value]
    return value


def _revolved_polygon_volume(profile: list[tuple[float, float]]) -> float:
    """Volume swept by a closed (r, z) polygon revolved about the z axis (Pappus, via the shoelace sum)."""
    v = 0.0
    n = len(profile)
    for i in range(n):
        r1, z1 = profile[i]
        r2, z2 = profile[(i + 1) % n]
        v += (r1 * z2 - r2 * z1) * (r1 + r2)
    return abs(v) * math.pi / 3.0


def _skin_volume(centres: tuple[tuple[float, float], ...], R: float, hb: float, domes: bool) -> float:
    """A continuous skin's envelope: its outline (the centres' hull grown by R) times the base height, and a
    hemispherical dome over each centre: closed form where the domes stay apart, else their union integrated on a
    0.02 mm grid (midpoint rule; its error is below 1e-4 of the volume)."""
    h = outline.hull(list(centres))
    v = outline.area(h, R) * hb
    if not domes:
        return v
    pitch = min((math.dist(a, b) for i, a in enumerate(centres) for b in centres[i + 1:]), default=math.inf)
    if pitch >= 2.0 * R:
        return v + len(centres) * (2.0 / 3.0) * math.pi * R**3

    step = 0.02
    xs, ys = [c[0] for c in centres], [c[1] for c in centres]
    gx = np.arange(min(xs) - R + step / 2, max(xs) + R, step)
    gy = np.arange(min(ys) - R + step / 2, max(ys) + R, step)
    X, Y = np.meshgrid(gx, gy)
    top = np.zeros_like(X)
    for cx, cy in centres:
        top = np.maximum(top, np.sqrt(np.clip(R * R - (X - cx) ** 2 - (Y - cy) ** 2, 0.0, None)))
    return v + float(top.sum()) * step * step


def derive(spec: Spec) -> Design:
    """Compute the whole design from a validated spec, or raise :class:`SpecError` if it cannot exist.

    In the order a person would design it: the magnet and its pocket in the elastomer, the stack from the
    chip's sensing point up, where the pocket sits so that the rest distance is d_max, the pad, the chip's
    address, the mould round the part. Geometry only: the reference chip's site, what the build would cost and the
    board's size (:func:`magfab.check.preflight`) are checked by the stage above, ``magfab check`` and the pipeline's
    plan, which go on with the design it returns."""
    plausible(spec)  # a unit's mistake is named at the key typed, before a derived key breaks on it
    chip = resolve.chip(spec.sensor.chip)
    printer = resolve.printer(spec.mould.printer.value)
    part = _elastomer(spec)
    stack = _stack(spec, chip)
    pocket = _pocket(spec, part, stack)
    pad = _pad(spec)
    array = None
    if spec.array is not None and spec.array.taxels > 1:
        array = _array(spec, spec.array, chip, printer, _min_pitch(spec, spec.array.skin, printer, part, stack, pad))
        pad["alignment_holes"] = _array_holes(spec, array)
    mould = _mould(spec, printer, part, pocket["core_base_radius_mm"], array)
    return Design(spec=spec, printer=printer, chip=chip, magnet_grade=resolve.magnet_grade(spec.magnet.grade),
                  material=resolve.material(spec.elastomer.material),
                  adhesive=resolve.adhesive(spec.fabrication.adhesive),
                  release_agent=resolve.adhesive(spec.fabrication.release_agent),
                  **part, **stack, **pocket, **pad, **_address(spec, chip), **mould, array=array)


def _elastomer(spec: Spec) -> Part:
    """The magnet, the elastomer's envelope and the pocket's size, checked against each other."""
    mag, el = spec.magnet, spec.elastomer
    R_m, H_m = mag.diameter_mm / 2.0, mag.height_mm
    R_e, H_e = el.diameter_mm / 2.0, el.height_mm
    c, skin_min = el.pocket_clearance_mm, el.min_skin_mm
    R_p, h_p = R_m + c, H_m + c
    r_ch = el.insert_channel_diameter_mm / 2.0
    if el.tip is Tip.HEMISPHERE and H_e < R_e:
        raise SpecError("elastomer.height_mm", shown(H_e),
                        f"must be at least the tip radius {_fmt(R_e)} mm for a hemisphere tip",
                        "or use tip = \"flat\"")
    if R_p + skin_min > R_e:
        limit = 2.0 * (R_e - skin_min - c)
        raise SpecError("magnet.diameter_mm", shown(mag.diameter_mm),
                        f"must be at most {_fmt(limit)} mm so the pocket keeps {_fmt(skin_min)} mm of silicone "
                        f"inside the {_fmt(el.diameter_mm)} mm elastomer")
    if r_ch > R_p:
        raise SpecError("elastomer.insert_channel_diameter_mm", shown(el.insert_channel_diameter_mm),
                        f"must be at most the pocket diameter {_fmt(2 * R_p)} mm")
    return Part(magnet_radius_mm=R_m, magnet_height_mm=H_m, elastomer_radius_mm=R_e, elastomer_height_mm=H_e,
                base_height_mm=H_e - R_e if el.tip is Tip.HEMISPHERE else H_e, tip=el.tip,
                pocket_radius_mm=R_p, pocket_height_mm=h_p, channel_radius_mm=r_ch)


def _stack(spec: Spec, chip) -> Stack:
    """Heights in the board frame (board top face at z = 0): the sensing point, the pad, the elastomer's base."""
    sen, pad = spec.sensor, spec.pad
    body_max, h_nom, h_max = chip["body_mm"].high, chip["height_mm"].nominal, chip["height_mm"].high
    depth = sen.sensing_depth_mm if sen.sensing_depth_mm is not None else chip["sensing_depth_mm"].nominal
    if depth > h_nom:
        raise SpecError("sensor.sensing_depth_mm", shown(depth), f"must be at most the package height {_fmt(h_nom)} mm")
    recess_depth = h_max + pad.recess_clearance_mm
    if recess_depth >= pad.thickness_mm:
        raise SpecError("pad.thickness_mm", shown(pad.thickness_mm),
                        f"must exceed the chip recess depth {_fmt(recess_depth)} mm (package height max "
                        f"{_fmt(h_max)} mm + recess clearance)")
    return Stack(chip_body_max_mm=body_max, chip_height_nominal_mm=h_nom, chip_height_max_mm=h_max,
                sensing_depth_mm=depth, z_sense_mm=h_nom - depth, z_pad_top_mm=pad.thickness_mm,
                z_elastomer_base_mm=pad.thickness_mm + pad.glue_thickness_mm,
                recess_side_mm=body_max + 2.0 * pad.recess_clearance_mm, recess_depth_mm=recess_depth,
                pad_roof_mm=pad.thickness_mm - recess_depth, pad_thickness_mm=pad.thickness_mm)


def _pocket(spec: Spec, part: Part, stack: Stack) -> Pocket:
    """Where the pocket's roof sits so that the magnet's lower face is d_max above the sensing point, within
    what the skin allows; the funnel and channel below it; d_min checked against the stack."""
    el, sen = spec.elastomer, spec.sensor
    R_e, H_e, base_h = part["elastomer_radius_mm"], part["elastomer_height_mm"], part["base_height_mm"]
    R_p, h_p, r_ch, H_m = (part["pocket_radius_mm"], part["pocket_height_mm"], part["channel_radius_mm"],
                           part["magnet_height_mm"])
    z_base, z_sense, skin_min = stack["z_elastomer_base_mm"], stack["z_sense_mm"], el.min_skin_mm
    roof_max = base_h + math.sqrt((R_e - skin_min) ** 2 - R_p**2) if el.tip is Tip.HEMISPHERE else H_e - skin_min
    roof_max = min(roof_max, H_e - skin_min)
    roof_min = skin_min + h_p

    def d_of_roof(roof: float) -> float:  # the magnet's top is at the roof
        return z_base + roof - H_m - z_sense

    d_lo, d_hi = d_of_roof(roof_min), d_of_roof(roof_max)
    if d_hi < d_lo:
        raise SpecError("elastomer.height_mm", shown(H_e), f"is too short to hold the {_fmt(H_m)} mm magnet with "
                        f"{_fmt(skin_min)} mm of silicone around its pocket")
    if el.cover_mm is not None:
        roof = H_e - el.cover_mm
        if abs(d_of_roof(roof) - sen.d_max_mm) > DISTANCE_TOLERANCE_MM:
            want = H_e - (sen.d_max_mm - d_of_roof(0.0))
            raise SpecError("elastomer.cover_mm", shown(el.cover_mm),
                            f"gives a rest distance of {_fmt(d_of_roof(roof))} mm, not sensor.d_max_mm = "
                            f"{_fmt(sen.d_max_mm)} mm", f"omit cover_mm to derive it, or set it to {_fmt(want)}")
    else:
        roof = sen.d_max_mm - d_of_roof(0.0)
    if not roof_min - 1e-9 <= roof <= roof_max + 1e-9:
        raise SpecError("sensor.d_max_mm", shown(sen.d_max_mm),
                        f"must be between {_fmt(d_lo)} and {_fmt(d_hi)} mm for this stack (pad top + glue at "
                        f"{_fmt(z_base - z_sense)} mm above the sensing point, a {_fmt(H_e)} mm elastomer, "
                        f"{_fmt(skin_min)} mm minimum skin)")
    if sen.d_min_mm >= sen.d_max_mm:
        raise SpecError("sensor.d_min_mm", shown(sen.d_min_mm),
                        f"must be less than sensor.d_max_mm = {_fmt(sen.d_max_mm)} mm")
    if sen.d_min_mm <= z_base - z_sense:
        raise SpecError("sensor.d_min_mm", shown(sen.d_min_mm),
                        f"must exceed {_fmt(z_base - z_sense)} mm: the elastomer's base (pad + glue) is that far "
                        "above the sensing point")
    floor = roof - h_p
    funnel_bottom = floor - (R_p - r_ch)
    if el.tip is Tip.HEMISPHERE:
        skin = min(R_e - R_p, R_e - math.hypot(R_p, max(0.0, roof - base_h)))
    else:
        skin = min(R_e - R_p, H_e - roof)
    return Pocket(pocket_roof_z_mm=roof, pocket_floor_z_mm=floor, funnel_bottom_z_mm=max(funnel_bottom, 0.0),
                core_base_radius_mm=r_ch if funnel_bottom >= 0.0 else R_p - floor, cover_mm=H_e - roof, skin_mm=skin,
                z_magnet_low_mm=z_base + roof - H_m, z_magnet_top_mm=z_base + roof, d_rest_mm=d_of_roof(roof),
                d_rest_range_mm=(d_lo, d_hi))


def _pad(spec: Spec) -> Pad:
    """The pad's disc, centring lip and the two alignment holes (of different sizes: it fits one way round)."""
    pad, R_e = spec.pad, spec.elastomer.diameter_mm / 2.0
    lip_inner = R_e + pad.lip_clearance_mm
    lip_outer = lip_inner + pad.lip_width_mm if pad.lip_height_mm > 0 else lip_inner
    R_pad = pad.diameter_mm / 2.0
    if lip_outer > R_pad:
        raise SpecError("pad.diameter_mm", shown(pad.diameter_mm),
                        f"must be at least {_fmt(2 * lip_outer)} mm to hold the elastomer and its centring lip")
    d1 = pad.alignment_hole_diameter_mm
    d2 = d1 + SECOND_HOLE_EXTRA_MM
    sx = pad.alignment_hole_spacing_mm / 2.0
    if sx - d1 / 2.0 <= lip_outer or sx + d2 / 2.0 >= R_pad:
        raise SpecError("pad.alignment_hole_spacing_mm", shown(pad.alignment_hole_spacing_mm),
                        f"must place both holes (diameters {_fmt(d1)} and {_fmt(d2)} mm) between the lip "
                        f"(radius {_fmt(lip_outer)} mm) and the pad's edge (radius {_fmt(R_pad)} mm)")
    return Pad(pad_radius_mm=R_pad, lip_inner_radius_mm=lip_inner, lip_outer_radius_mm=lip_outer,
                lip_height_mm=pad.lip_height_mm, alignment_holes=((-sx, 0.0, d1), (sx, 0.0, d2)))


def _address(spec: Spec, chip) -> Address:
    """The I2C address: the option code's base plus the A1/A0 straps; and the chip's refused OSR/DIG_FILT pairs."""
    sen = spec.sensor
    codes = sorted(k.rsplit("_", 1)[1] for k in chip.quantities if k.startswith("i2c_base_address_"))
    if sen.option_code not in codes:
        raise SpecError("sensor.option_code", shown(sen.option_code),
                        "must be one of " + ", ".join(repr(c) for c in codes)
                        + f" for {chip.key}")
    base = int(chip[f"i2c_base_address_{sen.option_code}"].nominal)
    if not base <= sen.i2c_address <= base + 3:
        allowed = ", ".join(f"0x{a:02X}" for a in range(base, base + 4))
        raise SpecError("sensor.i2c_address", shown(sen.i2c_address),
                        f"must be one of {allowed} for option code {sen.option_code} (base plus the A1/A0 straps)",
                        "or change sensor.option_code")
    forbidden = {tuple(int(v) for v in pair.split("/"))
                 for pair in chip.texts.get("forbidden_osr_dig_filt", "").split()}
    if (sen.osr, sen.dig_filt) in forbidden:
        raise SpecError("sensor.dig_filt", shown(sen.dig_filt),
                        f"is not allowed with sensor.osr = {sen.osr} (the chip refuses OSR/DIG_FILT pairs "
                        + ", ".join(f"{a}/{b}" for a, b in sorted(forbidden)) + ")",
                        "raise sensor.dig_filt or sensor.osr")
    return Address(i2c_address=sen.i2c_address,
                address_straps=((sen.i2c_address - base) >> 1 & 1, (sen.i2c_address - base) & 1))


def _mould(spec: Spec, printer, part: Part, core_base_r: float, array: ArrayLayout | None) -> Mould:
    """A cup holding N inverted cavities in a row along x, and a lid carrying the cores, fill and vent holes. A
    cavity is one tip, or one continuous skin; an array's default count is the parts it needs (a tip per taxel)."""
    R_e, H_e = part["elastomer_radius_mm"], part["elastomer_height_mm"]
    wall, n = spec.mould.wall_mm, spec.mould.cavities
    hx = hy = R_e  # the cast part's half extent
    if array is not None and array.skin is Skin.CONTINUOUS:
        hx = R_e + max(x for x, _ in array.part_centres_mm)
        hy = R_e + max(y for _, y in array.part_centres_mm)
    elif array is not None and "cavities" not in spec.mould.model_fields_set:
        n = min(len(array.taxels), ARRAY_CAVITIES_DEFAULT_MAX)
    pitch = 2.0 * hx + wall
    span = (n - 1) * pitch
    pin_d = REGISTRATION_PIN_MM
    pin_x = span / 2.0 + hx + wall + pin_d / 2.0
    cup = (2.0 * (pin_x + pin_d / 2.0 + wall), 2.0 * (hy + wall), H_e + wall)
    lid_t = max(wall, 2.5)
    annulus = R_e - core_base_r
    sprue_d = min(SPRUE_MAX_MM, annulus - 1.0)
    vent_d = max(VENT_MIN_MM, printer["min_hole_mm"].nominal)
    if sprue_d <= 0.0 or vent_d > annulus - 0.6:
        raise SpecError("elastomer.diameter_mm", shown(spec.elastomer.diameter_mm),
                        "leaves no room between the insertion channel and the cavity wall for the fill and vent "
                        "holes", "use a larger elastomer or a narrower insert channel")
    return Mould(
        cavity_centres_x_mm=tuple((i - (n - 1) / 2.0) * pitch for i in range(n)), cavity_pitch_mm=pitch,
        wall_mm=wall, cup_size_mm=cup, lid_thickness_mm=lid_t, lid_size_mm=(cup[0] + 2.0 * PRY_LIP_MM, cup[1], lid_t),
        pin_diameter_mm=pin_d, pin_hole_diameter_mm=pin_d + 2 * printer["fit_clearance_mm"].nominal,
        pin_positions_x_mm=(-pin_x, pin_x), pin_height_mm=0.8 * lid_t, core_root_mm=lid_t / 2.0,
        sprue_diameter_mm=sprue_d, sprue_offset_mm=(core_base_r + R_e) / 2.0,
        vent_diameter_mm=vent_d, vent_offset_mm=R_e - vent_d / 2.0 - 0.3, vent_angles_deg=(210.0, 330.0),
    )


def _array(spec: Spec, arr: Array, chip, printer, minimum: float) -> ArrayLayout:
    """The array's taxels (``arr``, the spec's [array]): their centres (a grid centred on the origin, row 0 at +y,
    index row by row; or the explicit positions), polarity, and one I2C address each; checked against the smallest
    pitch the parts allow (``minimum``, mm)."""
    if arr.positions_mm is not None:
        centres, key = list(arr.positions_mm), "array.positions_mm"
        signs = [(-1) ** i for i in range(len(centres))]
    else:
        p, key = arr.pitch_mm, "array.pitch_mm"
        assert p is not None  # the spec requires pitch_mm for a grid of more than one taxel
        cells = [(r, c) for r in range(arr.rows) for c in range(arr.cols)]
        centres = [((c - (arr.cols - 1) / 2.0) * p, ((arr.rows - 1) / 2.0 - r) * p) for r, c in cells]
        signs = [(-1) ** (r + c) for r, c in cells]
    if arr.polarity is Polarity.SAME:
        signs = [1] * len(centres)
    pitch = min(math.dist(a, b) for i, a in enumerate(centres) for b in centres[i + 1:])
    if pitch + 1e-9 < minimum:
        raise SpecError(key, shown(arr.pitch_mm if arr.positions_mm is None else arr.positions_mm),
                        f"puts two taxels {_fmt(pitch)} mm apart: at least {_fmt(minimum)} mm for "
                        + ("separate fingertips with their centring lips" if arr.skin is Skin.SEPARATE else
                           "one skin (pockets apart by the minimum skin, chip recesses by the printer's minimum wall)"))
    addresses = address_plan(spec, chip, len(centres))
    taxels = tuple(Taxel(i, x + 0.0, y + 0.0, s, a, code, straps)
                   for i, ((x, y), s, (a, code, straps)) in enumerate(zip(centres, signs, addresses)))
    hull = outline.hull(centres)
    R = spec.pad.diameter_mm / 2.0
    xs, ys = [x for x, _ in centres], [y for _, y in centres]
    cx, cy = (min(xs) + max(xs)) / 2.0, (min(ys) + max(ys)) / 2.0
    part = tuple((x - cx + 0.0, y - cy + 0.0) for x, y in centres) if arr.skin is Skin.CONTINUOUS else ((0.0, 0.0),)
    return ArrayLayout(taxels, arr.skin, arr.polarity, pitch, minimum, tuple(hull),
                       (min(xs) - R, min(ys) - R, max(xs) + R, max(ys) + R), part)


def _min_pitch(spec: Spec, skin: Skin, printer, part: Part, stack: Stack, pad: Pad) -> float:
    """The closest two taxels' centres may be: separate fingertips share one lip wall between them; a continuous
    skin keeps the minimum skin between two pockets; the pad keeps its minimum wall between two chip recesses."""
    recesses = stack["recess_side_mm"] + printer["min_wall_mm"].nominal
    if skin is Skin.SEPARATE:
        return max(2.0 * pad["lip_inner_radius_mm"] + (spec.pad.lip_width_mm if spec.pad.lip_height_mm > 0 else 0.0),
                   recesses)
    return max(2.0 * part["pocket_radius_mm"] + spec.elastomer.min_skin_mm, recesses)


def address_plan(spec: Spec, chip, n: int) -> list[tuple[int, str, tuple[int, int]]]:
    """(address, option code, (A1, A0)) per taxel: the four A1/A0 straps of the sensor's option code from its
    address on, then the next option codes' (the order number's -0xx sets the base: one code per four chips, as the
    ReSkin/AnySkin boards mix two). Ordering the right chips needs no programming step; the chip's user-writable
    EE_I2C_ADDR (datasheet section 8.4) would, for each chip alone on the bus before assembly."""
    codes = sorted(k.rsplit("_", 1)[1] for k in chip.quantities if k.startswith("i2c_base_address_"))
    start = codes.index(spec.sensor.option_code)
    plan = []
    for code in codes[start:] + codes[:start]:
        base = int(chip[f"i2c_base_address_{code}"].nominal)
        first = spec.sensor.i2c_address - base if code == spec.sensor.option_code else 0
        plan += [(base + k, code, (k >> 1 & 1, k & 1)) for k in range(first, 4)]
    if len(plan) < n:
        raise SpecError("sensor.i2c_address", shown(spec.sensor.i2c_address),
                        f"leaves {len(plan)} addresses for {n} taxels on one bus",
                        f"start at the base address of option code {codes[0]}")
    return plan[:n]


def _array_holes(spec: Spec, array: ArrayLayout) -> tuple[tuple[float, float, float], ...]:
    """The pad's two alignment holes beyond the outermost taxels along x, at pad.alignment_hole_spacing_mm / 2 from
    them (the smaller one at -x): inside the pad's outline (the taxels' hull grown by the pad radius)."""
    taxels = array.taxels
    d1 = spec.pad.alignment_hole_diameter_mm
    sx = spec.pad.alignment_hole_spacing_mm / 2.0
    lo, hi = min(t.x_mm for t in taxels), max(t.x_mm for t in taxels)

    def mean_y(x: float) -> float:
        ys = [t.y_mm for t in taxels if abs(t.x_mm - x) < 1e-9]
        return (min(ys) + max(ys)) / 2.0

    return ((lo - sx, mean_y(lo) + 0.0, d1), (hi + sx, mean_y(hi) + 0.0, d1 + SECOND_HOLE_EXTRA_MM))
