"""Per-group figures: every axis labelled with its unit, a legend, and the legend clear of the plots."""

from __future__ import annotations

import re

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from pipeline.report.figures import map_figure, residuals_figure, view3d_figure
from support.synthetic import synthetic_group

UNIT = re.compile(r"\((m|px|s)\)$")


@pytest.fixture(scope="module")
def group():
    return synthetic_group("group2", seed=12, intersection_angle_deg=25, n_frames=12)


@pytest.mark.parametrize("make", [map_figure, view3d_figure, residuals_figure])
def test_axes_labelled_with_units_and_legend_clear(group, make):
    fig = make(group)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert axes
    for ax in axes:
        xlabel = ax.get_xlabel() or next((a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax)
                                          if a.get_xlabel()), "")  # a shared x axis is labelled once, below
        labels = [xlabel, ax.get_ylabel()] + ([ax.get_zlabel()] if hasattr(ax, "get_zlabel") else [])
        for label in labels:
            assert UNIT.search(label), f"axis label without unit: {label!r}"
    assert fig.legends, "the figure has no legend"
    legend_box = fig.legends[0].get_window_extent(renderer)
    for ax in axes:
        assert not legend_box.overlaps(ax.get_window_extent(renderer)), "legend overlaps a plot"
    # titles and labels inside the figure
    fig_box = fig.bbox
    for ax in axes:
        tight = ax.get_tightbbox(renderer)
        assert tight.x0 >= fig_box.x0 - 1 and tight.x1 <= fig_box.x1 + 1
        assert tight.y0 >= fig_box.y0 - 1 and tight.y1 <= fig_box.y1 + 1


def test_map_marks_an_off_scale_estimate(group):
    """An estimate far outside the close-up is drawn as an arrow labelled with its distance, not dropped."""
    import dataclasses

    import numpy as np

    far = dataclasses.replace(group.estimates["range"], position_m=group.truth_m + np.array([0.0, 2500.0, 0.0]))
    g = dataclasses.replace(group, estimates={**group.estimates, "range": far})
    fig = map_figure(g)
    closeup = fig.axes[1]
    texts = [t.get_text() for t in closeup.texts]
    assert "range 2.5 km" in texts
    half = closeup.get_xlim()[1]
    assert half < 200  # the close-up stayed at the scale of the other estimates


def test_off_scale_labels_in_one_direction_do_not_overlap_and_light_colours_are_darkened(group):
    """Three estimates off the close-up in nearly the same direction (group2's 68, 77, 586 m) get three
    separate labels; the yellow of dlt is darkened to a legible contrast on white."""
    import dataclasses

    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from pipeline.report.figures import text_color

    moved = {m: dataclasses.replace(group.estimates[m], position_m=group.truth_m
                                    + d * np.array([np.sin(a), -np.cos(a), 0.0]))
             for m, a, d in (("vision", 0.13, 68.0), ("dlt", 0.13, 77.0), ("range", 0.05, 586.0))}
    g = dataclasses.replace(group, estimates={**group.estimates, **moved})
    fig = map_figure(g)
    renderer = FigureCanvasAgg(fig).get_renderer()
    closeup = fig.axes[1]
    labels = [t for t in closeup.texts if t.get_text().endswith(" m")]
    assert sorted(t.get_text() for t in labels) == ["DLT 77 m", "range 586 m", "vision 68 m"]
    boxes = [t.get_window_extent(renderer) for t in labels]
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert not boxes[i].overlaps(boxes[j]), (labels[i].get_text(), labels[j].get_text())
    dlt = next(t for t in labels if t.get_text().startswith("DLT"))
    assert dlt.get_color().upper() == text_color("#F0E442").upper() != "#F0E442"

    def contrast_on_white(hex_rgb):
        c = np.array([int(hex_rgb[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
        lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
        return 1.05 / (float(lin @ [0.2126, 0.7152, 0.0722]) + 0.05)

    assert contrast_on_white("#F0E442") < 1.5 and contrast_on_white(text_color("#F0E442")) >= 4.5
    assert text_color("#0072B2") == "#0072B2"  # already legible: unchanged


def test_reused_figures_give_the_same_pngs_as_new_ones(group):
    """render_group_figures reuses this thread's figures: after a different group (no truth, far estimate, other
    frame count, fewer methods) its PNGs are byte for byte those of new figures made in a new thread."""
    import dataclasses
    import threading

    import numpy as np

    from pipeline.report.figures import figure_png, render_group_figures

    other = synthetic_group("other", seed=3, intersection_angle_deg=60, n_frames=20, truth_known=False)
    far = dataclasses.replace(other.estimates["range"], position_m=other.estimates["mle"].position_m
                              + np.array([900.0, 0.0, 0.0]))
    other = dataclasses.replace(other, estimates={**{m: e for m, e in other.estimates.items() if m != "dlt"},
                                                  "range": far})
    fresh = {}

    def render_new():
        fresh.update(map=figure_png(map_figure(group)), view3d=figure_png(view3d_figure(group)),
                     residuals=figure_png(residuals_figure(group)))

    worker = threading.Thread(target=render_new)
    worker.start()
    worker.join()
    first = render_group_figures(group)
    render_group_figures(other)
    again = render_group_figures(group)
    assert set(fresh) == set(again) == {"map", "view3d", "residuals"}
    for k in fresh:
        assert again[k] == first[k] == fresh[k], k
    assert render_group_figures(other)["map"] != again["map"]


def test_the_close_up_draws_the_answers_ellipse_where_its_method_has_no_covariance_of_its_own(group):
    """The answer from a method without its own covariance (dem, los: propagated by the answer rule) gets its 95 %
    ellipse in the close-up, which holds it (it had none: a photo's `dem` answer, CE90 128 m, in a +-5 m close-up)."""
    import dataclasses

    import numpy as np

    from pipeline.answer import Answer
    from pipeline.report.labels import METHOD_COLORS
    from pipeline.solve.uncertainty import ellipse_points_en_m

    assert group.estimates["los"].covariance_m2 is None
    cov = np.diag([40.0 ** 2, 15.0 ** 2, 20.0 ** 2])
    answer = Answer(True, "los", group.estimates["los"].position_m, cov, "los: the most precise", group.n_observations)
    closeup = map_figure(dataclasses.replace(group, answer=answer)).axes[1]
    dashed = [ln for ln in closeup.get_lines() if ln.get_linestyle() == "--"
              and ln.get_color() == METHOD_COLORS["los"]]
    assert len(dashed) == 1
    extent = np.abs(ellipse_points_en_m(cov[:2, :2])).max()
    assert closeup.get_xlim()[1] >= extent


def test_views_centre_on_the_answer_not_on_an_undetermined_method():
    """On the real KLV clip vision and mle lie kilometres off along nearly parallel lines of sight while the answer
    is the line of sight's point: the close-up, the footprints and the lines of sight centre on the answer; without
    an answer, on the first finite estimate of the order (mle first)."""
    from types import SimpleNamespace

    from pipeline.report.geometry import best_reference_m

    est = {"mle": SimpleNamespace(position_m=np.array([900.0, 0.0, -1000.0])),
           "vision": SimpleNamespace(position_m=np.array([800.0, 0.0, -900.0])),
           "los": SimpleNamespace(position_m=np.array([1.0, 2.0, 3.0]))}
    located = SimpleNamespace(located=True, position_m=np.array([1.0, 2.0, 3.0]))
    assert best_reference_m(SimpleNamespace(estimates=est, answer=located)).tolist() == [1.0, 2.0, 3.0]
    not_located = SimpleNamespace(located=False, position_m=None)
    assert best_reference_m(SimpleNamespace(estimates=est, answer=not_located)).tolist() == [900.0, 0.0, -1000.0]
