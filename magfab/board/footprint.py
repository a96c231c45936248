"""Land patterns drawn to the KiCad Library Conventions from package data, with lands sized by the
IPC-7351B calculator (:mod:`magfab.board.ipc`), and written as KiCad 6 footprints (``.kicad_mod``).

Coordinates are in millimetres in KiCad's footprint frame: x to the right, y *down*, origin at the
package centre, pin 1 at the top left. The lands of a QFN also keep ``ep_pad_clearance`` from the
exposed pad.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace

from ..formats.sexpr import Sym, at, render, xy
from ..recipes import Recipe, catalogue
from ..spec import Density
from .ipc import Band, Land, ipc_land

__all__ = [
    "Density", "Band", "Land", "Pad", "Line", "Poly", "Text", "Footprint", "flip_layer",
    "ipc_land", "qfn_footprint", "chip_footprint", "connector_footprint", "hole_footprint",
]

FOOTPRINT_VERSION = 20211014  # KiCad 6.0 file format


# ---------------------------------------------------------------------------------------------------
# Footprint primitives


@dataclass(frozen=True)
class Pad:
    """One pad. ``kind`` is smd / thru_hole / np_thru_hole; ``shape`` roundrect / rect / circle."""

    number: str
    x: float
    y: float
    w: float
    h: float
    layers: tuple[str, ...] = ("F.Cu", "F.Paste", "F.Mask")
    kind: str = "smd"
    shape: str = "roundrect"
    rratio: float = 0.0
    drill: float = 0.0

    @property
    def copper(self) -> bool:
        return any(layer.endswith(".Cu") for layer in self.layers)

    def box(self) -> tuple[float, float, float, float]:
        return (self.x - self.w / 2, self.y - self.h / 2, self.x + self.w / 2, self.y + self.h / 2)


@dataclass(frozen=True)
class Line:
    x1: float
    y1: float
    x2: float
    y2: float
    layer: str
    width: float


@dataclass(frozen=True)
class Poly:
    points: tuple[tuple[float, float], ...]
    layer: str
    width: float
    fill: bool = True


@dataclass(frozen=True)
class Circle:
    x: float
    y: float
    r: float
    layer: str
    width: float


@dataclass(frozen=True)
class Text:
    kind: str  # reference / value / user
    text: str
    x: float
    y: float
    layer: str
    size: float
    thickness: float


@dataclass(frozen=True)
class Footprint:
    """A footprint in its own frame; :meth:`library_text` renders the ``.kicad_mod`` file."""

    name: str
    descr: str
    tags: str
    attr: str
    pads: tuple[Pad, ...]
    lines: tuple[Line, ...] = ()
    polys: tuple[Poly, ...] = ()
    circles: tuple[Circle, ...] = ()
    texts: tuple[Text, ...] = ()
    courtyard: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    body: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    height_mm: float = 0.0
    sources: Mapping[str, str] = field(default_factory=dict)

    def copper_pads(self) -> tuple[Pad, ...]:
        return tuple(p for p in self.pads if p.copper)

    def nodes(self, *, reference: str = "REF**", angle: float = 0.0, nets: Mapping[str, tuple[int, str]] | None = None,
              bottom: bool = False) -> list[tuple]:
        """Children of the ``footprint`` node. On the bottom side layers flip and y mirrors (KiCad's flip)."""
        side = flip_layer if bottom else (lambda layer: layer)
        my = -1.0 if bottom else 1.0
        out: list[tuple] = []
        for t in self.texts:
            text = reference if t.kind == "reference" else t.text
            effects: tuple = ("effects", ("font", ("size", t.size, t.size), ("thickness", t.thickness)))
            if bottom:
                effects = (*effects, ("justify", Sym("mirror")))
            out.append(("fp_text", Sym(t.kind), text, at(t.x, my * t.y, angle), ("layer", side(t.layer)), effects))
        for ln in self.lines:
            out.append(("fp_line", ("start", ln.x1, my * ln.y1), ("end", ln.x2, my * ln.y2),
                        ("layer", side(ln.layer)), ("width", ln.width)))
        for c in self.circles:
            out.append(("fp_circle", ("center", c.x, my * c.y), ("end", c.x + c.r, my * c.y),
                        ("layer", side(c.layer)), ("width", c.width), ("fill", Sym("none"))))
        for pg in self.polys:
            out.append(("fp_poly", ("pts", *(xy(x, my * y) for x, y in pg.points)), ("layer", side(pg.layer)),
                        ("width", pg.width), ("fill", Sym("solid" if pg.fill else "none"))))
        for p in self.pads:
            node: tuple = ("pad", p.number, Sym(p.kind), Sym(p.shape), at(p.x, my * p.y, angle), ("size", p.w, p.h))
            if p.drill:
                node += (("drill", p.drill),)
            node += (("layers", *(side(layer) for layer in p.layers)),)
            if p.shape == "roundrect":
                node += (("roundrect_rratio", p.rratio),)
            if nets is not None and p.number in nets and p.copper:
                code, name = nets[p.number]
                node += (("net", code, name),)
            out.append(node)
        return out

    def library_text(self) -> str:
        """The ``.kicad_mod`` file: deterministic, KiCad 6 format."""
        node = ("footprint", self.name, ("version", FOOTPRINT_VERSION), ("generator", Sym("magfab")),
                ("layer", "F.Cu"), ("descr", self.descr), ("tags", self.tags), ("attr", Sym(self.attr)),
                *self.nodes())
        return render(node, wrap=("footprint",)) + "\n"


def flip_layer(layer: str) -> str:
    """The layer a footprint's item lands on when the footprint is flipped to the other side (KiCad's flip)."""
    if layer.startswith("F."):
        return "B." + layer[2:]
    if layer.startswith("B."):
        return "F." + layer[2:]
    return layer


# ---------------------------------------------------------------------------------------------------
# House rules shared by every footprint


@dataclass(frozen=True)
class _Rules:
    klc: Recipe
    tol: Recipe

    def q(self, name: str) -> float:
        return self.klc[name].nominal

    def radius_ratio(self, w: float, h: float) -> float:
        """Roundrect ratio: 25 % of the short side, the radius capped at ``roundrect_max_radius_mm``."""
        ratio = self.q("roundrect_ratio")
        r = min(ratio * min(w, h), self.q("roundrect_max_radius_mm"))
        return round(r / min(w, h), 6)


def _rules() -> _Rules:
    land = catalogue("land")
    return _Rules(land["klc"], land["tolerances"])


def _out(x: float, grid: float) -> float:
    """Round away from zero onto ``grid`` (courtyards grow, never shrink)."""
    return round(math.copysign(math.ceil(abs(x) / grid - 1e-9) * grid, x), 6)


def _courtyard(pads: Iterable[Pad], body: tuple[float, float, float, float], excess: float, grid: float):
    boxes = [p.box() for p in pads] + [body]
    x0 = min(b[0] for b in boxes) - excess
    y0 = min(b[1] for b in boxes) - excess
    x1 = max(b[2] for b in boxes) + excess
    y1 = max(b[3] for b in boxes) + excess
    return (_out(x0, grid), _out(y0, grid), _out(x1, grid), _out(y1, grid))


def _rect_lines(box: tuple[float, float, float, float], layer: str, width: float) -> tuple[Line, ...]:
    x0, y0, x1, y1 = box
    return (Line(x0, y0, x1, y0, layer, width), Line(x1, y0, x1, y1, layer, width),
            Line(x1, y1, x0, y1, layer, width), Line(x0, y1, x0, y0, layer, width))


def _texts(rules: _Rules, name: str, courtyard, body) -> tuple[Text, ...]:
    gap = rules.q("text_courtyard_gap_mm")
    size, stroke = rules.q("reference_text_mm"), rules.q("reference_stroke_mm")
    short = min(body[2] - body[0], body[3] - body[1])
    fab = min(rules.q("fab_text_max_mm"), max(rules.q("fab_text_min_mm"), round(short / 4, 2)))
    cx = round((body[0] + body[2]) / 2, 6)
    cy = round((body[1] + body[3]) / 2, 6)
    return (
        Text("reference", "REF**", cx, round(courtyard[1] - gap, 6), "F.SilkS", size, stroke),
        Text("value", name, cx, round(courtyard[3] + gap, 6), "F.Fab", size, stroke),
        Text("user", "${REFERENCE}", cx, cy, "F.Fab", fab, round(0.15 * fab, 2)),
    )


def _fab_outline(rules: _Rules, body) -> tuple[Line, ...]:
    """Body outline on F.Fab with the pin-1 chamfer at the top-left corner (KLC F5.2)."""
    x0, y0, x1, y1 = body
    bevel = min(rules.q("fab_bevel_max_mm"), rules.q("fab_bevel_fraction") * min(x1 - x0, y1 - y0))
    w, layer = rules.q("fab_line_mm"), "F.Fab"
    return (Line(x0 + bevel, y0, x1, y0, layer, w), Line(x1, y0, x1, y1, layer, w), Line(x1, y1, x0, y1, layer, w),
            Line(x0, y1, x0, y0 + bevel, layer, w), Line(x0, y0 + bevel, x0 + bevel, y0, layer, w))


# ---------------------------------------------------------------------------------------------------
# QFN


def qfn_footprint(chip: Recipe, density: Density = Density.NOMINAL, *, name: str | None = None,
                  clearance: float = 0.0) -> Footprint:
    """The land pattern of a square QFN with an exposed pad, from the chip recipe's package bands.

    Pins are numbered counter-clockwise from the top left, as seen from above: one quarter down the
    left side, then along the bottom, up the right side and back along the top; the exposed pad is
    the last number.

    ``clearance`` is the board's copper clearance (mm): where it exceeds the house gap between the
    lands and the exposed pad, the exposed-pad land shrinks (the chip's own pad does not), so the
    board's rule holds inside the footprint too.
    """
    rules = _rules()
    goals = catalogue("land")[f"qfn-{density.value}"]
    body_band = Band.of(chip["body_mm"])
    term = Band.of(chip["terminal_length_mm"])
    width = Band.of(chip["terminal_width_mm"])
    ep = chip["exposed_pad_mm"].nominal
    pitch = chip["pitch_mm"].nominal
    pins = sorted(int(k[4:]) for k in chip.texts if k.startswith("pin_") and k[4:].isdigit())
    per_side = len(pins) // 4
    land = ipc_land(body_band, term, width, goals, rules.tol)
    g_min = max(land.g_min, ep + 2 * rules.tol["ep_pad_clearance_mm"].nominal)
    land = replace(land, g_min=g_min)
    length, centre, w = round(land.length, 6), round(land.centre, 6), land.x_max
    ep_land = ep
    if g_min - ep < 2 * clearance:
        ep_land = round(math.floor((g_min - 2 * clearance) / 0.01 + 1e-9) * 0.01, 6)
    ratio = rules.radius_ratio(length, w)
    pads: list[Pad] = []
    offsets = [round((i - (per_side - 1) / 2) * pitch, 6) for i in range(per_side)]
    for side in range(4):
        for i, off in enumerate(offsets):
            n = side * per_side + i + 1
            if side == 0:
                x, y, pw, ph = -centre, off, length, w
            elif side == 1:
                x, y, pw, ph = off, centre, w, length
            elif side == 2:
                x, y, pw, ph = centre, -off, length, w
            else:
                x, y, pw, ph = -off, -centre, w, length
            pads.append(Pad(str(n), x, y, pw, ph, rratio=ratio))
    ep_number = str(len(pins) + 1)
    pads.append(Pad(ep_number, 0.0, 0.0, ep_land, ep_land, layers=("F.Cu", "F.Mask"), shape="rect"))
    pads.extend(_paste_grid(ep_land, rules))

    half = body_band.nominal / 2
    body = (-half, -half, half, half)
    courtyard = _courtyard(pads, body, goals["courtyard_mm"].nominal, rules.q("courtyard_grid_mm"))
    silk = _qfn_silk(rules, half, offsets[-1] + w / 2, centre + length / 2)
    fp_name = name or (f"QFN-{len(pins)}-1EP_{_mm(body_band.nominal)}x{_mm(body_band.nominal)}mm_P{_mm(pitch)}mm"
                       f"_EP{_mm(ep)}x{_mm(ep)}mm")
    descr = (f"{chip.name}: QFN-{len(pins)} {_mm(body_band.nominal)} mm, {_mm(pitch)} mm pitch, IPC-7351B "
             f"density {density.value}, lands {_mm(length)} x {_mm(w)} mm at +/-{_mm(centre)} mm"
             + (f", exposed-pad land {_mm(ep_land)} mm for a {_mm(clearance)} mm clearance" if ep_land != ep else "")
             + "; generated by magfab")
    sources = {k: chip[k].source for k in ("body_mm", "pitch_mm", "terminal_length_mm", "terminal_width_mm",
                                           "exposed_pad_mm")}
    sources["ipc"] = goals.name
    return Footprint(
        name=fp_name, descr=descr, tags="QFN NoLead MLX90393 magnetometer", attr="smd", pads=tuple(pads),
        lines=_rect_lines(courtyard, "F.CrtYd", rules.q("courtyard_line_mm")) + _fab_outline(rules, body) + silk[0],
        polys=silk[1], texts=_texts(rules, fp_name, courtyard, body), courtyard=courtyard, body=body,
        height_mm=chip["height_mm"].high, sources=sources,
    )


def _mm(x: float) -> str:
    return f"{x:g}"


def _paste_grid(ep: float, rules: _Rules, n: int = 2) -> list[Pad]:
    """Paste apertures on the exposed pad: an n x n grid covering ``ep_paste_coverage`` of its area."""
    coverage = rules.tol["ep_paste_coverage"].nominal
    size = round(ep * math.sqrt(coverage) / n, 2)
    step = round(size + (ep - n * size) / n, 2)
    ratio = rules.radius_ratio(size, size)
    out = []
    for j in range(n):
        for i in range(n):
            x = round((i - (n - 1) / 2) * step, 6)
            y = round((j - (n - 1) / 2) * step, 6)
            out.append(Pad("", x, y, size, size, layers=("F.Paste",), rratio=ratio))
    return out


def _qfn_silk(rules: _Rules, half: float, pin_row_half: float, land_outer: float):
    """Corner marks just outside the body, stopping ``silk_pad_clearance`` short of the lands, and a
    filled pin-1 arrow above the top-left corner pointing down the pin-1 column."""
    w = rules.q("silk_line_mm")
    s = round(half + rules.q("silk_body_offset_mm"), 6)
    end = round(pin_row_half + rules.q("silk_pad_clearance_mm") + w / 2, 6)
    lines: list[Line] = []
    if end < s:
        for sx in (-1, 1):
            for sy in (-1, 1):
                lines.append(Line(sx * end, sy * s, sx * s, sy * s, "F.SilkS", w))
                if not (sx < 0 and sy < 0):  # the pin-1 corner keeps only its top stroke
                    lines.append(Line(sx * s, sy * s, sx * s, sy * end, "F.SilkS", w))
    # Arrow tip just above the silk corner, over the pin-1 land column; clear of every land.
    tip_x, tip_y = -land_outer, -(s + w / 2 + 0.05)
    a = 0.3
    arrow = Poly(((tip_x, tip_y), (tip_x - a / 2, tip_y - a), (tip_x + a / 2, tip_y - a)), "F.SilkS", w)
    return tuple(lines), (arrow,)


# ---------------------------------------------------------------------------------------------------
# Two-terminal chips, the Qwiic connector and holes


def chip_footprint(part: Recipe, density: Density = Density.NOMINAL, *, prefix: str = "C") -> Footprint:
    """A 0603-style two-terminal chip land pattern along x (pads ``1`` at -x, ``2`` at +x)."""
    rules = _rules()
    goals = catalogue("land")[f"chip-{density.value}"]
    length = Band.of(part["body_length_mm"])
    width = Band.of(part["body_width_mm"])
    term = Band.of(part["terminal_length_mm"])
    land = ipc_land(length, term, width, goals, rules.tol)
    plen, centre, w = round(land.length, 6), round(land.centre, 6), land.x_max
    ratio = rules.radius_ratio(plen, w)
    pads = (Pad("1", -centre, 0.0, plen, w, rratio=ratio), Pad("2", centre, 0.0, plen, w, rratio=ratio))
    body = (-length.nominal / 2, -width.nominal / 2, length.nominal / 2, width.nominal / 2)
    courtyard = _courtyard(pads, body, goals["courtyard_mm"].nominal, rules.q("courtyard_grid_mm"))
    fab_w = rules.q("fab_line_mm")
    # Silk: two lines along the long sides, between the pads, clear of them.
    sw = rules.q("silk_line_mm")
    sy = round(w / 2 + rules.q("silk_pad_clearance_mm") + sw / 2, 6)
    sx = round(centre - plen / 2 - rules.q("silk_pad_clearance_mm") - sw / 2, 6)
    silk = (Line(-sx, -sy, sx, -sy, "F.SilkS", sw), Line(-sx, sy, sx, sy, "F.SilkS", sw)) if sx > 0.1 else ()
    metric = f"{round(length.nominal * 10):02d}{round(width.nominal * 10):02d}"
    name = f"{prefix}_0603_{metric}Metric"
    return Footprint(
        name=name, descr=f"{part.name}; IPC-7351B density {density.value}; generated by magfab",
        tags="capacitor resistor 0603", attr="smd", pads=pads,
        lines=(_rect_lines(courtyard, "F.CrtYd", rules.q("courtyard_line_mm")) + _rect_lines(body, "F.Fab", fab_w)
               + silk),
        texts=_texts(rules, name, courtyard, body), courtyard=courtyard, body=body,
        height_mm=part["height_mm"].nominal, sources={k: part[k].source for k in part.quantities},
    )


def connector_footprint(part: Recipe, circuits: int = 4) -> Footprint:
    """JST SH side-entry connector on the maker's recommended land; the mating face points to +y."""
    rules = _rules()
    q = lambda k: part[k].nominal
    pitch = q("pitch_mm")
    sr = rules.radius_ratio(q("signal_pad_width_mm"), q("signal_pad_length_mm"))
    mr = rules.radius_ratio(q("mount_pad_width_mm"), q("mount_pad_length_mm"))
    pads = [Pad(str(i + 1), round((i - (circuits - 1) / 2) * pitch, 6), q("signal_pad_y_mm"),
                q("signal_pad_width_mm"), q("signal_pad_length_mm"), rratio=sr) for i in range(circuits)]
    for sx in (-1, 1):
        pads.append(Pad("MP", sx * q("mount_pad_x_mm"), q("mount_pad_y_mm"), q("mount_pad_width_mm"),
                        q("mount_pad_length_mm"), rratio=mr))
    half = q("body_width_mm") / 2
    body = (-half, q("body_back_mm"), half, q("body_front_mm"))
    connector_excess = 0.5  # KLC F5.3: connectors take a 0.5 mm courtyard
    courtyard = _courtyard(pads, body, connector_excess, rules.q("courtyard_grid_mm"))
    name = f"JST_SH_SM{circuits:02d}B-SRSS-TB_1x{circuits:02d}-1MP_P1.00mm_Horizontal"
    fab = _fab_outline(rules, body)
    return Footprint(
        name=name, descr=f"{part.name}; maker's recommended land; generated by magfab",
        tags="connector JST SH Qwiic", attr="smd", pads=tuple(pads),
        lines=_rect_lines(courtyard, "F.CrtYd", rules.q("courtyard_line_mm")) + fab,
        texts=_texts(rules, name, courtyard, body), courtyard=courtyard, body=body,
        height_mm=q("height_mm"), sources={k: part[k].source for k in part.quantities},
    )


def hole_footprint(diameter: float, name: str, keepout: float) -> Footprint:
    """A non-plated hole (dowel pin or screw); ``keepout`` is the courtyard radius beyond the hole, mm."""
    rules = _rules()
    r = diameter / 2
    pad = Pad("", 0.0, 0.0, diameter, diameter, layers=("*.Cu", "*.Mask"), kind="np_thru_hole", shape="circle",
              drill=diameter)
    c = _out(r + keepout, rules.q("courtyard_grid_mm"))
    courtyard = (-c, -c, c, c)
    return Footprint(
        name=name, descr=f"non-plated hole {_mm(diameter)} mm; generated by magfab", tags="hole npth",
        attr="exclude_from_pos_files exclude_from_bom",
        pads=(pad,), circles=(Circle(0.0, 0.0, c, "F.CrtYd", rules.q("courtyard_line_mm")),
                              Circle(0.0, 0.0, r, "F.Fab", rules.q("fab_line_mm"))),
        texts=(Text("reference", "REF**", 0.0, round(-c - rules.q("text_courtyard_gap_mm"), 6), "F.Fab",
                    rules.q("reference_text_mm"), rules.q("reference_stroke_mm")),
               Text("value", name, 0.0, round(c + rules.q("text_courtyard_gap_mm"), 6), "F.Fab",
                    rules.q("reference_text_mm"), rules.q("reference_stroke_mm"))),
        courtyard=courtyard, body=(-r, -r, r, r),
    )
