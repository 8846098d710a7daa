"""Closed-form estimators: `dlt` (linear forward intersection) and `los` (single-frame line of sight x range)."""

from __future__ import annotations

import numpy as np

from pipeline.solve.estimate import Status
from pipeline.solve.stacked import Stacked


def dlt(st: Stacked, with_condition: bool = True):
    """Homogeneous linear triangulation from every frame with a pixel (docs/solvers.md, dlt): the rows u p3 - p1,
    v p3 - p2 of A [X; 1] = 0 in a frame centred on the platforms and scaled by their spread, each row of unit
    length; X the eigenvector of A^T A of the smallest eigenvalue. (Inverse iteration instead of eigh was tried: at
    small intersection angles the two smallest eigenvalues are too close for a few steps to converge.)

    Returns X (B,3) (NaN, status DEGENERATE with fewer than two pixels or parallel rays), status (B,) int8, cond
    (B,) sigma_1 / sigma_3 of the normalised A (NaN unless with_condition)."""
    B, n = st.has_pix.shape
    c = st.platform_m.mean(axis=1)  # (B,3)
    d = st.platform_m - c[:, None, :]
    spread = np.sqrt(np.einsum("bni,bni->b", d, d) / n)
    sc = np.where(spread > 1.0, spread, 1.0)
    # the rows of P' = P [[sc I, c], [0, 1]]: (B,n,2,4)
    rows = np.empty((B, n, 2, 4))
    np.multiply(st.pix[..., :, None] * st.M[..., 2:3, :] - st.M[..., :2, :], sc[:, None, None, None],
                out=rows[..., :3])
    p4p = np.einsum("bnij,bj->bni", st.M, c) + st.p4
    rows[..., 3] = st.pix * p4p[..., 2:3] - p4p[..., :2]
    norm = np.sqrt(np.einsum("bnkj,bnkj->bnk", rows, rows))
    ok = st.has_pix[..., None] & (norm > 0)
    A = np.where(ok[..., None], rows / np.where(ok, norm, 1.0)[..., None], 0.0).reshape(B, -1, 4)
    N = np.swapaxes(A, 1, 2) @ A
    enough = st.has_pix.sum(axis=1) >= 2
    evals, evecs = np.linalg.eigh(N)
    x = evecs[..., 0]
    w = x[:, 3]
    at_infinity = np.abs(w) <= 1e-12 * np.sqrt((x[:, :3] ** 2).sum(axis=1))
    good = enough & ~at_infinity
    with np.errstate(divide="ignore", invalid="ignore"):
        X = c + sc[:, None] * x[:, :3] / w[:, None]
    X[~good] = np.nan
    status = np.where(good, Status.CLOSED_FORM, Status.DEGENERATE).astype(np.int8)
    cond = np.full(st.size, np.nan)
    if with_condition:
        with np.errstate(divide="ignore", invalid="ignore"):
            cond = np.sqrt(np.maximum(evals[:, 3], 0) / np.maximum(evals[:, 1], 0))
        cond = np.where(np.isfinite(cond), cond, np.inf)
    return X, status, cond


def finite_cameras(st: Stacked) -> np.ndarray:
    """(B,n) True where P's left 3x3 block M is a finite camera: |det M| against |M|^3 (its rows' lengths)."""
    g = st.gram
    return np.abs(st.det_M) > 1e-12 * np.sqrt(g[..., 0, 0] * g[..., 1, 1] * g[..., 2, 2])


def los_points(st: Stacked):
    """Per-frame line-of-sight points (B,n,3) and where they are valid (B,n) (docs/solvers.md, los): on the ray
    from C = -M^-1 p4 along sign(det M) M^-1 [u, v, 1], at the laser range d from the platform s (a lever arm
    between camera and laser: |C + t a - s| = d, the far root); NaN without the pixel or the range."""
    finite_camera = finite_cameras(st)
    Minv = np.linalg.inv(np.where(finite_camera[..., None, None], st.M, np.eye(3)))
    C = -np.einsum("bnij,bnj->bni", Minv, st.p4)
    xh = np.concatenate([st.pix, np.ones((*st.pix.shape[:-1], 1))], axis=-1)
    a = np.einsum("bnij,bnj->bni", Minv, xh) * st.depth_sign()[..., None]
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    cs = C - st.platform_m
    b = np.einsum("bni,bni->bn", a, cs)
    disc = b * b - (np.einsum("bni,bni->bn", cs, cs) - st.range_m ** 2)
    t = -b + np.sqrt(np.maximum(disc, 0.0))
    pts = C + t[..., None] * a
    valid = st.has_pix & st.has_range & finite_camera
    pts[~valid] = np.nan
    return pts, valid


def los(st: Stacked):
    """Line-of-sight estimate: X (B,3) the per-frame points' component-wise median, status (B,) (CLOSED_FORM, or
    DEGENERATE without a usable frame), the points (B,n,3), and oracle (B,): the best single frame's error against
    the truth (NaN without it), the figure of the paper's Table 4."""
    pts, valid = los_points(st)
    any_valid = valid.any(axis=1)
    X = np.full((st.size, 3), np.nan)
    if any_valid.any():
        X[any_valid] = np.nanmedian(pts[any_valid], axis=1)
    status = np.where(any_valid, Status.CLOSED_FORM, Status.DEGENERATE).astype(np.int8)
    oracle = np.full(st.size, np.nan)
    if st.truth_m is not None and any_valid.any():
        oracle[any_valid] = np.nanmin(np.linalg.norm(pts - st.truth_m[:, None, :], axis=-1)[any_valid], axis=1)
    return X, status, pts, oracle
