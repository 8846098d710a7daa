"""Per-group figures like the paper's Fig. 7 (matplotlib, headless Agg backend).

    map_figure(r)        flight path, lines of sight, every method's estimate, truth; a close-up panel in metres
                         around the target with the 95 % horizontal error ellipse of each estimate that has one
    view3d_figure(r)     the same in 3D (East, North, Up)
    residuals_figure(r)  per-frame pixel residuals (px) and range residuals (m) of the main estimates
    render_group_figures(r) -> {"map": png bytes, "view3d": ..., "residuals": ...}

All coordinates are the group's local ENU metres. Figures are built with the object API (no pyplot), so they
are headless and safe to make from several threads at once. Cost (docs/outputs.md, figures): a fixed layout in
inches, few ticks, and render_group_figures reusing its thread's figures (`reuse=True`) from one target to the
next; `python scripts/bench_figures.py OUT --against DIR` measures it.
"""

from __future__ import annotations

import io
import threading

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import Bbox
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from pipeline.report.geometry import (
    best_reference_m,
    frame_residuals,
    lines_of_sight_m,
)
from pipeline.report.labels import METHOD_COLORS, METHOD_MARKERS, count, method_label, ordered_methods
from pipeline.results import GroupResult
from pipeline.solve.uncertainty import ellipse_points_en_m

FIGURE_NAMES = ("map", "view3d", "residuals")
# Titles are given y=1.0 (just above the axes, where matplotlib puts them when no tick labels are on top): an
# automatic title position measures every tick label of the axes again at each draw.
DPI = 110
# zlib level 3: 40 % less encoding time than the default 6 and, for these flat-coloured figures, no larger files
_PNG_COMPRESS_LEVEL = 3
RESIDUAL_METHODS = ("mle", "ridge", "fusion", "vision", "range")
_PATH_COLOR = "#1F4E79"
_LOS_COLOR = "#9A9A9A"
# Fixed layout, in inches (no layout engine: constrained layout measured every text of the figure in an extra
# draw before the real one, two thirds of a figure's cost). The margins hold the tick labels, axis labels and
# titles at these font sizes; the legend's band under the axes grows with its number of rows.
_TITLE_IN = 0.36      # the figure's suptitle (13 pt)
_AX_TITLE_IN = 0.3    # an axes title (12 pt)
_XAXIS_IN = 0.52      # x tick labels and x label under an axes
_YAXIS_IN = 0.92      # y tick labels (up to "−10000") and y label left of an axes
_LEGEND_ROW_IN = 0.21  # one row of a 9 pt legend
_LEGEND_PAD_IN = 0.12


def _legend_height_in(n_entries: int, ncol: int) -> float:
    return _LEGEND_PAD_IN + _LEGEND_ROW_IN * -(-max(n_entries, 1) // ncol)


def _place(fig: Figure, ax, left_in: float, bottom_in: float, width_in: float, height_in: float) -> None:
    """Put `ax` at a rectangle given in inches from the figure's lower left corner."""
    w, h = fig.get_size_inches()
    ax.set_position([left_in / w, bottom_in / h, width_in / w, height_in / h])


_REUSED = threading.local()  # this thread's figures kept for reuse: {kind: (Figure, [axes])}


def _blank_figure(kind: str, reuse: bool) -> tuple[Figure, list]:
    """A figure of `kind` ("map", "view3d", "residuals") and its axes, empty. With `reuse`, this thread's figure
    of that kind from the last call, cleared of its data, titles, labels and legend: its axes, ticks and tick
    labels (a third of a figure's cost to create) are reused. A reused figure changes at the next call of the
    same kind in the same thread; the PNG is the same as a new figure's."""
    figures = _REUSED.__dict__.setdefault("figures", {})
    if reuse and kind in figures:
        fig, axes = figures[kind]
        for legend in list(fig.legends):
            legend.remove()
        for ax in axes:
            _clear_axes(ax)
        return fig, axes
    if kind == "map":
        fig = Figure(figsize=(12.5, 6.2), dpi=DPI)
        axes = [fig.add_axes((0, 0, 1, 1)), fig.add_axes((0, 0, 1, 1))]  # placed once the legend is known
    elif kind == "view3d":
        fig = Figure(figsize=(8.5, 7.0), dpi=DPI)
        axes = [fig.add_axes((0, 0, 1, 1), projection="3d")]
    else:
        fig = Figure(figsize=(9.0, 7.0), dpi=DPI)
        axes = [fig.add_axes((0, 0, 1, 1))]
        axes.append(fig.add_axes((0, 0, 1, 1), sharex=axes[0]))
        axes[0].tick_params(labelbottom=False)
    FigureCanvasAgg(fig)  # savefig then draws with this canvas's renderer, kept while the size and DPI stay
    if reuse:
        figures[kind] = (fig, axes)
    return fig, axes


def _clear_axes(ax) -> None:
    """`ax` as new, but for its axis objects and ticks: no data, titles, labels; autoscaling on."""
    for artist in (*ax.lines, *ax.collections, *ax.patches, *ax.texts, *ax.artists, *ax.images):
        artist.remove()
    ax.set_title("")
    ax.set_xlabel("")
    ax.set_ylabel("")
    ax.set_aspect("auto")
    ax.set_axis_on()
    if hasattr(ax, "zaxis"):  # as Axes3D.clear
        ax.set_zlabel("")
        margin = 0.05 * 10 / 11
        ax.xy_dataLim = Bbox([[margin, margin], [1 - margin, 1 - margin]])
        ax.zz_dataLim = Bbox.unit()
    else:
        ax.dataLim.set_points(Bbox.null().get_points())
        ax.ignore_existing_data_limits = True
    ax.set_autoscale_on(True)


def _few_ticks(ax, nbins: int) -> None:
    """At most about `nbins` intervals per axis of `ax` (matplotlib's default picks up to 9-11 here): each tick
    is a label, a grid line and two marks to create and draw, a large share of a figure's cost."""
    for axis in (ax.xaxis, ax.yaxis, getattr(ax, "zaxis", None)):
        if axis is not None:
            axis.set_major_locator(MaxNLocator(nbins=nbins, steps=[1, 2, 2.5, 5, 10]))


def _los_proxy() -> Line2D:
    return Line2D([], [], color=_LOS_COLOR, lw=0.6, alpha=0.7)


def _finite_estimates(r: GroupResult) -> list[str]:
    return [m for m in ordered_methods(r.estimates) if np.isfinite(r.estimates[m].position_m).all()]


def _centre_m(r: GroupResult) -> np.ndarray | None:
    return np.asarray(r.truth_m, float) if r.truth_m is not None else best_reference_m(r)


def _ellipse_covariance(r: GroupResult, method: str) -> np.ndarray | None:
    """The covariance (3, 3) m^2 drawn as a method's 95 % ellipse: the estimator's own, and for the answer's method
    without one (dem, los, ...: propagated by the answer rule) the answer's, as the report's maps draw it."""
    cov = r.estimates[method].covariance_m2
    if cov is None and r.answer is not None and r.answer.method == method:
        cov = r.answer.covariance_m2
    return cov


def _closeup_half_width_m(r: GroupResult, centre: np.ndarray, methods: list[str]) -> float:
    """Half width of the close-up: holds the ellipses and most of the estimates the flight determines (all of them
    where the answer rule judged none); far outliers and undetermined points are drawn as arrows."""
    verdicts = r.answer.verdicts if r.answer is not None else {}
    methods = [m for m in methods if m in verdicts and verdicts[m].determined] or methods
    d = np.array([np.linalg.norm(r.estimates[m].position_m[:2] - centre[:2]) for m in methods]) if methods else []
    ext = [5.0]
    for m in methods:
        cov = _ellipse_covariance(r, m)
        if cov is not None and np.isfinite(cov).all():
            ring = ellipse_points_en_m(np.asarray(cov)[:2, :2]) + r.estimates[m].position_m[:2] - centre[:2]
            ext.append(float(np.abs(ring).max()))
    if len(d):
        # the estimates within 5x the median distance set the scale, so one wild estimate does not
        near = d[d <= 5.0 * max(np.median(d), 1.0)]
        ext.append(float(near.max()) if near.size else 0.0)
    return 1.15 * max(ext)


def text_color(hex_rgb: str, min_contrast: float = 4.5) -> str:
    """`hex_rgb` darkened until its WCAG contrast against white is at least `min_contrast` (4.5: legible small
    text), so light method colours (the yellow of dlt) stay readable as text; darker colours are unchanged."""
    rgb = np.array([int(hex_rgb[i:i + 2], 16) for i in (1, 3, 5)], dtype=float) / 255.0

    def contrast(c):
        lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
        return 1.05 / (float(lin @ [0.2126, 0.7152, 0.0722]) + 0.05)

    while contrast(rgb) < min_contrast:
        rgb = rgb * 0.9
    return "#" + "".join(f"{round(v * 255):02X}" for v in rgb)


def _offscale_labels(ax, items: list[tuple[str, np.ndarray, float]], half: float) -> None:
    """Arrows at the close-up's edge towards estimates outside it, each labelled with its method and distance.
    Labels that would overlap (estimates in similar directions) are stacked inwards, one line apart."""
    placed: list[np.ndarray] = []
    step = 0.085 * half
    for m, xy, dist in sorted(items, key=lambda it: it[2]):
        color = METHOD_COLORS.get(m, "#000000")
        u = xy / np.linalg.norm(xy)
        edge = u * half * 0.86 / np.abs(u).max()
        ax.annotate("", xy=edge + u * half * 0.12, xytext=edge,
                    arrowprops={"arrowstyle": "-|>", "fc": color, "ec": text_color(color, 3.0), "lw": 1.8})
        pos = edge - u * half * 0.08
        inward = -np.sign(pos[1]) if abs(pos[1]) >= abs(pos[0]) else 0.0  # stack away from a top/bottom edge
        along = np.array([0.0, inward if inward else -1.0])
        while any(abs(pos[0] - q[0]) < 0.42 * half and abs(pos[1] - q[1]) < step for q in placed):
            pos = pos + along * step
        placed.append(pos)
        txt = f"{dist / 1000:.1f} km" if dist >= 1000 else f"{dist:.0f} m"
        ax.text(*pos, f"{_SHORT.get(m, m)} {txt}", color=text_color(color), fontsize=8, ha="center", va="center",
                fontweight="bold", bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85, "pad": 0.6},
                zorder=8)


_SHORT = {"vision": "vision", "range": "range", "los": "LOS", "fusion-raw": "fusion-raw", "fusion": "fusion",
          "ridge": "ridge", "dlt": "DLT", "mle": "MLE"}


def _draw_estimates_2d(ax, r: GroupResult, methods: list[str], offset: np.ndarray, half: float | None,
                       ellipses: bool) -> None:
    offscale = []
    for m in methods:
        e = r.estimates[m]
        xy = e.position_m[:2] - offset[:2]
        color = METHOD_COLORS.get(m, "k")
        marker = METHOD_MARKERS.get(m, "o")
        if half is not None and np.abs(xy).max() > half:
            offscale.append((m, xy, float(np.linalg.norm(xy))))  # off the close-up: an arrow at the edge
            continue
        ax.plot(*xy, marker=marker, color=color, markersize=11 if m == "mle" else 8, markeredgecolor="k",
                markeredgewidth=0.6, linestyle="none", zorder=5)
        cov = _ellipse_covariance(r, m)
        if ellipses and cov is not None and np.isfinite(cov).all():
            ring = ellipse_points_en_m(np.asarray(cov)[:2, :2]) + xy
            ax.plot(ring[:, 0], ring[:, 1], color=color, lw=1.4, ls="--", zorder=4)
    if offscale:
        _offscale_labels(ax, offscale, half)


def map_figure(r: GroupResult, reuse: bool = False) -> Figure:
    """Plan view (East/North metres): overview of the whole flight and a close-up around the target. `reuse`:
    see `_blank_figure`."""
    fig, (ax0, ax1) = _blank_figure("map", reuse)
    obs = r.observations
    methods = _finite_estimates(r)
    centre = _centre_m(r)
    seg, _ = lines_of_sight_m(obs, best_reference_m(r), max_lines=60)
    handles = {}

    # overview
    if len(seg):
        ax0.add_collection(LineCollection(seg[:, :, :2], colors=_LOS_COLOR, linewidths=0.6, alpha=0.7, zorder=1))
        handles["Lines of sight"] = _los_proxy()
    (h,) = ax0.plot(obs.platform_m[:, 0], obs.platform_m[:, 1], color=_PATH_COLOR, lw=2.2, zorder=3)
    handles["Flight path"] = h
    (h,) = ax0.plot(*obs.platform_m[0, :2], "o", color=_PATH_COLOR, markersize=7, zorder=3)
    handles["Path start"] = h
    _draw_estimates_2d(ax0, r, methods, np.zeros(3), None, ellipses=False)
    if r.truth_m is not None:
        ax0.plot(*r.truth_m[:2], marker="*", color="k", markersize=15, markerfacecolor="yellow", ls="none",
                 zorder=6)
    ax0.set_aspect("equal", adjustable="datalim")
    _few_ticks(ax0, 6)
    ax0.set_xlabel("East (m)")
    ax0.set_ylabel("North (m)")
    ax0.set_title("Overview: flight path and lines of sight", y=1.0)
    ax0.grid(True, alpha=0.3)

    # close-up
    if centre is not None:
        half = _closeup_half_width_m(r, centre, methods)
        if len(seg):
            # a line of sight as a line through the close-up, so the bundle's crossing shows
            d = seg[:, 1] - seg[:, 0]
            d = d / np.linalg.norm(d, axis=1, keepdims=True)
            lines = seg[:, 1, None, :] + np.array([-4 * half, 4 * half])[None, :, None] * d[:, None, :]
            ax1.add_collection(LineCollection(lines[:, :, :2] - centre[:2], colors=_LOS_COLOR, linewidths=0.6,
                                              alpha=0.6, zorder=1), autolim=False)
        _draw_estimates_2d(ax1, r, methods, centre, half, ellipses=True)
        if r.truth_m is not None:
            ax1.plot(0, 0, marker="*", color="k", markersize=18, markerfacecolor="yellow", ls="none", zorder=6)
        ax1.set_xlim(-half, half)
        ax1.set_ylim(-half, half)
        ax1.set_aspect("equal")
        _few_ticks(ax1, 6)
        what = "truth" if r.truth_m is not None else ("the answer" if r.answer is not None and r.answer.located
                                                      else "the reference estimate")
        ax1.set_xlabel(f"East of {what} (m)")
        ax1.set_ylabel(f"North of {what} (m)")
        ax1.set_title("Close-up: estimates, dashed = 95 % error ellipse", y=1.0)
        ax1.grid(True, alpha=0.3)
        ax0.add_patch(Rectangle((centre[0] - half, centre[1] - half), 2 * half, 2 * half, fill=False,
                                    ec="k", lw=0.8, zorder=7))
    else:
        ax1.set_axis_off()

    # one legend for both panels, under them, so it never covers data
    for m in methods:
        handles[method_label(m)] = Line2D([], [], marker=METHOD_MARKERS.get(m, "o"), ls="none",
                                              color=METHOD_COLORS.get(m, "k"), markeredgecolor="k",
                                              markersize=9)
    if r.truth_m is not None:
        handles["Truth"] = Line2D([], [], marker="*", ls="none", color="k", markerfacecolor="yellow",
                                      markersize=13)
    ncol = min(6, len(handles))
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=ncol, frameon=False, fontsize=9)
    angle = f", intersection angle {r.intersection_angle_deg:.1f}°" if np.isfinite(r.intersection_angle_deg) else ""
    fig.suptitle(f"{r.label}: {count(obs.n, 'observation')}{angle}", fontsize=13)
    w_in, h_in = fig.get_size_inches()
    bottom = _legend_height_in(len(handles), ncol) + _XAXIS_IN
    height = h_in - bottom - _TITLE_IN - _AX_TITLE_IN
    gap, right = _YAXIS_IN + 0.12, 0.15
    width = w_in - _YAXIS_IN - gap - right
    _place(fig, ax0, _YAXIS_IN, bottom, width * 1.15 / 2.15, height)
    _place(fig, ax1, _YAXIS_IN + width * 1.15 / 2.15 + gap, bottom, width / 2.15, height)
    return fig


def view3d_figure(r: GroupResult, reuse: bool = False) -> Figure:
    """3D view (East, North, Up metres) of the path, lines of sight, estimates and truth. `reuse`: see
    `_blank_figure`."""
    fig, (ax,) = _blank_figure("view3d", reuse)
    obs = r.observations
    seg, _ = lines_of_sight_m(obs, best_reference_m(r), max_lines=40)
    handles = {}
    if len(seg):
        ax.add_collection3d(Line3DCollection(seg, colors=_LOS_COLOR, linewidths=0.6, alpha=0.7))
        handles["Lines of sight"] = _los_proxy()
    (handles["Flight path"],) = ax.plot(*obs.platform_m.T, color=_PATH_COLOR, lw=2.2)
    (handles["Path start"],) = ax.plot(*obs.platform_m[0], "o", color=_PATH_COLOR, markersize=6)
    centre = _centre_m(r)
    for m in _finite_estimates(r):
        p = r.estimates[m].position_m
        if centre is not None and np.linalg.norm(p - centre) > 0.2 * np.ptp(obs.platform_m[:, :2], axis=0).max() + 500:
            continue  # far outliers would stretch the view; the map's close-up marks them
        (handles[method_label(m)],) = ax.plot(*p, marker=METHOD_MARKERS.get(m, "o"), color=METHOD_COLORS.get(m, "k"),
                                              markeredgecolor="k", markersize=8, ls="none")
    if r.truth_m is not None:
        (handles["Truth"],) = ax.plot(*r.truth_m, marker="*", color="k", markerfacecolor="yellow", markersize=14,
                                      ls="none")
    ax.set_xlabel("East (m)", labelpad=10)
    ax.set_ylabel("North (m)", labelpad=10)
    ax.set_zlabel("Up (m)", labelpad=8)
    _few_ticks(ax, 5)
    ax.set_title(f"{r.label}: 3D view", y=1.0)
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=4, frameon=False, fontsize=9)
    w_in, h_in = fig.get_size_inches()
    bottom = _legend_height_in(len(handles), 4)
    _place(fig, ax, 0.1, bottom, w_in - 0.2, h_in - bottom - 0.45)  # room for the title above
    return fig


def _robust_limit(values: list[np.ndarray], floor: float) -> float:
    """An axis limit holding the bulk of |values| but not gross outliers (beyond 6x the median)."""
    v = np.abs(np.concatenate(values)) if values else np.zeros(0)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return floor
    inliers = v[v <= 6.0 * max(np.median(v), floor / 6.0)]
    return 1.2 * max(float(inliers.max()) if inliers.size else floor, floor)


def _mark_off_scale(ax, t_s: np.ndarray, series: list[tuple[str, np.ndarray, dict]], scale_methods, lim: float,
                    lower: float, unit: str) -> str:
    """Off-scale points of the scale-setting methods as triangles at the edge; returns a note for the title
    (how many, the largest, and which other methods run off scale: their RMS is in the legend)."""
    n, worst, others = 0, 0.0, []
    for m, r, style in series:
        hi, lo = r > lim, r < lower
        if m not in scale_methods:
            if np.mean((hi | lo)[np.isfinite(r)]) > 0.3:
                others.append(method_label(m))
            continue
        for mask, y, marker in ((hi, lim, "^"), (lo, lower, "v")):
            if mask.any():
                ax.plot(t_s[mask], np.full(mask.sum(), y), ls="none", marker=marker, color=style["color"],
                        markersize=9, markeredgecolor="k", clip_on=False, zorder=6)
                n += int(mask.sum())
                worst = max(worst, float(np.abs(r[mask]).max()))
    notes = []
    if n:
        notes.append(f"{n} off scale (▲▼), largest {worst:,.0f} {unit}")
    if others:
        notes.append(f"off scale: {', '.join(others)}")
    return "; ".join(notes)


def residuals_figure(r: GroupResult, reuse: bool = False) -> Figure:
    """Per-frame residuals of the main estimates: pixel reprojection error (px) and range residual (m). `reuse`:
    see `_blank_figure`."""
    obs = r.observations
    t_s = (obs.t_ns - obs.t_ns[0]) / 1e9
    fig, (ax0, ax1) = _blank_figure("residuals", reuse)
    methods = [m for m in ordered_methods(r.estimates) if m in RESIDUAL_METHODS and m in _finite_estimates(r)]
    methods = sorted(methods, key=lambda m: m != "mle")  # the MLE first: it sets the scales
    px_series, m_series, handles, labels = [], [], [], []
    for m in methods:
        px, rg = frame_residuals(obs, r.estimates[m].position_m)
        style = {"marker": METHOD_MARKERS.get(m, "o"), "color": METHOD_COLORS.get(m, "k"),
                 "lw": 2.2 if m == "mle" else 1.2, "markersize": 6 if m == "mle" else 4.5}
        rms = []
        if np.isfinite(px).any():
            ax0.plot(t_s, px, **style)
            rms.append(f"{np.sqrt(np.nanmean(px ** 2)):.2f} px")
            px_series.append((m, px, style))
        if np.isfinite(rg).any():
            ax1.plot(t_s, rg, **style)
            rms.append(f"{np.sqrt(np.nanmean(rg ** 2)):.1f} m")
            m_series.append((m, rg, style))
        handles.append(Line2D([], [], **style))
        labels.append(f"{method_label(m)} (RMS {', '.join(rms)})")
    # the well-fitting estimates (MLE, ridge) set the scale, robustly: gross outliers and badly fitting
    # estimates are marked at the edge instead of squashing everything else
    scale = ("mle", "ridge")
    lim_px = _robust_limit([v for m, v, _ in px_series if m in scale] or [v for _, v, _ in px_series], 0.5)
    lim_m = _robust_limit([v for m, v, _ in m_series if m in scale] or [v for _, v, _ in m_series], 1.0)
    ax0.set_ylim(0, lim_px)
    ax1.set_ylim(-lim_m, lim_m)
    shown = {m for m, _, _ in px_series + m_series if m in scale} or {m for m, _, _ in px_series + m_series}
    note_px = _mark_off_scale(ax0, t_s, px_series, shown, lim_px, -np.inf, "px")
    note_m = _mark_off_scale(ax1, t_s, m_series, shown, lim_m, -lim_m, "m")
    ax1.axhline(0, color="k", lw=0.8)
    _few_ticks(ax0, 6)
    _few_ticks(ax1, 6)
    ax0.set_ylabel("Reprojection error (px)")
    ax1.set_ylabel("Range residual |X − s| − d (m)")
    ax1.set_xlabel("Time since first frame (s)")
    ax0.set_title("Pixel residuals" + (f" ({note_px})" if note_px else ""), fontsize=11, y=1.0)
    ax1.set_title("Range residuals" + (f" ({note_m})" if note_m else ""), fontsize=11, y=1.0)
    for ax in (ax0, ax1):
        ax.grid(True, alpha=0.3)
        if not ax.lines:
            ax.text(0.5, 0.5, "no observations of this kind", transform=ax.transAxes, ha="center")
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=2, frameon=False, fontsize=9)
    fig.suptitle(f"{r.label}: residuals per frame", fontsize=13)
    w_in, h_in = fig.get_size_inches()
    bottom = (_legend_height_in(len(handles), 2) if handles else 0.0) + _XAXIS_IN
    height = (h_in - bottom - _TITLE_IN - 2 * _AX_TITLE_IN - 0.1) / 2
    _place(fig, ax1, _YAXIS_IN, bottom, w_in - _YAXIS_IN - 0.15, height)
    _place(fig, ax0, _YAXIS_IN, bottom + height + _AX_TITLE_IN + 0.1, w_in - _YAXIS_IN - 0.15, height)
    return fig


def figure_png(fig: Figure) -> bytes:
    """The figure as PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, pil_kwargs={"compress_level": _PNG_COMPRESS_LEVEL})
    return buf.getvalue()


def render_group_figures(r: GroupResult) -> dict[str, bytes]:
    """{"map", "view3d", "residuals"} -> PNG bytes of one group."""
    return {"map": figure_png(map_figure(r, reuse=True)), "view3d": figure_png(view3d_figure(r, reuse=True)),
            "residuals": figure_png(residuals_figure(r, reuse=True))}
