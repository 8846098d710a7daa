"""Synthetic GeoTIFF DEMs of a known analytic terrain, for tests, benchmarks and synthetic photo flights.

`Hills` is the truth: a WGS84 ellipsoidal height as a smooth function of the horizontal position in the ENU
frame at its centre (a base height plus a few cosine ridges). `write_dem` samples it at the posts of a grid in
a chosen CRS and writes the heights in the vertical datum the CRS says (or the one the caller names): h for an
ellipsoidal DEM, h - N (EGM2008 geoid) for an orthometric one.

    from pipeline.synth.dem import Hills, write_dem
    hills = Hills(46.5, 7.5, base_m=600.0)
    write_dem("dem.tif", hills, extent_m=4000.0, post_m=30.0, crs="EPSG:32632")
"""

from __future__ import annotations

from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np
import pymap3d

# (amplitude m, wavelength m, azimuth deg, phase rad) of each ridge
DEFAULT_RIDGES = ((80.0, 2400.0, 20.0, 0.3), (35.0, 1100.0, 115.0, 1.1), (12.0, 520.0, 250.0, 2.0))


@dataclass(frozen=True)
class Hills:
    """h(lat, lon) = base_m + sum_k A_k cos(2 pi (e sin az_k + n cos az_k) / L_k + phase_k), metres above the
    WGS84 ellipsoid, with (e, n) the horizontal ENU position (m) at (lat0_deg, lon0_deg, 0)."""

    lat0_deg: float
    lon0_deg: float
    base_m: float = 500.0
    ridges: tuple = field(default=DEFAULT_RIDGES)

    def h_wgs84_m(self, lat_deg, lon_deg) -> np.ndarray:
        e, n, _ = pymap3d.geodetic2enu(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64),
                                       0.0, self.lat0_deg, self.lon0_deg, 0.0)
        h = np.full(np.shape(e), float(self.base_m))
        for amp, wavelength, az_deg, phase in self.ridges:
            az = np.radians(az_deg)
            h = h + amp * np.cos(2 * np.pi * (e * np.sin(az) + n * np.cos(az)) / wavelength + phase)
        return h


def write_dem(path: str | PathLike, hills: Hills, extent_m: float = 4000.0, post_m: float = 30.0,
              crs: str = "EPSG:4326", vertical_datum: str | None = None, dtype: str = "float32",
              nodata: float | None = None, compress: str | None = None) -> Path:
    """Writes a square DEM of side `extent_m` centred on the hills' centre with posts every ~`post_m` metres, in
    `crs` (a geographic CRS: posts on a lat/lon grid; a projected one: on its x/y grid), as a GeoTIFF.

    The heights are in `vertical_datum` ("orthometric" or "ellipsoidal"); None takes the one a reader infers
    from `crs` (pipeline.terrain.dem): ellipsoidal for a 3-D geographic CRS (EPSG:4979), otherwise orthometric.
    """
    import rasterio
    from rasterio.crs import CRS
    from rasterio.transform import from_origin
    from rasterio.warp import transform

    crs_obj = CRS.from_string(crs)
    if vertical_datum is None:
        vertical_datum = "ellipsoidal" if "ellipsoidal height" in crs_obj.to_wkt(version="WKT2_2019") \
            else "orthometric"
    half = extent_m / 2
    n_lon = n_lat = round(extent_m / post_m) + 1
    if crs_obj.is_geographic:
        dlat = post_m / 111_320.0
        dlon = dlat / np.cos(np.radians(hills.lat0_deg))
        x0, y0 = hills.lon0_deg - dlon * (n_lon - 1) / 2, hills.lat0_deg + dlat * (n_lat - 1) / 2
        dx, dy = dlon, dlat
    else:
        (cx,), (cy,) = transform("EPSG:4326", crs_obj, [hills.lon0_deg], [hills.lat0_deg])
        x0, y0 = cx - half, cy + half
        dx = dy = post_m
    xs = x0 + dx * np.arange(n_lon)
    ys = y0 - dy * np.arange(n_lat)
    X, Y = np.meshgrid(xs, ys)
    if crs_obj.is_geographic:
        lon, lat = X, Y
    else:
        lon, lat = (np.asarray(v).reshape(X.shape) for v in transform(crs_obj, "EPSG:4326", X.ravel(), Y.ravel()))
    h = hills.h_wgs84_m(lat, lon)
    if vertical_datum == "orthometric":
        from pipeline.geometry.geoid import geoid_undulation_m

        h = h - geoid_undulation_m(lat, lon)
    path = Path(path)
    profile = dict(driver="GTiff", width=n_lon, height=n_lat, count=1, dtype=dtype, crs=crs_obj,
                   transform=from_origin(x0 - dx / 2, y0 + dy / 2, dx, dy))
    if nodata is not None:
        profile["nodata"] = nodata
    if compress is not None:
        profile["compress"] = compress
    with rasterio.open(path, "w", **profile) as ds:
        ds.write((np.round(h) if np.dtype(dtype).kind in "iu" else h).astype(dtype)[None])
    return path


def ray_truth_ecef(origins_lla: np.ndarray, directions_enu: np.ndarray, height_fn, t_max_m: float = 6000.0,
                   step_m: float = 0.5) -> np.ndarray:
    """The first point (k, 3) (ECEF m) of each ray below the surface `height_fn(lat_deg, lon_deg)` (ellipsoidal
    m): samples every step_m up to t_max_m, then 60 bisections of the first bracket. A reference for the ray
    caster (pipeline.terrain.raycast), deliberately the plain way: it shares no code with it. NaN rows for rays
    that do not go below the surface within t_max_m."""
    from pipeline.geometry.frames import R_ecef_from_enu, ecef_from_lla

    origins = np.asarray(origins_lla, dtype=np.float64)
    d = np.asarray(directions_enu, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    O = ecef_from_lla(origins[:, 0], origins[:, 1], origins[:, 2])
    D = np.einsum("kij,kj->ki", R_ecef_from_enu(origins[:, 0], origins[:, 1]), d)

    def above(t):  # t (k,) or (k, m)
        p = O[:, None, :] + t[..., None] * D[:, None, :] if t.ndim == 2 else O + t[:, None] * D
        lat, lon, h = pymap3d.ecef2geodetic(p[..., 0], p[..., 1], p[..., 2])
        return h - height_fn(lat, lon)

    ts = np.arange(0.0, t_max_m, step_m)
    below = above(np.broadcast_to(ts, (len(O), ts.size))) < 0
    j = np.maximum(below.argmax(axis=1), 1)
    lo, hi = ts[j - 1], ts[j]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        b = above(mid) < 0
        hi, lo = np.where(b, mid, hi), np.where(b, lo, mid)
    out = O + lo[:, None] * D
    out[~below.any(axis=1)] = np.nan
    return out


def incidence_sin(points_ecef: np.ndarray, directions_enu: np.ndarray, height_fn, step_m: float = 1.0) -> np.ndarray:
    """|sin| of the angle (k,) between each ray (unit direction (k, 3), ENU; the ENU frames of the ray's origin
    and of its hit differ by ~0.01 deg per km) and the surface `height_fn` at its hit (ECEF (k, 3)), from the
    surface's slope by central differences over +-step_m. A DEM height error dh moves the hit by ~dh / sin."""
    lat, lon, h = pymap3d.ecef2geodetic(points_ecef[:, 0], points_ecef[:, 1], points_ecef[:, 2])

    def at(de, dn):
        la, lo, _ = pymap3d.enu2geodetic(de, dn, 0.0, lat, lon, h)
        return height_fn(la, lo)

    ge = (at(step_m, 0.0) - at(-step_m, 0.0)) / (2 * step_m)
    gn = (at(0.0, step_m) - at(0.0, -step_m)) / (2 * step_m)
    normal = np.stack([-ge, -gn, np.ones_like(ge)], axis=1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    d = np.asarray(directions_enu, dtype=np.float64)
    return np.abs((normal * d).sum(axis=1)) / np.linalg.norm(d, axis=1)


def bilinear_error_bound_m(hills: Hills, post_m: float) -> float:
    """An upper bound of |bilinear interpolation - terrain| for the hills sampled every post_m (m) in both
    directions: sum_k A_k (2 pi / L_k)^2 (2 post^2) / 8, the second-derivative bound of each ridge."""
    return float(sum(a * (2 * np.pi / wl) ** 2 * 2 * post_m ** 2 / 8 for a, wl, _, _ in hills.ridges))
