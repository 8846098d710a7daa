"""Dense references the tests check the batched kernels against: the paper's equations written as they stand."""

import numpy as np

from pipeline.solve.least_squares import _minmax
from pipeline.solve.stacked import Stacked, pixel_model, range_model


def normalized_system(st: Stacked, X: np.ndarray):
    """The paper's eqs. (36)-(38) at X: T (B, 2n+n, 4), dPhi (B, 3n) (unused rows zero) and the rows in use (B,)."""
    Jp, rp, okp = pixel_model(st, X)
    Jr, rr, okr = range_model(st, X)
    Lo, Sp = _minmax(rp, okp)
    lo, sp = _minmax(rr, okr)
    m = rp.shape[1]
    T = np.empty((X.shape[0], m + rr.shape[1], 4))
    T[:, :m, :3] = Jp * (1.0 / Sp)[:, None, None]  # Jp, Jr are zero on unused rows
    T[:, m:, :3] = Jr * (1.0 / sp)[:, None, None]
    T[:, :m, 3] = (-Lo / Sp)[:, None] * okp
    T[:, m:, 3] = (-lo / sp)[:, None] * okr
    dPhi = np.concatenate([(rp - Lo[:, None]) * (okp / Sp[:, None]), (rr - lo[:, None]) * (okr / sp[:, None])],
                          axis=1)
    rows = okp.sum(axis=1) + okr.sum(axis=1)
    return T, dPhi, rows
