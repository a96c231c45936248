"""The prediction plots, the calibration chart and the stack-up drawing show what their captions claim: one
speed-accuracy panel per model family and cost unit with its Pareto front and tolerance, references off the
measured axes, colour bars on the filled contours, legends outside the axes, labels that do not overlap, the
board at its true width; and every plot is byte-identical run to run."""

from __future__ import annotations

import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest

from magfab.export import calibration_chart
from magfab.export import figures as F
from magfab.pipeline import model_bench


@pytest.fixture(scope="module")
def drawn(magone_design, magone_prediction):
    figs = F.draw(magone_design, magone_prediction, model_bench())
    for fig in figs.values():
        F._freeze_layout(fig)
    yield figs
    for fig in figs.values():
        plt.close(fig)


def _bbox(artist, fig):
    """Display-space box; of a text, the text alone (not an annotation's leader line)."""
    from matplotlib.text import Text

    renderer = fig.canvas.get_renderer()
    if hasattr(artist, "update_positions"):  # an annotation: where its text is, from its anchor and offset
        artist.update_positions(renderer)
    return Text.get_window_extent(artist, renderer) if isinstance(artist, Text) else artist.get_window_extent(renderer)


def _overlaps(a, b) -> bool:
    return min(a.x1, b.x1) - max(a.x0, b.x0) > 0.5 and min(a.y1, b.y1) - max(a.y0, b.y0) > 0.5


def _points(ax) -> np.ndarray:
    """Every scatter point of an axes, in data coordinates (n, 2)."""
    offsets = [c.get_offsets() for c in ax.collections if len(c.get_offsets())]
    return np.vstack(offsets) if offsets else np.zeros((0, 2))


def test_every_plot_has_a_caption_and_every_caption_a_plot(drawn):
    assert set(drawn) == set(F.CAPTIONS)


def test_legends_sit_below_the_axes_never_over_the_data(drawn):
    for name, fig in drawn.items():
        assert fig.legends, f"{name}: no legend"
        assert not any(ax.get_legend() for ax in fig.axes), f"{name}: a legend inside an axes"
        legend = _bbox(fig.legends[0], fig)
        for ax in fig.axes:
            assert not _overlaps(legend, _bbox(ax, fig)), f"{name}: the legend overlaps an axes"
            assert legend.y1 <= _bbox(ax, fig).y0 + 1.0, f"{name}: the legend is not below the panels"


def test_speed_accuracy_has_one_panel_per_family_and_unit_with_front_and_tolerance(drawn, magone_design):
    table = model_bench()
    panels = F.bench_panels(table)
    assert {p[0] for p in panels} == {str(r["family"]) for r in table}  # every family the bench holds
    for _family, _reference, _unit, rows in panels:
        assert len({r["unit"] for r in rows}) == 1
    fig = drawn["speed_accuracy"]
    main = [ax for ax in fig.axes if ax.get_label().startswith("speed:")]
    strips = [ax for ax in fig.axes if ax.get_label().startswith("reference:")]
    assert len(main) == len(strips) == len(panels)
    tol = magone_design.spec.predict.tolerance_pct / 100.0
    units = [strip.get_xlabel() for strip in strips]
    assert len(set(units)) == len(units) or len({(p[0], p[2]) for p in panels}) < len(panels)
    assert not any("elastomer" in u and "points" in u for u in units)  # no axis mixes two cost units
    for ax, (family, reference, _unit, rows) in zip(main, panels):
        assert ax.get_label() == f"speed:{family}:{reference}"
        assert any(np.allclose(line.get_ydata(), tol) for line in ax.lines), f"{family}: no tolerance line"
        measured = [r for r in rows if float(r["error"]) > 0]
        front = F.pareto_front([(float(r["time_s"]), float(r["error"])) for r in measured])
        steps = [line for line in ax.lines if line.get_drawstyle() == "steps-post"]
        assert len(steps) == 1 and list(steps[0].get_xdata()) == [t for t, _ in front], f"{family}: no front"
        assert any("%" in t.get_text() for t in ax.texts), f"{family}: the tolerance line is not labelled"


def test_speed_accuracy_references_are_not_plotted_as_measured(drawn):
    fig = drawn["speed_accuracy"]
    panels = F.bench_panels(model_bench())
    main = [ax for ax in fig.axes if ax.get_label().startswith("speed:")]
    strips = [ax for ax in fig.axes if ax.get_label().startswith("reference:")]
    for ax, strip, (family, _ref, _unit, rows) in zip(main, strips, panels):
        refs = [r for r in rows if F.is_reference(r)]
        assert refs, f"{family}: the bench names no reference"
        pts = _points(ax)
        assert len(pts) == len(rows) - len(refs)
        assert pts[:, 1].min() >= min(float(r["error"]) for r in rows if not F.is_reference(r)) * (1 - 1e-12)
        assert pts[:, 1].min() > 1e-15  # nothing sits at a floor standing in for 0
        on_strip = _points(strip)
        assert sorted(on_strip[:, 0]) == sorted(float(r["time_s"]) for r in refs)


def test_speed_accuracy_point_labels_do_not_overlap(drawn):
    fig = drawn["speed_accuracy"]
    for ax in (a for a in fig.axes if a.get_label().startswith("speed:")):
        boxes = [_bbox(t, fig) for t in ax.texts if "%" not in t.get_text()]
        frame = _bbox(ax, fig)
        assert boxes
        for i, a in enumerate(boxes):
            assert frame.x0 - 0.5 <= a.x0 and a.x1 <= frame.x1 + 0.5 and \
                frame.y0 - 0.5 <= a.y0 and a.y1 <= frame.y1 + 0.5
            assert not any(_overlaps(a, b) for b in boxes[i + 1:]), f"{ax.get_label()}: labels overlap"


def test_pareto_front_keeps_only_points_nothing_beats():
    pts = [(1.0, 0.5), (2.0, 0.6), (3.0, 0.1), (0.5, 0.9), (4.0, 0.1)]
    assert F.pareto_front(pts) == [(0.5, 0.9), (1.0, 0.5), (3.0, 0.1)]


def test_each_filled_contour_has_its_colour_bar_and_no_inline_labels(drawn):
    fig = drawn["field_contours"]
    from matplotlib.contour import ContourSet

    panels = [ax for ax in fig.axes if any(isinstance(c, ContourSet) and c.filled for c in ax.collections)]
    bars = [ax for ax in fig.axes if ax not in panels]
    assert len(panels) == 2 and len(bars) == 2
    for ax in panels:
        filled = next(c for c in ax.collections if isinstance(c, ContourSet) and c.filled)
        assert filled.colorbar is not None and filled.colorbar.ax in bars
        assert not any(getattr(c, "labelTexts", None) for c in ax.collections)  # the labels that piled up
        ticks = [t.get_text() for t in filled.colorbar.ax.get_yticklabels() if t.get_text()]
        assert ticks and all(re.fullmatch(r"\d+(\.\d+)?", t) for t in ticks), ticks  # plain round numbers


def test_sensitivity_draws_normal_and_shear_in_both_panels_with_plain_ticks(drawn, magone_prediction):
    fig = drawn["sensitivity"]
    sens, res = list(fig.axes)
    for ax in (sens, res):
        dashed = [line for line in ax.lines if line.get_linestyle() == "--"]
        solid = [line for line in ax.lines if line.get_linestyle() == "-"]
        assert len(dashed) == 3 and len(solid) == 3  # shear and normal, per material
    a, noise = magone_prediction.arrays, magone_prediction.noise
    shear_res = [line.get_ydata() for line in res.lines if line.get_linestyle() == "--"]
    for y, k in zip(shear_res, F.BAND_COLOURS):  # the shear's resolution: XY noise over its sensitivity
        assert np.allclose(y, 1000.0 * noise.total_xy_G / np.abs(a[f"sfs_{k}_nominal"]))
    for ax in (sens, res):
        labels = [t.get_text() for t in ax.get_yticklabels() + ax.get_yticklabels(minor=True) if t.get_text()]
        assert labels and not any("times" in t or "^" in t or "$" in t for t in labels), labels


def test_force_marks_every_range_limit_where_it_binds(drawn, magone_prediction):
    """One vertical line per limit the curve reaches, at the indentation where the magnet's travel reaches it, in
    both panels; the one that ends the range black and dashed, named "range ends" with "(model reach)" when it is a
    model's; a limit past the curve named in the legend only."""
    fig, n, a = drawn["force"], magone_prediction.normal, magone_prediction.arrays
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    u, ind = a["u"], a["indentation"]
    for label, travel in n.range_limits_travel_mm.items():
        (text,) = [t for t in texts if label in t]
        if travel <= u[-1] + 1e-9:
            at = float(np.interp(travel, u, ind))
            assert f"{at:.2f} mm" in text
            for ax in fig.axes:
                xs = [line.get_xdata()[0] for line in ax.lines if len(set(line.get_xdata())) == 1]
                assert any(abs(x - at) < 1e-9 for x in xs), (label, xs)
        else:
            assert "past the curve" in text
    (ends,) = [t for t in texts if t.startswith("range ends")]
    assert n.range_limit in ends and ("(model reach)" in ends) == n.range_is_model_reach
    assert n.range_limit == "scan depth" and "d_min: past the curve" in " ".join(texts)  # MagOne, Yeoh (the default)


def test_calibration_chart_draws_what_its_caption_says(magone_design, magone_prediction):
    from magfab.models import calibration as C
    from magfab.models.scan import simulate_scan

    result = C.fit(simulate_scan(magone_design, magone_prediction), magone_design, mls=False)
    fig = calibration_chart.draw(plt, result)
    try:
        (ax,) = fig.axes
        stars = [line for line in ax.lines if line.get_marker() == "*"]
        assert not stars and "no MLS" in calibration_chart.caption(result)
        assert fig.legends and ax.get_legend() is None
        assert any("not fitted" in t.get_text() for t in fig.legends[0].get_texts())
    finally:
        plt.close(fig)
    fake_mls = C.Candidate("mls", "mls", 2, result.candidates[0].rms_holdout_N, result.candidates[0].max_holdout_N,
                           result.candidates[0].rms_fit_N, 10 ** 5)
    with_mls = type(result)(result.calibration, (*result.candidates, fake_mls), result.chosen,
                            result.tolerance_mN, result.meets_tolerance)
    fig = calibration_chart.draw(plt, with_mls)
    try:
        stars = [line for line in fig.axes[0].lines if line.get_marker() == "*"]
        assert len(stars) == 2 and "moving least squares" in calibration_chart.caption(with_mls)
    finally:
        plt.close(fig)


def test_the_build_ships_the_plots_captioned_and_byte_identical(default_build, magone_design, magone_prediction):
    out = default_build.out_dir
    again = F.figures(magone_design, magone_prediction, model_bench())
    for stem in F.CAPTIONS:
        assert (out / "plots" / f"{stem}.svg").read_bytes() == again[f"{stem}.svg"]
        assert (out / "plots" / f"{stem}.png").read_bytes() == again[f"{stem}.png"]
    report = (out / "report.html").read_text()
    for caption in F.CAPTIONS.values():
        assert caption.replace("'", "&#39;") in report or caption in report


def test_the_stack_up_draws_the_board_at_its_true_width(magone_design):
    from matplotlib.patches import Rectangle

    from magfab import derive
    from magfab.export.report import drawings

    def board_width(design) -> tuple[float, bool]:
        fig, ax = plt.subplots()
        try:
            drawings._draw_stack(ax, design, {"pad": _disc(), "elastomer": _disc()})
            green = [p for p in ax.patches if isinstance(p, Rectangle)
                     and matplotlib.colors.same_color(p.get_facecolor(), drawings.STACK_STYLE["board"][0])]
            (board,) = green
            text = " ".join(t.get_text() for t in ax.texts)
            assert f"board {design.spec.pcb.width_mm:g} mm wide" in text  # its true width, broken off or not
            return board.get_width(), "broken off" in text
        finally:
            plt.close(fig)

    spec = magone_design.spec
    assert board_width(magone_design) == (pytest.approx(spec.pcb.width_mm), False)
    wide = derive(spec.model_copy(update={"pcb": spec.pcb.model_copy(update={"width_mm": 80.0})}))
    drawn_width, broken = board_width(wide)
    assert broken and drawn_width < 80.0  # broken off, and labelled with its true width
    assert drawings.board_half_width(wide) == (pytest.approx(drawn_width / 2), True)


def _disc():
    import trimesh

    return trimesh.creation.cylinder(radius=3.0, height=1.0)
