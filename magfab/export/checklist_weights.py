"""The weight jig on the bench papers: its checklist section ("Calibrate with weights") and its bill-of-materials rows,
from the build's weight plan (calibration/weigh_plan.json, :mod:`magfab.export.weigh_plan`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ..jig import jig_of

if TYPE_CHECKING:
    from ..design import Design

__all__ = ["weights_steps", "jig_rows"]


def weights_steps(design: Design, plan: Mapping[str, Any] | None, sensor: str) -> list[str]:
    """The checklist's steps of a calibration with known weights for the sensor ``sensor`` (none without a plan: an
    array, or a design whose ranges the jig's loads do not fit)."""
    if plan is None:
        return []
    j = jig_of(design)
    steps = plan["steps"]
    most = plan["coins_most"]
    arm = max(s["moment_arm_mm"] for s in steps if s["angle_deg"] > 0)
    coin = plan["coin"]
    return [
        "No force sensor? Calibrate from known weights instead of the scan (README, 'Calibration without a force "
        "sensor'; docs/bundle.md section 1b). Print weigh_cap.stl and the stands weigh_stand_0.stl, weigh_stand_20.stl "
        "and weigh_stand_40.stl on any filament printer (PLA, 0.2 mm layers), in the poses they are saved in, with "
        "supports under the cap's plate: its underside is the face that rests on the tip, and must come out flat "
        f"(check it with a straightedge). Number the cap's pockets 1 to {plan['pockets']} round it with a marker, "
        "from any one.",
        f"Weigh the printed cap on a balance (0.1 g or finer): it is part of every load (at most "
        f"{plan['cap_mass_bound_g']:.1f} g in the densest filament). Have {most} coins ready: {coin['name']} "
        f"({coin['mass_g']:g} g each; another coin of known mass up to {2 * j.pocket_radius_mm:.1f} mm across fits "
        "the pockets, given with --coin-g).",
        "Put the board in the stand's pocket of the angle each step names (flat, 20 or 40 degrees), connector uphill "
        "and its cable out of the open end, then the cap on the tip, centred by eye so its skirt clears the tip evenly "
        "all round: its flat face is the contact the model presses with. Nothing but the cap may touch the tip.",
        "Put each step's coins in the pockets it lists: equal stacks in opposite pockets keep the load on the axis. "
        f"On the tilted platforms a stack stays below the pockets' rim ({j.rim_mm:g} mm); the load's centre sits at "
        f"most {arm:.1f} mm above the tip's top there, which the model does not include.",
        "From the build folder, run magfab-readout weigh first.csv --cap-g G --first, G the cap's mass in grams: it "
        f"walks the plan's first {len(plan['first'])} steps (flat), waits at each until the reading is steady and "
        "writes the weighings. magfab weigh-plan first.csv plan.json fits them and writes the plan for this skin's "
        "stiffness, and magfab-readout weigh weighings.csv --cap-g G --plan plan.json walks it (without --plan, "
        f"weigh walks this build's {len(steps)} steps, the softest skin's plan, in one stage). Then magfab "
        f"calibrate --weights weighings.csv --sensor {sensor} fits the sensor's model to them, states the "
        "calibration's predicted error over the region and keeps it in the sensor's record, and magfab-readout upload "
        f"--sensor {sensor} writes it into the board (the README's block shows the whole path). A new skin "
        f"on a calibrated board: magfab sensor reskin, then weigh --reskin ({len(plan['reskin'])} steps) and the "
        "same calibrate and upload.",
    ]


def jig_rows(plan: Mapping[str, Any] | None, row) -> list[dict[str, object]]:
    """The weight jig's rows of the bill of materials (``row`` builds one, as bom.py's), none without a plan."""
    if plan is None:
        return []
    most = plan["coins_most"]
    coin = plan["coin"]
    return [
        row("Printed weight jig", "weigh_cap.stl + weigh_stand_0/20/40.stl", "any filament printer (PLA); the "
            "calibration without a force sensor, instead of the reference sensor, indenter and stage", 1, "set",
            "this build; magfab/jig.py, recipes/bench.toml weigh-jig"),
        row("Coins", coin["name"], f"the weight plan's loads for the stiffest skin, {coin['mass_g']:g} g each "
            "(calibration/weigh_plan.json)",
            most, "pcs", "recipes/bench.toml weigh-coin (" + coin["source"] + ")"),
        row("Balance", "kitchen or lab balance, 0.1 g or finer", "weighs the printed cap once", 1, "pcs",
            "the cap's mass enters every load; 0.1 g is 1 mN"),
    ]
