"""Display names, order and colours of the estimators, as the paper's Table 4 names them."""

from __future__ import annotations

# The order of the paper's Table 4, then ours (dlt, mle).
METHOD_ORDER = ("vision", "range", "los", "fusion-raw", "fusion", "ridge", "dlt", "mle")

METHOD_LABELS = {
    "dlt": "DLT triangulation",
    "vision": "Vision algorithm",
    "range": "Laser ranging algorithm",
    "los": "Line of sight algorithm",
    "fusion-raw": "Fusion without normalization",
    "fusion": "Fusion algorithm",
    "ridge": "Fusion under ridge estimation",
    "mle": "Weighted MLE",
    # The photo methods of `ridgeloc locate` (docs/locate.md).
    "dem": "Ray into the terrain model (DEM)",
    "dji": "DJI's own laser target",
    "ground": "Ray onto level ground",
}

# Colour-blind-safe (Okabe-Ito) colours, one per method.
METHOD_COLORS = {
    "vision": "#0072B2",
    "range": "#E69F00",
    "los": "#999999",
    "fusion-raw": "#CC79A7",
    "fusion": "#56B4E9",
    "ridge": "#009E73",
    "dlt": "#F0E442",
    "mle": "#D55E00",
    "dem": "#000000",
    "dji": "#882255",
    "ground": "#332288",
}

METHOD_MARKERS = {
    "vision": "s", "range": "D", "los": "v", "fusion-raw": "P", "fusion": "X", "ridge": "o", "dlt": "^", "mle": "h",
    "dem": "*", "dji": "d", "ground": "p",
}


def method_label(method: str) -> str:
    return METHOD_LABELS.get(method, method)


def ordered_methods(methods) -> list[str]:
    """`methods` in Table-4 order; unknown names last, in their given order."""
    methods = list(methods)
    known = [m for m in METHOD_ORDER if m in methods]
    return known + [m for m in methods if m not in METHOD_ORDER]


def count(n: int, noun: str) -> str:
    """'1 observation', '2 observations'."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def one_decimal(x: float) -> str:
    """x with one decimal, without a sign on a zero ('-0.0' reads as a sign that means something)."""
    text = f"{x:.1f}"
    return "0.0" if text == "-0.0" else text
