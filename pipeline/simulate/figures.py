"""Figures like the paper's Fig. 4 (median error vs intersection angle) and Fig. 5 (RMS error of the fusion
estimators), rendered with matplotlib's Agg canvas (no display, no pyplot global state) to PNG bytes."""

from __future__ import annotations

import io

from matplotlib.figure import Figure

from pipeline.simulate.experiment import SimulationResult
from pipeline.simulate.paper import PAPER_ANGLES_DEG, PAPER_TABLE2_MEDIAN_M

LABELS = {
    "dlt": "DLT intersection", "vision": "vision", "range": "laser ranging", "los": "line of sight",
    "los-oracle": "line of sight (best frame)", "fusion-raw": "fusion, not normalized", "fusion": "fusion",
    "ridge": "ridge fusion", "mle": "weighted MLE",
}
COLOURS = {
    "dlt": "tab:gray", "vision": "tab:blue", "range": "tab:orange", "los": "tab:brown", "los-oracle": "tab:pink",
    "fusion-raw": "tab:olive", "fusion": "tab:purple", "ridge": "tab:red", "mle": "tab:green",
}
FIG4_METHODS = ("vision", "range", "ridge", "mle")
FIG5_METHODS = ("fusion", "ridge", "mle")


def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    return buf.getvalue()


def _setup(title: str, ylabel: str) -> tuple[Figure, object]:
    fig = Figure(figsize=(7.0, 4.6), layout="constrained")
    ax = fig.add_subplot()
    ax.set_xlabel("intersection angle γ (deg)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    return fig, ax


def _subtitle(result: SimulationResult) -> str:
    cfg = result.config
    g = cfg.geometry
    return (f"{g.path} path, n={g.n_observations}, height {g.height_m / 1000:g} km, slant {g.slant_distance_m / 1000:g}"
            f" km, {cfg.trials} trials/angle, attitude noise {cfg.noise.attitude_model}")


def fig4_png(result: SimulationResult) -> bytes:
    """Median 3D error vs angle, log scale: ours solid, the paper's Table 2 dashed."""
    fig, ax = _setup("Median localization error (cf. paper Fig. 4)\n" + _subtitle(result), "median 3D error (m)")
    angles = result.angles_deg
    for m in FIG4_METHODS:
        if m in result.rows:
            ax.plot(angles, result.rows[m]["median_m"], "o-", color=COLOURS[m], label=f"{LABELS[m]} (ours)")
        if m in PAPER_TABLE2_MEDIAN_M:
            ax.plot(PAPER_ANGLES_DEG, PAPER_TABLE2_MEDIAN_M[m], "s--", color=COLOURS[m], alpha=0.6, mfc="none",
                    label=f"{LABELS[m]} (paper Table 2)")
    ax.set_yscale("log")
    ax.legend(fontsize=8, ncol=2)
    return _png(fig)


def fig5_png(result: SimulationResult) -> bytes:
    """RMS 3D error vs angle of fusion, ridge fusion and the MLE (the paper gives no RMS numbers to overlay)."""
    fig, ax = _setup("RMS localization error (cf. paper Fig. 5)\n" + _subtitle(result), "RMS 3D error (m)")
    for m in FIG5_METHODS:
        if m in result.rows:
            ax.plot(result.angles_deg, result.rows[m]["rms_m"], "o-", color=COLOURS[m], label=LABELS[m])
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    return _png(fig)
