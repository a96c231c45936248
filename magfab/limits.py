"""Resource limits: what a build of a design will cost, estimated before any of the work, and the bounds that
keep every valid spec within the budget (about a minute and a few GB on two cores).

Each key that drives cost feeds one estimate, and each estimate has a limit sized so that the fixed part of a
build plus every estimate at its limit stays within :data:`BUDGET_S` and :data:`BUDGET_MB`:

=========================  ==================================================  ===================================
estimate                   driven by                                           grows like
=========================  ==================================================  ===================================
surface triangles          mould.tessellation_tolerance_mm,                    (cavities + 1) n(R_e)^2 for a dome,
                           mould.angular_tolerance_deg, mould.cavities,        n the facets round a circle:
                           elastomer.diameter_mm                               max(360/angle, pi/acos(1 - tol/r))
FE work (elements x steps) predict.tolerance_pct (the meshes the auto choice   profile area / h^2 per mesh, summed
                           runs), elastomer size, predict.mechanics_model      over the meshes tried
scan rows                  calibration.scan_step_mm, scan_y_mm, scan_z_mm      (y / step) (z / step)
MLS work                   scan rows, calibration.method ('mls' or 'auto')     rows^2
board routing              array.rows x cols or positions_mm (the chips)       1.45 s x chips^1.7 (fitted, below)
=========================  ==================================================  ===================================

The constants were measured on the MagOne design and variants of it, on a shared two-core machine that was
busy at the time (so ratios more than absolute times), and carry a margin of about 1.5-2x; the figures are in
the constants' comments. :func:`check_limits` is called by :func:`magfab.check.preflight` right after derive, so
``magfab check`` and ``magfab build`` both refuse an over-budget spec with one :class:`~magfab.errors.SpecError` that
names the key, its value, the estimate and the limit, and the value that would fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from .errors import ScanError, SpecError
from .errors import number_text as _fmt
from .models.mechanics.schedule import FE_ERROR_PER_H_OVER_R, fe_meshes

if TYPE_CHECKING:
    from .design import Design
    from .spec import Spec

__all__ = ["BUDGET_S", "BUDGET_MB", "Cost", "estimate", "check_limits", "scan_rows", "triangles",
           "MAX_TRIANGLES", "MAX_FE_WORK", "MAX_SCAN_ROWS", "MAX_MLS_ROWS", "MAX_BOARD_S", "routing_s",
           "most_chips"]

#: What any valid spec may take to build, on two cores.
BUDGET_S = 60.0
BUDGET_MB = 4000.0

#: The part of a build that no spec key scales (CAD kernel import, board, firmware, report): the MagOne build
#: took 16.5 s, of which about 5.4 s FE and 1.3 s tessellation; 10 s kept with a margin.
FIXED_S = 10.0
FIXED_MB = 700.0

# ---- surface triangles ----------------------------------------------------------------------------------
#: Triangles over all four parts per (dome facet count)^2 and per cavity + 1 (the elastomer and each of the
#: cup's cavities carry the dome). Measured 1.1-1.3 on MagOne from tolerance 0.01 to 0.0003 mm and angles 10-2
#: degrees; 1.2 with the small-feature term below bounds every measurement from above.
DOME_TRIANGLES = 1.2
#: Triangles per facet of a small (1 mm) circle, per (cavity + 1) / 2: holes, pins, cores, the pad's features.
#: Measured 127-160 (lid + pad at angle 2 degrees: 23,482 triangles over 180 facets).
SMALL_FEATURE_TRIANGLES = 150.0
#: Triangles per facet of the elastomer's rim for a flat tip (no dome): the cylinder, its ends and the cup's
#: cavity; measured 18 (tolerance-bound) to 33 (2 degrees) per facet over the elastomer and the cup.
RIM_TRIANGLES = 20.0
#: MagOne at 2 degrees (101,668 triangles) took 41 s of CPU to build (87 s wall on the busy machine) against
#: the default's 12,172; 233k triangles took 39 s to tessellate alone (the kernel's mesher is superlinear).
MAX_TRIANGLES = 60_000
SECONDS_PER_TRIANGLE = 4.0e-4  # tessellation, STL/STEP, mould fit, report pictures: (41 - 16) s / 89k, 1.4x
MB_PER_TRIANGLE = 0.006  # 233k triangles: 983 MB peak, of which ~550 MB the CAD kernel

# ---- the normal-load FE ---------------------------------------------------------------------------------
#: Triangles of the (r, z) profile mesh per (profile area / h^2): equilateral triangles of side h,
#: 1 / (sqrt(3) / 4) = 2.31, away from the magnet's edges.
FE_TRIANGLES_PER_AREA_H2 = 2.4
#: Triangles added by the grading at the magnet's two rounded edges (size 0.07 of the edge radius, growing 1:4),
#: nearly independent of h and of the scale: measured 827, 787, 835, 975 on MagOne at 1, 0.75, 0.5, 0.35 mm.
FE_EDGE_TRIANGLES = 900
#: Indentation steps along the normal curve (predict.N_INDENT); the FE may stop earlier.
FE_STEPS = 21
#: Seconds per triangle-step of the nonlinear FE, counting all FE_STEPS although a curve often stops earlier
#: (QDLDL factorisation, one symbolic factorisation per load path, kernel-averaged stretch): the two FE
#: curves of a MagOne prediction (1 and 0.75 mm, 1,844 triangles, solved to the 3 mm scan depth, meshes cold) took
#: 2.1-4.0 s over nine runs on the shared two-core machine, 0.054-0.10 ms per triangle-step, median 0.068 ms;
#: 1.5x the median, rounded.
SECONDS_PER_FE_WORK = 0.1e-3
#: FE work (triangles x steps, summed over the meshes tried): 9 s at the rate above, three of the graded meshes
#: (all four of the schedule's FE_MESHES_MM, 101k, are refused: no spec needs them). MagOne runs 1 and 0.75 mm at 1 %
#: (2,030 estimated triangles, 43k triangle-steps, ~4 s).
MAX_FE_WORK = 90_000
MB_PER_FE_TRIANGLE = 0.1  # 1,299 triangles: 221 MB peak, with ~100 MB of Python and numpy

# ---- an array's board ----------------------------------------------------------------------------------
#: Routing the breakout board grows faster than its chips: every connection of the bus searches a board that grows
#: with them, and a dense grid rips up and re-routes. Measured (CPU s of pcb.board, preflight's board, 14 mm pitch,
#: the two-core machine under a load of 8-15): 1 chip 0.48 s, 2 (1x2) 2.79, 4 (2x2) 15.1, 5 (1x5) 7.24, 8 (2x4) 27.9,
#: 9 (3x3) 18.9; 16 (4x4) over 300 s of wall time (73 s in the issue's run, 41 s on a quieter machine). A least-squares
#: fit of log t on log N gives t = 0.675 N^1.71 (measured/fitted 0.66-2.09, the compact 2x2 the worst: its rip-ups);
#: adding the board's area gave t ~ N^0.43 (N/A)^3.1 over six noisy points, an over-fit we do not use. The estimate is
#: the fit's power with its constant raised to bound every measurement: 1.45 N^1.7 (measured/estimated 0.31-0.98).
SECONDS_PER_CHIP_POWER = 1.45
CHIP_EXPONENT = 1.7
#: The board's share of the budget: all of it but the fixed part; the whole-budget check (routing counted beside
#: the other parts) refuses most arrays past six to eight chips first.
MAX_BOARD_S = 50.0


def routing_s(chips: int) -> float:
    """Estimated seconds to route an array's board of ``chips`` MLX90393s (0 for a single taxel: in FIXED_S)."""
    return SECONDS_PER_CHIP_POWER * chips**CHIP_EXPONENT if chips > 1 else 0.0


def most_chips(seconds: float) -> int:
    """The most chips whose board routes within ``seconds``."""
    return max(1, int((max(seconds, 0.0) / SECONDS_PER_CHIP_POWER) ** (1.0 / CHIP_EXPONENT)))


# ---- calibration ----------------------------------------------------------------------------------------
#: Rows of the simulated scan (field, force, the polynomial fits, the CSV in the build): linear and cheap, but
#: each row is an exact-field evaluation and a CSV line. MagOne: 2,673 rows (at most 4,941 by the spec's
#: steps).
MAX_SCAN_ROWS = 40_000
SECONDS_PER_SCAN_ROW = 2.5e-4
#: MLS cross-validation grows with rows^2 (11 bandwidths x the folds). The MLS candidate of the 4,941-row scan of
#: MagOne with mechanics_model = "hertz_column" (whose scan fills its bound) took 46.6 s before MLS was computed from
#: weighted moments and 7.2 s after (2,500 rows: 13.0 and 2.1 s), both in one run on the two-core machine under load:
#: 0.29-0.33 us per row^2, where the estimate had 1.2 and that build took 61-72 s against 46 estimated. 0.5 us keeps a
#: 1.5x margin; the row count is an upper bound (MagOne: 4,941 by its steps, 2,673 in fact), which is more margin.
SECONDS_PER_MLS_ROW2 = 0.5e-6
MAX_MLS_ROWS = 5_000
MB_PER_SCAN_ROW = 0.01


@dataclass(frozen=True)
class Cost:
    """What a build of a design is estimated to need, before any of the work: counts, and the time (s, two
    cores) and peak memory (MB) they imply."""

    triangles: int
    fe_meshes_mm: tuple[float, ...]
    fe_triangles: int  # summed over the meshes
    fe_peak_triangles: int  # the finest mesh's
    scan_rows: int
    mls: bool
    chips: int = 0  # an array's chips on its board (0: a single taxel)

    @property
    def fe_work(self) -> int:
        return self.fe_triangles * FE_STEPS

    @property
    def parts_s(self) -> dict[str, float]:
        """Estimated seconds per cost driver (the fixed part excluded)."""
        mls = SECONDS_PER_MLS_ROW2 * self.scan_rows**2 if self.mls else 0.0
        return {"tessellation": SECONDS_PER_TRIANGLE * self.triangles, "fe": SECONDS_PER_FE_WORK * self.fe_work,
                "calibration": SECONDS_PER_SCAN_ROW * self.scan_rows + mls, "routing": routing_s(self.chips)}

    @property
    def seconds(self) -> float:
        return FIXED_S + sum(self.parts_s.values())

    @property
    def megabytes(self) -> float:
        return (FIXED_MB + MB_PER_TRIANGLE * self.triangles + MB_PER_FE_TRIANGLE * self.fe_peak_triangles
                + MB_PER_SCAN_ROW * self.scan_rows)


# ---- the estimates --------------------------------------------------------------------------------------


#: More facets round a circle than any limit lets through (what a tolerance too fine to compute is counted as).
MAX_FACETS = 1e12


def facets(radius_mm: float, tolerance_mm: float, angle_deg: float) -> float:
    """Facets round a full circle of ``radius_mm`` meshed within ``tolerance_mm`` of it and ``angle_deg``
    between neighbouring facets' normals: the kernel honours both, so the finer of the two."""
    by_angle = 360.0 / angle_deg
    if tolerance_mm >= radius_mm:
        return max(by_angle, 3.0)
    # acos(1 - x) as 2 asin(sqrt(x / 2)): exact where 1 - x rounds to 1 (x below 1e-16 gave acos(1) = 0 and a division
    # by zero); capped where even that underflows, far past any limit.
    half_angle = 2.0 * math.asin(math.sqrt(tolerance_mm / radius_mm / 2.0))
    # capped: a subnormal tolerance's pi / half_angle squared would overflow the triangle count
    return min(max(by_angle, math.pi / half_angle if half_angle > 0.0 else MAX_FACETS, 3.0), MAX_FACETS)


def triangles(design: Design) -> int:
    """Surface triangles over the four parts' STLs (model in the module doc; constants above)."""
    m = design.spec.mould
    tol, ang = m.tessellation_tolerance_mm, m.angular_tolerance_deg
    n_dome = facets(design.elastomer_radius_mm, tol, ang)
    n_small = facets(1.0, tol, ang)
    copies = (design.cavities + 1) * len(design.part_centres_mm)  # every dome: the part's and each cavity's
    dome = DOME_TRIANGLES * copies * n_dome**2 if design.tip.value == "hemisphere" else RIM_TRIANGLES * copies * n_dome
    return int(dome + SMALL_FEATURE_TRIANGLES * n_small * (copies + len(design.taxels) - 1) / 2.0)


def _profile_area_mm2(design: Design) -> float:
    """Area of the elastomer's (r, z) half-profile less the magnet's, mm^2: what the axisymmetric FE meshes."""
    R, hb = design.elastomer_radius_mm, design.base_height_mm
    area = R * hb + (math.pi * R * R / 4.0 if design.tip.value == "hemisphere" else 0.0)
    return max(area - design.magnet_radius_mm * design.magnet_height_mm, 0.0)


def fe_triangles(design: Design, mesh_mm: float) -> int:
    return int(FE_TRIANGLES_PER_AREA_H2 * _profile_area_mm2(design) / (mesh_mm * mesh_mm)) + FE_EDGE_TRIANGLES


def scan_rows(design: Design) -> int:
    """The most rows the simulated scan can have: the spec's y and z extents over the step, y capped at the
    magnet's radius each side (the lateral range never exceeds it) and z at 1.25 x the travel to d_min (the
    end of the predicted normal curve); see :func:`magfab.models.scan.scan_track`."""
    cal, sen = design.spec.calibration, design.spec.sensor
    step = cal.scan_step_mm
    half = min(cal.scan_y_mm / 2.0, design.magnet_radius_mm)
    z = min(cal.scan_z_mm, 1.25 * max(design.d_rest_mm - sen.d_min_mm, 0.0))
    return (math.floor(2.0 * half / step + 1e-9) + 1) * (math.floor(z / step + 1e-9) + 1)


def estimate(design: Design) -> Cost:
    """The cost of building ``design`` (module doc), without doing any of the work."""
    meshes = fe_meshes(design)
    return Cost(
        triangles=triangles(design),
        fe_meshes_mm=meshes,
        fe_triangles=sum(fe_triangles(design, h) for h in meshes),
        fe_peak_triangles=fe_triangles(design, min(meshes)) if meshes else 0,
        scan_rows=scan_rows(design),
        mls=design.spec.calibration.method.value in ("mls", "auto"),
        chips=(len(design.taxels) + (design.spec.reference is not None)) if design.spec.array is not None else 0,
    )


# ---- the limits -----------------------------------------------------------------------------------------


def _round_up(x: float) -> float:
    """x rounded up to two significant digits (a value a user can type that is on the right side)."""
    if x <= 0:
        return x
    e = math.floor(math.log10(x)) - 1
    return math.ceil(x / 10**e - 1e-9) * 10**e


def check_limits(design: Design) -> Cost:
    """Raise :class:`SpecError` for the first estimate past its limit (naming the key to change and the value
    that would fit); return the estimate otherwise."""

    spec = design.spec
    cost = estimate(design)
    m = spec.mould
    if cost.triangles > MAX_TRIANGLES:
        knobs = [("mould.angular_tolerance_deg", "angular_tolerance_deg", 0.5, 45.0),
                 ("mould.tessellation_tolerance_mm", "tessellation_tolerance_mm", 1e-9, 1.0)]
        if 360.0 / m.angular_tolerance_deg < facets(design.elastomer_radius_mm, m.tessellation_tolerance_mm, 360.0):
            knobs.reverse()  # blame first the key whose own facet count is the finer
        what = f"would need about {_fmt(cost.triangles)} triangles (limit {_fmt(MAX_TRIANGLES)})"
        for key, name, lo, hi in knobs:
            need = _bisect(lambda x, name=name: triangles(_with(design, mould=m.model_copy(update={name: x}))), lo, hi)
            if need is not None:
                raise SpecError(key, getattr(m, name), what, f"raise {key} to at least {_fmt(_round_up(need))}")
        # neither alone: the kernel honours the finer of the two, so both coarsen together, each along its own range
        # (geometrically, from its value to its coarsest) by one shared share
        def both(share: float) -> dict[str, float]:
            return {name: _round_up(max(getattr(m, name), lo) * (hi / max(getattr(m, name), lo)) ** share)
                    for _, name, lo, hi in knobs}

        share = _bisect(lambda x: triangles(_with(design, mould=m.model_copy(update=both(x)))), 0.0, 1.0)
        if share is not None:
            coarser = both(share)
            raise SpecError(knobs[0][0], getattr(m, knobs[0][1]), what, " and ".join(
                f"raise {key} to at least {_fmt(coarser[name])}" for key, name, _, _ in knobs))
        if design.cavities > 1:
            raise SpecError("mould.cavities", design.cavities, what, "use fewer cavities per mould")
        raise SpecError("array.rows", design.spec.array.rows if design.spec.array else 1, what,
                        "fewer taxels: even the coarsest tolerances leave too many domes to mesh")
    if routing_s(cost.chips) > MAX_BOARD_S:
        _too_many_chips(design, cost, MAX_BOARD_S, f"limit {MAX_BOARD_S:g} s")
    if cost.fe_work > MAX_FE_WORK:
        p = spec.predict
        finest_ok = [h for h in cost.fe_meshes_mm if sum(fe_triangles(design, g) for g in cost.fe_meshes_mm
                                                         if g >= h) * FE_STEPS <= MAX_FE_WORK]
        if len(finest_ok) >= 2:
            need = 100.0 * FE_ERROR_PER_H_OVER_R * min(finest_ok) / design.elastomer_radius_mm
            raise SpecError("predict.tolerance_pct", p.tolerance_pct,
                            f"would need FE meshes down to {min(cost.fe_meshes_mm):g} mm on this "
                            f"{_fmt(design.elastomer_radius_mm * 2)} mm elastomer, about {_fmt(cost.fe_work)} "
                            f"element-steps (limit {_fmt(MAX_FE_WORK)})",
                            f"raise predict.tolerance_pct to at least {_fmt(_round_up(need))}")
        key = ("elastomer.height_mm" if design.elastomer_height_mm >= design.elastomer_radius_mm * 2
               else "elastomer.diameter_mm")
        raise SpecError(key, getattr(spec.elastomer, key.split(".")[1]),
                        f"is too large for the FE model: about {_fmt(cost.fe_work)} element-steps even on the "
                        f"coarsest meshes (limit {_fmt(MAX_FE_WORK)})",
                        "use a smaller elastomer, or predict.mechanics_model = \"hertz_column\"")
    cal = spec.calibration
    limit_rows = MAX_MLS_ROWS if cost.mls else MAX_SCAN_ROWS
    if cost.scan_rows > limit_rows:
        need = _bisect(lambda s: scan_rows(_with(design, calibration=cal.model_copy(update={"scan_step_mm": s}))),
                       1e-9, 5.0, limit=limit_rows)
        why = f" with calibration.method = {cal.method.value!r} (moving least squares grows with rows squared)" \
            if cost.mls else ""
        fix = f"raise calibration.scan_step_mm to at least {_fmt(_round_up(need))}" if need is not None else \
            "shrink calibration.scan_y_mm and scan_z_mm"
        if cost.mls:
            fix += ", or use calibration.method = \"poly\""
        raise SpecError("calibration.scan_step_mm", cal.scan_step_mm,
                        f"would give a scan of up to {_fmt(cost.scan_rows)} rows{why} (limit {_fmt(limit_rows)})", fix)
    if cost.seconds > BUDGET_S or cost.megabytes > BUDGET_MB:
        _over_budget(design, cost)
    return cost


#: For the whole-budget check: the key that drives each part, its range and which way is cheaper.
_KNOBS = {
    "tessellation": ("mould", "tessellation_tolerance_mm", 1e-9, 1.0),
    "fe": ("predict", "tolerance_pct", 1e-9, 50.0),
    "calibration": ("calibration", "scan_step_mm", 1e-9, 5.0),
}


def _too_many_chips(design: Design, cost: Cost, seconds: float, limit: str) -> None:
    """Refuse an array whose board's routing is estimated past ``seconds``, naming the key that sets its taxels."""
    array = design.spec.array
    assert array is not None
    key = "array.rows" if array.positions_mm is None else "array.positions_mm"
    raise SpecError(key, getattr(array, key.split(".")[1]),
                    f"makes {cost.chips} chips, whose board would take about {routing_s(cost.chips):.0f} s to route "
                    f"({limit})", f"use at most {most_chips(seconds)} taxels per array")


def _over_budget(design: Design, cost: Cost) -> None:
    """Each part is within its own limit but together they are not: blame the costliest part's key."""
    part = max(cost.parts_s, key=lambda k: cost.parts_s[k])
    if part == "routing":
        rest = cost.seconds - cost.parts_s["routing"]
        _too_many_chips(design, cost, BUDGET_S - rest,
                        f"{cost.seconds:.0f} s for the whole build, budget {BUDGET_S:g} s")
    section, name, lo, hi = _KNOBS[part]
    current = getattr(getattr(design.spec, section), name)

    def total(x: float) -> float:
        c = estimate(_with(design, **{section: getattr(design.spec, section).model_copy(update={name: x})}))
        return max(c.seconds / BUDGET_S, c.megabytes / BUDGET_MB)

    need = None
    if total(hi) <= 1.0:
        for _ in range(60):
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if total(mid) <= 1.0 else (mid, hi)
        need = hi
    fix = f"raise {section}.{name} to at least {_fmt(_round_up(need))}" if need is not None else \
        "relax the other cost keys (mould tolerances, predict.tolerance_pct, calibration.scan_step_mm)"
    raise SpecError(f"{section}.{name}", current,
                    f"the build would need about {cost.seconds:.0f} s and {cost.megabytes:.0f} MB (budget "
                    f"{BUDGET_S:g} s, {BUDGET_MB:g} MB), {cost.parts_s[part]:.0f} s of it for the {part}", fix)


def _with(design: Design, **sections: object) -> Design:
    return replace(design, spec=design.spec.model_copy(update=sections))


def _bisect(count, lo: float, hi: float, limit: int = MAX_TRIANGLES) -> float | None:
    """The smallest x in [lo, hi] with count(x) <= limit (count falls as x grows), or None if even hi is over."""
    if count(hi) > limit:
        return None
    for _ in range(60):
        mid = math.sqrt(lo * hi) if lo > 0 else (lo + hi) / 2.0
        if count(mid) <= limit:
            hi = mid
        else:
            lo = mid
    return hi


def check_scan(spec: Spec, scan) -> None:
    """A measured scan the spec's calibration can afford: moving least squares grows with rows squared, so a
    scan calibrated with ``calibration.method`` "mls" or "auto" may have at most :data:`MAX_MLS_ROWS` rows, and
    any scan at most :data:`MAX_SCAN_ROWS`. :class:`~magfab.errors.ScanError` before any work otherwise."""
    method = spec.calibration.method.value
    if method != "poly" and scan.rows > MAX_MLS_ROWS:
        raise ScanError(f"scan {scan.source}: {scan.rows:,} rows; calibration.method = {method!r} fits moving least "
                        f"squares, whose cost grows with rows squared: at most {MAX_MLS_ROWS:,} rows (thin the scan, "
                        "or set calibration.method = \"poly\")")
    if scan.rows > MAX_SCAN_ROWS:
        raise ScanError(f"scan {scan.source}: {scan.rows:,} rows; at most {MAX_SCAN_ROWS:,} (thin the scan)")
