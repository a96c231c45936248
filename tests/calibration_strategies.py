"""Hypothesis strategies for calibration.json documents whose numbers are each within the format's bounds but
combine badly ("values the validator accepts that the device cannot survive"): a thermal reference and
coefficients whose denominator 1 + a (T - T0) crosses zero inside the chip's range, tiny scales, huge centres,
coefficients that overflow float32 over the region, a tiny MLS bandwidth or far MLS points. Each strategy mixes
harmless draws with harmful ones, so the tests see both verdicts; and the sample of points (uT) at which an
accepted calibration must evaluate finite: the hull's vertices, the region's box corners clipped to it and an
interior grid."""

from __future__ import annotations

import math

from hypothesis import strategies as st

from magfab.readout.src.magfab_readout.calibration_json import AXES, THERMAL_MAX_PER_C, THERMAL_REFERENCE_C, monomials


def _log_uniform(lo_exp: float, hi_exp: float) -> st.SearchStrategy[float]:
    return st.floats(lo_exp, hi_exp).map(lambda e: 10.0 ** e)


@st.composite
def region(draw) -> dict:
    """A valid region: an ellipse's 8-point hull (convex, counter-clockwise) and its box, uT."""
    cz = draw(st.floats(-40000.0, 40000.0))
    hz = draw(st.floats(10.0, 20000.0))
    hr = draw(st.floats(10.0, 10000.0))
    cr = hr + draw(st.floats(0.0, 20000.0))  # Br >= 0 over the region: a magnitude
    hull = [[cz + hz * math.cos(2 * math.pi * k / 8), cr + hr * math.sin(2 * math.pi * k / 8)] for k in range(8)]
    return {"Bz_uT": [cz - hz, cz + hz], "Br_uT": [cr - hr, cr + hr], "hull": hull}


@st.composite
def thermal(draw, spoil: bool) -> dict:
    """T0 in the chip's range and a per axis within +/-THERMAL_MAX_PER_C: each in bounds; spoiled, the whole
    range of both (the denominator free to reach zero inside the range), else a drift of magnet and chip."""
    lo, hi = THERMAL_REFERENCE_C
    a = st.floats(-THERMAL_MAX_PER_C, THERMAL_MAX_PER_C) if spoil else st.floats(-0.003, 0.003)
    return {"reference_C": draw(st.floats(lo, hi)), "source": "recipe",
            "coefficient_per_C": {axis: draw(a) for axis in AXES}}


#: What :func:`calibration` spoils, one class per document ("none": every value sane, the document accepted).
SPOILS = ("none", "centre", "scale", "thermal", "coefficients", "mls bandwidth", "mls points")


@st.composite
def calibration(draw, max_order: int = 4, mls: bool = True) -> dict:
    """A calibration.json dict, every number individually valid; one class of :data:`SPOILS` drawn to combine
    badly (which a draw may still leave harmless), the rest sane."""
    spoil = draw(st.sampled_from(SPOILS if mls else SPOILS[:5]))
    order = draw(st.integers(0, max_order))
    terms = len(monomials(order))
    valid = draw(region())
    scaling = {}
    for name in ("Bz_uT", "Br_uT"):
        lo, hi = valid[name]
        centre, scale = (lo + hi) / 2, (hi - lo) / 2
        if spoil == "centre" and draw(st.booleans()):
            centre = draw(st.one_of(st.floats(-1e308, 1e308), _log_uniform(0, 308), _log_uniform(0, 308).map(
                lambda x: -x)))
        if spoil == "scale" and draw(st.booleans()):
            scale = draw(_log_uniform(-300, 6))
        scaling[name] = {"center": centre, "scale": scale}
    magnitude = draw(_log_uniform(-3, 300)) if spoil == "coefficients" else 1.0
    coefficients = {force: [draw(st.floats(-1.0, 1.0)) * magnitude for _ in range(terms)]
                    for force in ("Fz_N", "Fr_N")}
    doc = {
        "format": "magfab-calibration/1", "method": "poly", "order": order, "monomials": monomials(order),
        "scaling": scaling, "coefficients": coefficients, "shear_sign": draw(st.sampled_from([1, -1])),
        "direction_min_uT": draw(st.floats(0.0, 50.0)), "tare_N": {"Fz_N": 0.01, "Fr_N": -0.02},
        "valid_region": valid,
    }
    if spoil == "thermal" or draw(st.booleans()):
        doc["thermal"] = draw(thermal(spoil == "thermal"))
    if spoil.startswith("mls") or (mls and draw(st.booleans())):
        n = 6
        zlo, zhi = valid["Bz_uT"]
        rlo, rhi = valid["Br_uT"]
        far = draw(_log_uniform(0, 300)) if spoil == "mls points" else 1.0
        bandwidth = draw(_log_uniform(-300, -1)) if spoil == "mls bandwidth" else draw(st.floats(0.05, 2.0))
        doc["method"] = "mls"
        doc["mls"] = {"order": 1, "bandwidth": bandwidth,
                      "points": {"Bz_uT": [zlo + (zhi - zlo) * k / (n - 1) * far for k in range(n)],
                                 "Br_uT": [rlo + (rhi - rlo) * ((k * 3) % n) / (n - 1) for k in range(n)],
                                 "Fz_N": [0.1 * k for k in range(n)], "Fr_N": [0.05 * k for k in range(n)]}}
    return doc


def region_points(doc: dict) -> list[tuple[float, float]]:
    """(Bz, Br) uT in the valid region (box and hull): the hull's vertices inside the box, the box's corners
    inside the hull, and a 5 x 5 interior grid of the hull's bounding box, the points in the region kept."""
    valid = doc["valid_region"]
    hull = [tuple(p) for p in valid["hull"]]
    (zlo, zhi), (rlo, rhi) = valid["Bz_uT"], valid["Br_uT"]
    hz = (min(p[0] for p in hull), max(p[0] for p in hull))
    hr = (min(p[1] for p in hull), max(p[1] for p in hull))
    grid = [(hz[0] + (hz[1] - hz[0]) * a / 4, hr[0] + (hr[1] - hr[0]) * b / 4) for a in range(5) for b in range(5)]
    candidates = hull + [(z, r) for z in (zlo, zhi) for r in (rlo, rhi)] + grid

    def inside(q: tuple[float, float]) -> bool:
        tol = 1e-9 * max(hz[1] - hz[0], hr[1] - hr[0]) ** 2
        return (zlo <= q[0] <= zhi and rlo <= q[1] <= rhi
                and all((b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]) >= -tol
                        for a, b in zip(hull, hull[1:] + hull[:1])))

    return [q for q in candidates if inside(q)]
