"""Per-group figures: every axis labelled with its unit, a legend, and the legend clear of the plots."""

from __future__ import annotations

import re

import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from pipeline.report.figures import map_figure, residuals_figure, view3d_figure
from pipeline.report.synthetic import synthetic_group

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
    assert "2.5 km" in texts
    half = closeup.get_xlim()[1]
    assert half < 200  # the close-up stayed at the scale of the other estimates
