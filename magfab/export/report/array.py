"""The report's array section: the address map, each taxel's figures (the neighbours' field its chip reads at
rest, its calibration's held-out errors), the crosstalk budget's table and charts. Read from the files the build
writes (calibration/array.json, calibration/taxel_NN.json, array/crosstalk.json), so the page shows what ships."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from ...units import UT_PER_GAUSS
from ..checklist_array import ADDRESS_HEADER, address_rows

if TYPE_CHECKING:
    from ...design import Design
    from ...output import Artifact

__all__ = ["array_context"]

TAXEL_HEADER = ("taxel", "neighbours' field at rest Bx, By, Bz (G)", "own Bz at rest (G)",
                "held-out RMS Fz, Fr (mN)")


def _json(by_path: dict, path: str) -> dict | None:
    a = by_path.get(path)
    return None if a is None else json.loads(a.data)


def array_context(design: Design, artifacts: Sequence[Artifact], figures: Callable[[str], list]) -> dict | None:
    """What report.html.j2's array section shows, or None for a single taxel. ``figures(folder)``: the build's
    plots under a folder, as the report draws them."""
    if design.array is None:
        return None

    by_path = {a.path: a for a in artifacts}
    doc = _json(by_path, "calibration/array.json") or {}
    rows = []
    for t in design.taxels:
        taxel = doc["taxels"][t.index] if doc else None
        cal = _json(by_path, f"calibration/{taxel['calibration']}") if taxel else None
        offset = ", ".join(f"{v / UT_PER_GAUSS:+.1f}" for v in doc["offset_uT"][t.index]) if doc else "-"
        own = f"{doc['rest_uT'][t.index][2] / UT_PER_GAUSS:+.1f}" if doc else "-"
        err = (f"{1000 * cal['errors']['Fz_N']['rms_holdout']:.2f}, {1000 * cal['errors']['Fr_N']['rms_holdout']:.2f}"
               if cal and "errors" in cal else "-")
        rows.append((str(t.index), offset, own, err))
    crosstalk = _json(by_path, "array/crosstalk.json")
    arr = design.array
    summary = (f"{len(design.taxels)} taxels, {arr.skin.value} skin, {arr.polarity.value} polarity, pitch "
               f"{arr.pitch_mm:g} mm (the parts allow {arr.min_pitch_mm:g} mm); the host removes the neighbours' "
               "field at rest" + (" and the field of a moving neighbour" if doc.get("dynamic") else "")
               + " before each taxel's calibration (calibration/array.json).")
    return {"summary": summary, "address_header": ADDRESS_HEADER, "address_rows": address_rows(design),
            "taxel_header": TAXEL_HEADER, "taxel_rows": rows, "crosstalk": crosstalk, "figures": figures("array/")}
