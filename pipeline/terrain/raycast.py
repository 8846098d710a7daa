"""First intersection of rays with a DEM's bilinear surface: cell traversal, then an exact solve in the cell.

A ray x(t) = O + t D (ECEF, t in metres) is cut at every grid line it crosses, so each piece lies in one DEM
cell. On a piece the height above the surface, f(t) = h(x(t)) - H(lat(t), lon(t)), is a quadratic in t (the
bilinear patch along a straight track; the ray's curvature against the ellipsoid and the map projection's are
below a micrometre over a cell), so its three samples (ends and middle) give the piece's first root exactly,
including a ray that dips below a ridge and out again inside one cell. The root is then polished by bisection
on the exact f (ECEF -> geodetic with pymap3d, the DEM's own CRS transform and geoid), so the answer is the
bilinear surface's intersection to ~1e-6 m, whatever the post spacing: nothing is marched at a fixed step.

Crossings are found on the ray's track in grid coordinates, linear between nodes every NODE_POSTS posts
(the track's curvature between nodes displaces a crossing by well under a millimetre). Rays are processed
together, a block of nodes at a time, until each has met the ground or stopped; the cost is proportional to
the cells crossed before the hit.
"""

from __future__ import annotations

import numpy as np
import pymap3d

from pipeline.geometry.frames import R_ecef_from_enu, ecef_from_lla
from pipeline.geometry.geodesic import geodesic_m

NODE_POSTS = 64  # node spacing along the ray, in posts (horizontally)
MAX_NODES = 20_000  # node intervals per ray at most (the crossings per interval are bounded by the grid)
BLOCK_NODES = 8  # node intervals per ray handled in one vectorised block
R_MIN_M = 6.3e6  # below the ellipsoid's smallest radius of curvature: bounds the ray's rise over it
TOL_M = 1e-6  # the polished root: |f| or the bracket below this
MAX_POLISH = 60


def _f(dem, O: np.ndarray, D: np.ndarray, ray: np.ndarray, t: np.ndarray):
    """Height of the ray points above the DEM surface (NaN outside it) and their lat, lon, h."""
    p = O[ray] + t[:, None] * D[ray]
    lat, lon, h = pymap3d.ecef2geodetic(p[:, 0], p[:, 1], p[:, 2])
    lat, lon, h = (np.asarray(v, dtype=np.float64) for v in (lat, lon, h))
    return h - dem.height_wgs84_m(lat, lon), lat, lon, h


def _first_root(f0: np.ndarray, fm: np.ndarray, f1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For quadratics through (0, f0), (1/2, fm), (1, f1) with f0 >= 0: the first tau in [0, 1] where they reach
    0 (NaN if none) and the end of a bracket [0, tau_b] over which they go from >= 0 to < 0 (the vertex when the
    quadratic dips below 0 and comes back up inside the piece)."""
    a = 2.0 * (f1 + f0 - 2.0 * fm)
    b = f1 - f0 - a
    c = f0
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - 4 * a * c
        sq = np.sqrt(np.maximum(disc, 0.0))
        q = -0.5 * (b + np.where(b >= 0, sq, -sq))
        r1, r2 = q / a, c / q
        lin = -c / b
    tiny = np.abs(a) <= 1e-12 * (np.abs(b) + np.abs(c) + 1e-300)
    r1 = np.where(tiny, lin, np.where(disc >= 0, r1, np.nan))
    r2 = np.where(tiny, np.nan, np.where(disc >= 0, r2, np.nan))
    r1 = np.where((r1 >= 0) & (r1 <= 1), r1, np.nan)
    r2 = np.where((r2 >= 0) & (r2 <= 1), r2, np.nan)
    tau = np.fmin(r1, r2)
    crosses = f1 < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(crosses & np.isnan(tau), f0 / (f0 - f1), tau)  # numerically missed: the secant root
        vertex = np.clip(-b / (2 * a), 0.0, 1.0)
    tau_b = np.where(crosses, 1.0, vertex)
    return tau, tau_b


def _polish(fun, lo: np.ndarray, hi: np.ndarray, f_lo: np.ndarray, f_hi: np.ndarray) -> np.ndarray:
    """Roots of fun(i, t) (the rays i at t) in brackets with f_lo >= 0 > f_hi: the Illinois variant of regula
    falsi (superlinear; a handful of steps from the quadratic's bracket), a bisection step where fun is NaN
    (at a data edge: counted as below, so the root stays on the side with data)."""
    lo, hi, f_lo, f_hi = (np.array(v, dtype=np.float64) for v in (lo, hi, f_lo, f_hi))
    t = 0.5 * (lo + hi)
    last = np.zeros(lo.size, np.int8)  # which end moved last: +1 hi, -1 lo
    todo = np.ones(lo.size, bool)
    for _ in range(MAX_POLISH):
        i = np.flatnonzero(todo)
        if i.size == 0:
            break
        with np.errstate(divide="ignore", invalid="ignore"):
            ti = lo[i] - f_lo[i] * (hi[i] - lo[i]) / (f_hi[i] - f_lo[i])
        ti = np.where(np.isfinite(ti) & (ti > lo[i]) & (ti < hi[i]), ti, 0.5 * (lo[i] + hi[i]))
        fi = fun(i, ti)
        nan = np.isnan(fi)
        below = nan | (fi < 0)
        t[i] = ti
        # Illinois: an end kept twice in a row has its value halved, so the secant stops creeping
        keep_lo = below & (last[i] == 1)
        keep_hi = ~below & (last[i] == -1)
        f_lo[i] = np.where(keep_lo, 0.5 * f_lo[i], f_lo[i])
        f_hi[i] = np.where(keep_hi, 0.5 * f_hi[i], f_hi[i])
        hi[i] = np.where(below, ti, hi[i])
        f_hi[i] = np.where(below, np.where(nan, -np.abs(f_lo[i]) - TOL_M, fi), f_hi[i])
        lo[i] = np.where(below, lo[i], ti)
        f_lo[i] = np.where(below, f_lo[i], fi)
        last[i] = np.where(below, 1, -1)
        todo[i] = ~((~nan & (np.abs(fi) < TOL_M)) | (hi[i] - lo[i] < TOL_M))
    return t


def _crossings(g: np.ndarray, t: np.ndarray, ray: np.ndarray, n_lines: int):
    """Parameters t where tracks cross the integer lines 0..n_lines-1 of one grid coordinate. g, t (k, m+1) node
    values; ray (k,). Returns (ray ids, t) flat."""
    a, b = g[:, :-1], g[:, 1:]
    ta, tb = t[:, :-1], t[:, 1:]
    ok = np.isfinite(a) & np.isfinite(b) & (a != b)
    lo = np.where(ok, np.minimum(a, b), 0.0)
    hi = np.where(ok, np.maximum(a, b), 0.0)
    m0 = np.maximum(np.floor(lo) + 1, 0)
    m1 = np.minimum(np.ceil(hi) - 1, n_lines - 1)
    count = np.where(ok, np.maximum(m1 - m0 + 1, 0), 0).astype(np.intp).ravel()
    total = int(count.sum())
    if total == 0:
        return np.zeros(0, np.intp), np.zeros(0)
    seg = np.repeat(np.arange(count.size), count)
    start = np.cumsum(count) - count
    m = m0.ravel()[seg] + (np.arange(total) - start[seg])
    a, b, ta, tb = a.ravel()[seg], b.ravel()[seg], ta.ravel()[seg], tb.ravel()[seg]
    tc = ta + (m - a) / (b - a) * (tb - ta)
    rays = np.broadcast_to(ray[:, None], g[:, :-1].shape).ravel()[seg]
    return rays, tc


def _where_the_dem_is(dem, origin_lla: np.ndarray) -> str:
    """For a ray that misses the DEM's area from a camera outside it: where the DEM is, and how far (a DEM of
    another site says so), e.g. "; the DEM covers lat 40.7088..40.7121, lon -111.8962..-111.8925, about 1812 km
    from the camera" (the geodesic to the nearest point of its outline). Empty for a camera over the DEM's bounds."""
    lat0, lat1, lon0, lon1 = dem.bounds_deg
    lat, lon = float(origin_lla[0]), float(origin_lla[1])
    if lat0 <= lat <= lat1 and lon0 <= lon <= lon1:
        return ""
    d_m = float(geodesic_m(lat, lon, dem.outline_deg[:, 0], dem.outline_deg[:, 1]).min())  # to the nearest of the
    # outline's sampled points: within a few posts
    far = f"{d_m / 1000:.0f} km" if d_m >= 10_000 else f"{d_m:.0f} m"
    return f"; the DEM covers lat {lat0:.4f}..{lat1:.4f}, lon {lon0:.4f}..{lon1:.4f}, about {far} from the camera"


def intersect_rays(dem, origins_lla: np.ndarray, directions_enu: np.ndarray):
    """First ground hits of k rays. origins_lla (k, 3) (lat_deg, lon_deg, ellipsoid height m); directions_enu
    (k, 3) in the ENU frame at each origin (any length). Returns lla (k, 3) (NaN where there is no hit) and a
    list of k reasons: None for a hit, otherwise one phrase saying why there is none."""
    origins = np.asarray(origins_lla, dtype=np.float64).reshape(-1, 3)
    dirs = np.asarray(directions_enu, dtype=np.float64).reshape(-1, 3)
    k = origins.shape[0]
    out = np.full((k, 3), np.nan)
    reasons: list[str | None] = ["no result"] * k
    norm = np.linalg.norm(dirs, axis=1)
    good = np.isfinite(origins).all(axis=1) & np.isfinite(dirs).all(axis=1) & (norm > 0) \
        & (np.abs(origins[:, 0]) <= 90)
    for r in np.flatnonzero(~good):
        reasons[r] = "the ray has no finite origin or direction"
    if not good.any():
        return out, reasons
    d = np.where(good[:, None], dirs / np.where(norm > 0, norm, 1.0)[:, None], [0.0, 0.0, -1.0])
    o = np.where(good[:, None], origins, 0.0)
    O = ecef_from_lla(o[:, 0], o[:, 1], o[:, 2])
    D = np.einsum("kij,kj->ki", R_ecef_from_enu(o[:, 0], o[:, 1]), d)

    # how far to search: past the DEM's outline horizontally, below its lowest post, or above its highest
    post = min(dem.post_m)
    e, n, _ = pymap3d.geodetic2enu(dem.outline_deg[None, :, 0], dem.outline_deg[None, :, 1], 0.0,
                                   o[:, 0, None], o[:, 1, None], 0.0)
    s_max = np.hypot(e, n).max(axis=1) + 2 * post
    d_h, d_up, h0 = np.hypot(d[:, 0], d[:, 1]), d[:, 2], o[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_h = np.where(d_h > 1e-12, s_max / d_h, np.inf)
        margin = s_max ** 2 / (2 * R_MIN_M) + 1.0
        t_v = np.where(d_up < 0, (h0 - dem.h_min_m + margin) / -d_up, np.inf)
        t_up = np.where(d_up > 0, (dem.h_max_m + 1.0 - h0) / d_up, np.inf)
    t_up = np.where((d_up >= 0) & (h0 > dem.h_max_m), 0.0, t_up)
    t_far = np.minimum(np.minimum(t_h, t_v), t_up)
    above = good & (t_far <= 0)
    for r in np.flatnonzero(above):
        reasons[r] = (f"the ray never meets the ground: it points above the terrain (starts at {h0[r]:.1f} m, "
                      f"above the DEM's highest post at {dem.h_max_m:.1f} m; WGS84 ellipsoidal heights)")
    node_t = np.where(d_h * t_far > 0, NODE_POSTS * post / np.maximum(d_h, 1e-300), t_far)
    node_t = np.clip(node_t, t_far / MAX_NODES, t_far)  # a camera 1000s of posts from a fine DEM: bounded work
    n_int = np.where(t_far > 0, np.ceil(t_far / np.where(node_t > 0, node_t, 1.0)), 0).astype(np.int64)
    rows, cols = dem.heights_m.shape

    active = good & ~above
    entered = np.zeros(k, bool)
    hit_seg = {}  # ray -> (t0, t1, tau, tau_b, f0) of the piece holding its hit
    block = 0
    while active.any():
        ids = np.flatnonzero(active)
        q = block * BLOCK_NODES + np.arange(BLOCK_NODES + 1)
        t_nodes = np.minimum(q[None, :] * node_t[ids, None], t_far[ids, None])  # (m, B+1)
        last = (block + 1) * BLOCK_NODES >= n_int[ids]
        pts = O[ids, None, :] + t_nodes[..., None] * D[ids, None, :]
        lat, lon, _ = pymap3d.ecef2geodetic(pts[..., 0], pts[..., 1], pts[..., 2])
        gx, gy = dem._grid_of_lla(np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64))
        rx, tx = _crossings(gx, t_nodes, ids, cols)
        ry, ty = _crossings(gy, t_nodes, ids, rows)
        ray = np.concatenate([np.repeat(ids, t_nodes.shape[1]), rx, ry])
        t = np.concatenate([t_nodes.ravel(), tx, ty])
        order = np.lexsort((t, ray))
        ray, t = ray[order], t[order]
        keep = np.ones(t.size, bool)
        keep[1:] = (ray[1:] != ray[:-1]) | (t[1:] > t[:-1])
        ray, t = ray[keep], t[keep]
        f, *_ = _f(dem, O, D, ray, t)
        # pieces between consecutive samples of the same ray
        piece = np.flatnonzero(ray[1:] == ray[:-1])
        pr, t0, t1 = ray[piece], t[piece], t[piece + 1]
        f0, f1 = f[piece], f[piece + 1]
        fm, *_ = _f(dem, O, D, pr, 0.5 * (t0 + t1))
        valid = np.isfinite(f0) & np.isfinite(fm) & np.isfinite(f1)
        tau, tau_b = _first_root(np.where(valid, f0, 0.0), np.where(valid, fm, 0.0), np.where(valid, f1, 0.0))
        is_hit = valid & (f0 >= 0) & np.isfinite(tau)
        is_below = valid & (f0 < 0)
        first_of_ray = np.searchsorted(pr, pr, side="left")
        cum = np.cumsum(valid) - valid
        entered_before = entered[pr] | (cum - cum[first_of_ray] > 0)
        is_leave = ~valid & entered_before
        event = is_hit | is_below | is_leave
        ev = np.flatnonzero(event)
        ev_rays, first = np.unique(pr[ev], return_index=True)
        for r, e in zip(ev_rays, ev[first], strict=True):
            active[r] = False
            if is_hit[e]:
                hit_seg[r] = (t0[e], t1[e], tau[e], tau_b[e], f0[e])
            elif is_below[e]:
                ll = _f(dem, O, D, np.array([r]), np.array([t0[e]]))
                where = f"{ll[1][0]:.6f}, {ll[2][0]:.6f}"
                if t0[e] == 0.0:
                    reasons[r] = (f"the ray starts below the DEM surface (at {where}, {h0[r]:.1f} m WGS84 "
                                  f"ellipsoidal height, {-f0[e]:.1f} m under the ground)")
                else:
                    reasons[r] = (f"the ray enters the DEM's data below its surface at {where}: the ground it "
                                  f"meets is outside the DEM")
            else:
                ll = _f(dem, O, D, np.array([r]), np.array([t0[e]]))
                reasons[r] = (f"the ray leaves the DEM's data at {ll[1][0]:.6f}, {ll[2][0]:.6f} "
                              f"({t0[e]:.0f} m from the camera) without meeting the ground")
        any_valid = np.zeros(k, bool)
        any_valid[pr[valid]] = True
        entered |= any_valid
        for r in ids[last]:
            if active[r]:
                active[r] = False
                if entered[r]:
                    reasons[r] = "the ray never meets the ground within the DEM: it passes above the terrain"
                elif t_far[r] == t_v[r]:
                    reasons[r] = (f"the ray meets the ground outside the DEM: it drops below the DEM's lowest post "
                                  f"({dem.h_min_m:.1f} m WGS84 ellipsoidal) without crossing its area"
                                  + _where_the_dem_is(dem, o[r]))
                else:
                    reasons[r] = "the ray never crosses the DEM's area" + _where_the_dem_is(dem, o[r])
        block += 1

    if hit_seg:
        rs = np.array(sorted(hit_seg))
        t0, t1, tau, tau_b, f0 = (np.array([hit_seg[r][i] for r in rs]) for i in range(5))
        hi = t0 + tau_b * (t1 - t0)
        f_hi, *_ = _f(dem, O, D, rs, hi)
        bracketed = f_hi < 0
        t_hit = t0 + tau * (t1 - t0)
        if bracketed.any():
            b = np.flatnonzero(bracketed)
            t_hit[b] = _polish(lambda i, t: _f(dem, O, D, rs[b][i], t)[0], t0[b], hi[b], f0[b], f_hi[b])
        _, lat, lon, h = _f(dem, O, D, rs, t_hit)
        out[rs] = np.stack([lat, lon, h], axis=-1)
        for r in rs:
            reasons[r] = None
    return out, reasons
