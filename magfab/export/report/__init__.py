"""report.html: one self-contained page that ties a build together.

What a researcher opens first: the key figures, pictures of every part (a shaded view and a cut-away at
the axis plane, the assembled stack-up with its distances, the routed board), the predictions and their
plots, the chosen models and the calibration, the design checks by severity, every spec key, and every
file of the build with what it is for, linked by relative paths so the page works from the build folder.

Self-contained: every picture is a ``data:`` URI (PNG or SVG made here, or the build's own plot SVGs), so
the page loads nothing from anywhere; nothing from the spec, the findings or the file list is marked
safe in the template (``templates/report/report.html.j2``, autoescaped). Deterministic: the same inputs
give the same bytes (matplotlib with fixed SVG ids and no dates, no time stamps on the page).

The page is put together here from :mod:`.render3d` (part pictures), :mod:`.drawings` (the stack-up and
the board) and :mod:`.tables` (every table). matplotlib and scipy are imported inside the functions that
draw, so importing this package is cheap.
"""

from __future__ import annotations

import base64
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import TYPE_CHECKING, Any

import numpy as np

from ... import __version__
from ...errors import Finding
from ..firmware import measured_rate_for
from ..templating import render
from . import tables
from .array import array_context
from .drawings import board_svg, stackup_figure
from .drift import drift_context
from .render3d import PART_VIEWS, part_figure, section_loops
from .tables import href

if TYPE_CHECKING:
    import trimesh

    from ...board.layout import Board
    from ...design import Design
    from ...models.predict import Prediction
    from ...output import Artifact
    from ...spec import Spec

__all__ = ["render_report", "Figure", "part_figure", "stackup_figure", "board_svg", "section_loops",
           "REPORT_PATH", "BENCH_FILES"]

REPORT_PATH = "report.html"
#: The bench documents the report links at its top, when the build has them.
BENCH_FILES = (("checklist.html", "printable checklist with tick boxes"),
               ("checklist.md", "the same checklist as Markdown"),
               ("bom.csv", "bill of materials"))


@dataclass(frozen=True)
class Figure:
    """A picture on the page: ``src`` is a data: URI; ``links`` are (relative href, label) pairs."""

    id: str
    title: str
    caption: str
    src: str
    links: tuple[tuple[str, str], ...] = ()


def _data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def _svg_uri(data: bytes, where: str) -> str:
    """An SVG of our own (a plot) as a data: URI, after checking that it is an SVG document."""
    head = data.lstrip()[:200]
    if not (head.startswith(b"<?xml") or head.startswith(b"<svg")) or b"<svg" not in data[:2000]:
        raise ValueError(f"{where} is not an SVG document (it must start with '<?xml' or '<svg')")
    return _data_uri(data, "image/svg+xml")


# ---------------------------------------------------------------------------------------------------
# Figures from the build


def _plot_figures(artifacts: Sequence[Artifact], folder: str) -> list[Figure]:
    """The build's SVG plots under ``folder``, each linked to its SVG and PNG files."""
    paths = {a.path for a in artifacts}
    out = []
    for a in artifacts:
        if a.path.startswith(folder) and a.path.endswith(".svg"):
            stem = a.path[:-4]
            links = ((href(a.path), "SVG"),) + (((href(stem + ".png"), "PNG"),) if stem + ".png" in paths else ())
            caption = a.description.removesuffix(", SVG")
            out.append(Figure("fig-" + stem.replace("/", "-"), PurePosixPath(stem).name.replace("_", " "), caption,
                              _svg_uri(a.data, a.path), links))
    return out


def _part_figures(meshes: Mapping[str, trimesh.Trimesh], artifacts: Sequence[Artifact],
                  drawn: Mapping[str, bytes]) -> list[Figure]:
    """Each part whole and cut away (PNG; ``drawn``'s where it has the part's), with its size, volume and triangle
    count, linked to its files."""
    by_path = {a.path: a for a in artifacts}
    out = []
    for stem in [s for s in PART_VIEWS if s in meshes] + sorted(set(meshes) - set(PART_VIEWS)):
        mesh = meshes[stem]
        size = np.ptp(np.asarray(mesh.bounds), axis=0)
        stl = by_path.get(f"{stem}.stl")
        what = stl.description.removesuffix(", STL") if stl else stem
        caption = (f"{what}. Bounding box {size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} mm, "
                   f"volume {abs(float(mesh.volume)) / 1000:.3f} mL, {len(mesh.faces)} triangles"
                   f"{'' if mesh.is_watertight else ', NOT watertight'}.")
        links = tuple((href(p), p.rsplit('.', 1)[1].upper()) for p in (f"{stem}.stl", f"{stem}.step") if p in by_path)
        out.append(Figure(f"part-{stem}", PART_VIEWS.get(stem, (stem, ""))[0], caption,
                          _data_uri(drawn.get(stem) or part_figure(stem, mesh), "image/png"), links))
    return out


def _board_figure(design: Design, board: Board, artifacts: Sequence[Artifact]) -> Figure:
    """The routed board from above (SVG), linked to the KiCad board and project."""
    pcb_spec = design.spec.pcb
    pcb = f"pcb/{design.spec.name}.kicad_pcb"
    files = ((pcb, "KiCad board"), (f"pcb/{design.spec.name}.kicad_pro", "project"))
    links = tuple((href(p), label) for p, label in files if p in {a.path for a in artifacts})
    unrouted = f" Unrouted: {', '.join(board.unrouted)}." if board.unrouted else ""
    caption = (f"{pcb_spec.width_mm:g} x {pcb_spec.height_mm:g} mm, {board.thickness_mm:g} mm thick, I2C address "
               f"0x{board.address:02X}; top copper red, bottom copper blue (seen through the board), vias gold, "
               f"drilled holes white, the mounting pad's disc dashed (nothing but the chip stands inside it on top)."
               + unrouted)
    if design.array is not None:
        t = design.taxels
        caption = (f"{pcb_spec.width_mm:g} x {pcb_spec.height_mm:g} mm, {board.thickness_mm:g} mm thick, {len(t)} "
                   f"chips on one I2C bus at 0x{t[0].i2c_address:02X}-0x{t[-1].i2c_address:02X} (each marked T<taxel> "
                   "<address> beside it); top copper red, bottom copper blue (seen through the board), vias gold, "
                   "drilled holes white, the mounting pad's outline dashed (nothing but the chips stands inside it on "
                   "top)." + unrouted)
    svg = board_svg(board, pcb_spec.via_drill_mm)
    return Figure("board", "Breakout board", caption, _data_uri(svg, "image/svg+xml"), links)


# ---------------------------------------------------------------------------------------------------
# The page


@dataclass(frozen=True)
class Pictures:
    """The report's drawings of the parts, the stack-up and the board: they need only the CAD branch's results,
    so the build draws them while the predictions are still being computed."""

    stack: Figure
    parts: list[Figure]
    board: Figure


def draw_pictures(design: Design, meshes: Mapping[str, trimesh.Trimesh], artifacts: Sequence[Artifact],
                  board: Board, parts: Mapping[str, bytes] | None = None) -> Pictures:
    """The stack-up (cut from the elastomer and pad meshes), every part whole and cut away (``parts``: the
    :func:`part_figure` PNGs by part stem, drawn already), the routed board."""
    missing = {"elastomer", "pad"} - set(meshes)
    if missing:
        raise ValueError(f"the report needs the meshes of {', '.join(sorted(missing))} "
                         "(the stack-up is cut from them)")
    stack = Figure("stackup", "Stack-up", "The assembled sensor at rest, cut through its axis (board frame). The "
                   "magnet rests against the pocket roof, north pole up; the dashed line is where its lower face "
                   "sits at d_min.", _data_uri(stackup_figure(design, meshes), "image/svg+xml"))
    return Pictures(stack, _part_figures(meshes, artifacts, parts or {}), _board_figure(design, board, artifacts))


def render_report(spec: Spec, design: Design, findings: Sequence[Finding], artifacts: Sequence[Artifact],
                  prediction: Prediction, calibration: Mapping[str, Any] | None,
                  meshes: Mapping[str, trimesh.Trimesh], extra_files: Iterable[tuple[str, str]] = (), *,
                  board: Board, pictures: Pictures | None = None) -> bytes:
    """report.html as UTF-8 bytes: one self-contained page for the build (module doc).

    ``artifacts``: what the build writes besides the report (``magfab.output.Artifact``: path, data,
    description); ``extra_files``: (path, description) of files written with or after the report (the
    report itself, the checklists, the BOM, the manifest), listed and linked too. ``calibration`` is the
    calibration.json content (or None); ``meshes`` the tessellated parts by file stem, at least
    ``elastomer`` and ``pad`` (the stack-up is drawn from their sections); ``board`` the routed board
    the build wrote (``magfab.pcb.board(design)``), drawn as it is, never routed again here; ``pictures``
    what :func:`draw_pictures` drew from them already (drawn here when not given)."""
    extra = [(str(p), str(d)) for p, d in extra_files]
    files = tables.file_groups(artifacts, extra)  # refuses a bad file list before any drawing
    listed = {a.path for a in artifacts} | {p for p, _ in extra}
    if pictures is None:
        pictures = draw_pictures(design, meshes, artifacts, board)
    html = render(
        "report/report.html.j2",
        spec=spec, version=__version__, sha256=spec.sha256(), design=design,
        bench=[{"href": href(p), "path": p, "what": w} for p, w in BENCH_FILES if p in listed],
        key_figures=tables.key_figures(design, prediction, calibration, findings),
        stack=pictures.stack, stack_rows=tables.stack_rows(design), heights=tables.heights(design),
        parts=pictures.parts, board=pictures.board,
        board_parts=tables.board_parts(board),
        array=array_context(design, artifacts, lambda folder: _plot_figures(artifacts, folder)),
        tables=tables.prediction_tables(prediction, measured=measured_rate_for(design, calibration)),
        plots=_plot_figures(artifacts, "plots/"),
        drift=drift_context(prediction, lambda folder: _plot_figures(artifacts, folder)),
        models=tables.model_rows(prediction),
        calibration=tables.calibration_summary(calibration, spec.calibration.tolerance_mN),
        calibration_plots=_plot_figures(artifacts, "calibration/"),
        findings=tables.findings_by_severity(findings), spec_sections=tables.spec_sections(spec), files=files,
        file_count=sum(len(g["rows"]) for g in files), spec_json="spec.json" if "spec.json" in listed else "",
    )
    return html.encode("utf-8")
