"""The weight jig: the cap that carries coins on the tip and the stand that holds the board at the plan's angles.

A weight calibration (``magfab calibrate --weights``, :mod:`magfab.models.weighing`) fits the sensor's model to the
field under known masses resting on the tip, with the board flat or tilted. The jig makes those loads the model's:

- **The cap** (:func:`cap_solid`) rests on the tip through a flat rigid plate, the contact of the FE's flat indenter
  (recipes bench.toml ``[indenter]``), which covers the tip at any lateral travel. A skirt hangs from the plate round
  the tip, clear of it, and carries a tray of coin pockets low beside the tip, so that the load's centre of mass sits
  near the contact plane: a tilted load then presses on the tip's top with little turning moment
  (:meth:`Jig.moment_arm_mm` states what remains for each load). Equal stacks in each opposite pair of pockets keep
  the centre of mass on the tip's axis. The cap's tray stays clear of the pad's lip and the connector at the
  deepest indentation the normal curve reaches; on a rounded tip its stacks stay low enough for the cap to sit steady.
- **The stand** (:func:`stand_solid`) is one part per stand angle (:data:`ANGLES_DEG`): a platform on a base plate,
  raised so that the loaded cap's tray clears the base on the downhill side. Each platform has a pocket that takes
  the board with its connector uphill (the pocket is open there for the cable) and a relief under it for the
  bottom-side parts; the weight's downhill pull is then along the sensor's +y, as the weighing model has it.

Board frame throughout (z = 0 on the board's top face, the chip on the axis); the cap's print pose is its use pose
moved down to the bed (the tray's underside), its face a bridge over the skirt (the checklist asks for supports under
it); each stand's is as it stands.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .board.placement import ORIGIN, place
from .design import Design
from .models.predict import travel_to_d_min
from .models.weighing import weight_plan
from .readout.src.magfab_readout.coins import coin_layout
from .recipes import catalogue
from .spec import Tip
from .units import G0

if TYPE_CHECKING:
    import cadquery as cq

    from .models.predict import Prediction

# Imported lazily, inside the functions that use it, for speed: CadQuery takes a noticeable time to import, and
# importing this module should not.

__all__ = ["Jig", "jig_of", "jig_plans", "cap_solid", "stand_solid", "ANGLES_DEG", "REACH", "coin_layout", "Platform",
           "platform"]

#: The stand's angles, degrees: the weight plan's (magfab.models.weighing.ANGLES_DEG, which a test holds equal).
ANGLES_DEG = (0.0, 20.0, 40.0)
#: How far past the travel to d_min the normal curve reaches (magfab.models.predict.GRID_REACH, which a test holds
#: equal): the deepest the cap can sink within the model's range.
REACH = 1.25
#: How tall a pocket's stack may be on the flat stand, in rims (our choice: four rims, about 24 mm, a steady column).
FLAT_STACK_RIMS = 4
#: A flat plate resting on a rounded tip is steady while its load's centre of mass sits below the tip's centre of
#: curvature (a rigid body rolling on a sphere: the restoring moment W (R - h) per radian); the silicone's contact
#: patch adds a restoring moment of its own, not counted. The coins' centre is kept within this share of the tip's
#: radius above the face; a flat tip carries the plate flat on flat.
STEADY_FRACTION = 1.0
#: On a flat tip, which has no rolling geometry to right the cap, only the silicone resists the cap's tipping: the
#: contact's rotational stiffness, estimated as a bed of independent springs under the flat face over the tip's top,
#: k_theta = k_n a^2 / 4 for the normal tangent stiffness k_n at the load (the softest skin's curve) and the tip's
#: radius a. The cap stays steady on the flat stand while the load's tipping moment per radian, W h (h the coins'
#: centre above the face), stays within this share of k_theta. An estimate, not a solved model (the tip's own
#: bending softens it; nothing here counts that), so the share is at most one. A rounded tip keeps the rolling rule
#: (:data:`STEADY_FRACTION`), which leaves the contact's own stiffness out.
CONTACT_STEADY_SHARE = 1.0
#: How far the loaded cap's lowest point stays above the stand's base plate, mm (our choice: room for a finger).
BASE_CLEARANCE_MM = 5.0


@dataclass(frozen=True)
class Jig:
    """The jig's dimensions for one design (mm, g; board frame), from :func:`jig_of`."""

    z_face_mm: float  # the contact plane: the tip's top
    face_radius_mm: float  # the flat face's radius (the skirt's inner radius)
    wall_mm: float
    plate_mm: float
    z_under_mm: float  # the tray's underside, unloaded
    floor_mm: float
    rim_mm: float  # a pocket's wall above its floor
    pocket_radius_mm: float
    pocket_ring_mm: float  # the radius the pockets' centres sit on
    pockets: int
    coin_g: float
    coin_mm: float  # a coin's thickness
    sink_mm: float  # the deepest the cap sinks within the model's range
    density_g_cm3: float
    board_mm: tuple[float, float, float, float]  # the board's outline in the sensor's frame: x0, y0, x1, y1
    board_thickness_mm: float
    tip_radius_mm: float
    rounded_tip: bool  # a hemispherical tip (the rolling rule) or a flat one (the contact rule)

    @property
    def steady_arm_mm(self) -> float:
        """The highest the coins' centre may sit above the face and the cap stay steady on a rounded tip (the rolling
        rule, :data:`STEADY_FRACTION`); unbounded on a flat tip, whose loads :meth:`contact_steady` bounds."""
        return STEADY_FRACTION * self.tip_radius_mm if self.rounded_tip else math.inf

    @property
    def z_floor_mm(self) -> float:
        """The pockets' floor."""
        return self.z_under_mm + self.floor_mm

    @property
    def outer_radius_mm(self) -> float:
        return self.pocket_ring_mm + self.pocket_radius_mm + 2.0 * self.wall_mm  # past the rings: no tangent circles

    def _stack_max(self, height_mm: float) -> int:
        """The most coins a pocket may hold: no taller than ``height_mm`` and the cap steady (:attr:`steady_arm_mm`)."""
        steady = (self.steady_arm_mm + self.z_face_mm - self.z_floor_mm) * 2.0 / self.coin_mm
        return max(0, int(min(height_mm / self.coin_mm, steady)))

    @property
    def tilted_coins_max(self) -> int:
        """The most coins a tilted stand may carry: stacks no taller than the pockets' rim, the cap steady."""
        return self.pockets * self._stack_max(self.rim_mm)

    def loads_g(self) -> tuple[float, ...]:
        """The loads the cap takes, g: every even number of coins up to :data:`FLAT_STACK_RIMS` rims a pocket, the
        cap steady."""
        most = self.pockets * self._stack_max(FLAT_STACK_RIMS * self.rim_mm)
        return tuple(round(n * self.coin_g, 6) for n in range(2, most + 1, 2))

    def contact_steady(self, coins: int, prediction: Prediction, stiffness: float = 1.0) -> bool:
        """Whether the heaviest printed cap with ``coins`` stays steady on a flat tip against its contact's
        rotational stiffness (:data:`CONTACT_STEADY_SHARE`; the whole load counted at the coins' centre, which
        overstates the moment of the cap's own mass, whose centre is lower). The skin is the softest of the band
        times ``stiffness`` (its normal curve's force scaled by it, :func:`magfab.models.weight_plan.stiffness_of`), so
        k_n at the load W is ``stiffness`` times the softest curve's tangent where it carries W / ``stiffness``. A
        rounded tip: True (the rolling rule bounds its stacks, :attr:`steady_arm_mm`)."""
        if self.rounded_tip:
            return True
        weight_N = (self.cap_mass_bound_g() + coins * self.coin_g) * G0 / 1000.0
        curve = prediction.curves["soft"]
        k_n = stiffness * float(np.interp(weight_N / stiffness, curve.force_N, curve.stiffness_N_per_mm))
        return weight_N * self.moment_arm_mm(coins) <= CONTACT_STEADY_SHARE * k_n * self.tip_radius_mm**2 / 4.0

    def plan_loads(self, prediction: Prediction, stiffness: float = 1.0) -> dict[str, Any]:
        """What :func:`magfab.models.weight_plan.weight_plan` takes of this jig for ``prediction``'s design and a skin
        ``stiffness`` times the softest: its loads on which the cap stays steady (:meth:`contact_steady`) and a tilted
        stand's most."""
        loads = tuple(w for w in self.loads_g()
                      if self.contact_steady(round(w / self.coin_g), prediction, stiffness))
        return {"loads_g": loads, "tilted_max_g": self.tilted_coins_max * self.coin_g}

    def plan(self, prediction: Prediction, cap_g: float | None = None, stiffness: float = 1.0
             ) -> list[tuple[float, float, int]]:
        """The weight plan (:func:`magfab.models.weight_plan.weight_plan`) in this jig's coins: (mass on the tip in g,
        stand angle in degrees, coins), the cap's mass ``cap_g`` (default: :meth:`cap_mass_bound_g`, the heaviest a
        printed cap may be), for a skin ``stiffness`` times the softest of the band (default: the softest, whose plan
        is safe for every skin)."""
        cap = self.cap_mass_bound_g() if cap_g is None else cap_g
        plan = weight_plan(prediction, cap, stiffness, **self.plan_loads(prediction, stiffness))
        return [(m, a, round((m - cap) / self.coin_g)) for m, a in plan]

    @property
    def skirt_span_mm(self) -> tuple[float, float]:
        """The skirt's bottom and top (board frame): from the tray's underside to the plate's top, or from the face up
        to the tray where the tray must sit above the tip's top (a short tip over a long travel)."""
        return (min(self.z_face_mm, self.z_under_mm),
                max(self.z_face_mm + self.plate_mm, self.z_under_mm + self.floor_mm))

    def cap_volume_mm3(self) -> float:
        """The cap's volume from its dimensions (a test holds it to the CAD solid's)."""
        r_in, w = self.face_radius_mm, self.wall_mm
        lo, hi = self.skirt_span_mm
        skirt = math.pi * ((r_in + w) ** 2 - r_in**2) * (hi - lo)
        plate = math.pi * r_in**2 * self.plate_mm
        floor = math.pi * (self.outer_radius_mm**2 - (r_in + w) ** 2) * self.floor_mm
        ring = math.pi * ((self.pocket_radius_mm + w) ** 2 - self.pocket_radius_mm**2) * self.rim_mm
        return skirt + plate + floor + self.pockets * ring  # the rings stand clear of the skirt and each other

    def cap_mass_bound_g(self) -> float:
        """The cap's mass at the densest printed material (the plan's range check; the bench weighs the cap)."""
        return self.cap_volume_mm3() / 1000.0 * self.density_g_cm3

    def moment_arm_mm(self, coins: int) -> float:
        """How far the load's centre of mass (the coins') sits above the contact plane, mm: a tilted stand turns the
        load about the tip's top by this arm times the load's downhill part."""
        per_pocket = math.ceil(coins / self.pockets)
        return self.z_floor_mm + per_pocket * self.coin_mm / 2.0 - self.z_face_mm


def jig_plans(design: Design, prediction: Prediction) -> Callable[[float], list[tuple[float, float]]]:
    """The plan in the weight jig's coins on its heaviest printed cap (:meth:`Jig.plan`, as the build ships it), as
    (mass on the tip, stand angle) pairs, as a function of the skin's stiffness over the softest of the band (the
    simulated study's :func:`magfab.models.weighing_study.trial` takes it)."""
    jig = jig_of(design)
    return lambda stiffness: [(m, a) for m, a, _ in jig.plan(prediction, stiffness=stiffness)]


def jig_of(design: Design) -> Jig:
    """The jig for a single-taxel ``design`` (ValueError for an array, which is not weighed)."""
    if design.array is not None:
        raise ValueError("the weight jig is for a single taxel: an array is calibrated from a scan")
    jig, coin = catalogue("bench")["weigh-jig"], catalogue("bench")["weigh-coin"]
    w, bulge, clear = jig["wall_mm"].nominal, jig["bulge_mm"].nominal, jig["clearance_mm"].nominal
    r_e = design.elastomer_radius_mm
    z_face = design.z_elastomer_base_mm + design.elastomer_height_mm
    face = 1.5 * r_e + bulge  # the tip, half its radius of lateral travel, and the bulge
    # the normal curve's end: the indentation grid's reach, or the scan depth the FE stops at (predict._fe_curve)
    sink = min(REACH * travel_to_d_min(design), float(design.spec.calibration.scan_z_mm))
    connector = catalogue("parts")["jst-sh-4"]["height_mm"].nominal
    tallest = max(design.z_pad_top_mm + design.lip_height_mm, connector)
    r_pocket = coin["diameter_mm"].nominal / 2.0 + jig["pocket_clearance_mm"].nominal / 2.0
    pockets = int(jig["pockets"].nominal)
    # the pockets' rings stand clear of the skirt and of each other (so their volumes add)
    ring = max(face + w + r_pocket + w + 0.1, (r_pocket + w + 0.1) / math.sin(math.pi / pockets))
    _, outline, _ = place(design)
    ox, oy = ORIGIN
    x0, y0, x1, y1 = outline
    return Jig(z_face_mm=z_face, face_radius_mm=face, wall_mm=w, plate_mm=jig["plate_mm"].nominal,
               z_under_mm=tallest + sink + clear, floor_mm=w, rim_mm=jig["rim_mm"].nominal,
               pocket_radius_mm=r_pocket, pocket_ring_mm=ring, pockets=pockets, coin_g=coin["mass_g"].nominal,
               coin_mm=coin["thickness_mm"].nominal, sink_mm=sink, density_g_cm3=jig["density_g_cm3"].nominal,
               board_mm=(x0 - ox, oy - y1, x1 - ox, oy - y0), board_thickness_mm=design.spec.pcb.thickness_mm,
               tip_radius_mm=r_e, rounded_tip=design.tip is Tip.HEMISPHERE)


def cap_solid(design: Design) -> cq.Workplane:
    """The cap in its print pose: its use pose (:class:`Jig`) moved down onto the bed (the tray's underside, or the
    face where the tray sits above it)."""
    import cadquery as cq

    j = jig_of(design)
    r_in, w = j.face_radius_mm, j.wall_mm
    lo, hi = j.skirt_span_mm
    cap = cq.Workplane("XY", origin=(0, 0, lo)).circle(r_in + w).circle(r_in).extrude(hi - lo)
    cap = cap.union(cq.Workplane("XY", origin=(0, 0, j.z_face_mm)).circle(r_in + w).extrude(j.plate_mm))
    tray = cq.Workplane("XY", origin=(0, 0, j.z_under_mm))
    cap = cap.union(tray.circle(j.outer_radius_mm).circle(r_in + w).extrude(j.floor_mm))
    centres = [(j.pocket_ring_mm * math.cos(2 * math.pi * k / j.pockets),
                j.pocket_ring_mm * math.sin(2 * math.pi * k / j.pockets)) for k in range(j.pockets)]
    rings = (cq.Workplane("XY", origin=(0, 0, j.z_under_mm)).pushPoints(centres)
             .circle(j.pocket_radius_mm + w).circle(j.pocket_radius_mm).extrude(j.floor_mm + j.rim_mm))
    return cap.union(rings).clean().translate((0, 0, -lo))


@dataclass(frozen=True)
class Platform:
    """The stand for one angle (mm): its top face's centre height and half its run along y (the face spans
    ``length_mm`` along its slope), the face's height at its downhill edge, the board's pocket depth, the base plate
    (x, y), and how high the loaded cap's lowest point (its tray's downhill edge, sunk to the normal curve's end) sits
    above the base plate."""

    angle_deg: float
    centre_z_mm: float
    half_run_mm: float
    low_mm: float
    width_mm: float
    length_mm: float
    depth_mm: float
    base_mm: tuple[float, float]
    cap_clearance_mm: float
    base_thickness_mm: float
    pocket_mm: tuple[float, float]  # the board's pocket (x, y), clearance included
    relief_mm: tuple[float, float, float]  # the relief under the board (x, y, depth below the pocket)


def platform(design: Design, angle_deg: float) -> Platform:
    """The stand for ``angle_deg``: tall enough that the loaded cap's tray clears its base plate by
    :data:`BASE_CLEARANCE_MM`, its base reaching past the platform by the apron uphill and downhill."""
    j = jig_of(design)
    jig = catalogue("bench")["weigh-jig"]
    base, apron = jig["stand_base_mm"].nominal, jig["stand_apron_mm"].nominal
    clear, relief = jig["stand_clearance_mm"].nominal, jig["stand_relief_mm"].nominal
    x0, y0, x1, y1 = j.board_mm
    wall = 2.0 * j.wall_mm
    width, length = x1 - x0 + 2 * (clear + wall), y1 - y0 + 2 * (clear + wall)
    depth = j.board_thickness_mm / 2.0  # the board stands half out of its pocket, to be lifted out
    a = math.radians(angle_deg)
    half = length / 2.0 * math.cos(a)
    # the tray's underside above the platform's face, the cap sunk: the board's top, then the tray over it
    tray = j.board_thickness_mm - depth + j.z_under_mm - j.sink_mm
    lowest = -j.outer_radius_mm * math.sin(a) + tray * math.cos(a)  # the tray's downhill edge, from the face's centre
    centre = max(base + depth + relief + wall + half * math.tan(a), base + BASE_CLEARANCE_MM - lowest)
    return Platform(angle_deg, centre, half, centre - half * math.tan(a), width, length, depth,
                    (width + 2 * wall, 2 * (half + apron)), centre + lowest - base, base,
                    (x1 - x0 + 2 * clear, y1 - y0 + 2 * clear), (x1 - x0 - 2 * wall, y1 - y0 - 2 * wall, relief))


def stand_solid(design: Design, angle_deg: float) -> cq.Workplane:
    """The stand for ``angle_deg`` as it prints and stands: the pocketed platform on its base plate."""
    import cadquery as cq

    p = platform(design, angle_deg)
    stand = cq.Workplane("XY").rect(*p.base_mm).extrude(p.base_thickness_mm)
    slope = math.tan(math.radians(angle_deg))
    wedge = (cq.Workplane("YZ", origin=(-p.width_mm / 2.0, 0, 0))
             .polyline([(-p.half_run_mm, 0.0), (p.half_run_mm, 0.0), (p.half_run_mm, p.low_mm),
                        (-p.half_run_mm, p.centre_z_mm + p.half_run_mm * slope)]).close()
             .extrude(p.width_mm))
    # the pocket in the platform's own frame (top face z = 0, the board centred), open uphill (-y)
    (px, py), (rx, ry, relief) = p.pocket_mm, p.relief_mm
    pocket = (cq.Workplane("XY", origin=(0, 0, -p.depth_mm)).center(0.0, -p.length_mm / 2.0)
              .rect(px, py + p.length_mm).extrude(p.depth_mm + 1.0))
    under = cq.Workplane("XY", origin=(0, 0, -p.depth_mm - relief)).rect(rx, ry).extrude(relief + 0.5)
    tool = pocket.union(under).rotate((0, 0, 0), (1, 0, 0), -angle_deg).translate((0, 0, p.centre_z_mm))
    return stand.union(wedge.cut(tool)).clean()
