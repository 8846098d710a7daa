"""The paper's published simulation figures (Table 2, median 3D error in metres), for side-by-side rows.

Only Table 2 has numbers; Fig. 5 (RMS error of fusion and ridge fusion) is a plot without values, so no paper RMS
is given anywhere in ridgeloc.
"""

from __future__ import annotations

PAPER_ANGLES_DEG = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)

# method name as in `ridgeloc solve` -> median error (m) at PAPER_ANGLES_DEG
PAPER_TABLE2_MEDIAN_M = {
    "vision": (355.52, 110.74, 72.33, 51.17, 46.19, 43.14, 39.06, 35.96),
    "range": (588.89, 324.99, 190.20, 135.97, 90.66, 64.56, 49.44, 39.14),
    "fusion": (23.39, 22.44, 21.89, 20.00, 18.15, 17.18, 15.85, 15.10),
    "ridge": (22.52, 21.43, 21.14, 19.30, 17.32, 16.81, 15.39, 14.79),
}


def paper_median_m(method: str, angle_deg: float) -> float | None:
    """The paper's Table 2 median error for a method at an angle, or None where the paper gives none."""
    row = PAPER_TABLE2_MEDIAN_M.get(method)
    if row is None or angle_deg not in PAPER_ANGLES_DEG:
        return None
    return row[PAPER_ANGLES_DEG.index(angle_deg)]
