"""A GeoTIFF digital elevation model (DEM) read with rasterio, as WGS84 ellipsoidal heights.

The posts (pixel centres) are the nodes of a bilinear surface in the raster's own coordinates (degrees for a
geographic CRS, metres for a projected one); a height query maps WGS84 lat/lon into that CRS (rasterio's PROJ
transform, skipped when the CRS is WGS84 geographic), interpolates bilinearly and adds the geoid undulation
N (pipeline.geometry.geoid, EGM2008) when the heights are orthometric. The vertical datum:

- a vertical CRS in the file (GeoTIFF VerticalCSTypeGeoKey, compound CRS) named EGM96 or EGM2008 height:
  orthometric; NAVD88 height (USGS 3DEP): orthometric, converted with EGM2008 (the difference belongs in the DEM's
  vertical sigma); a 3-D geographic CRS (EPSG:4979, axis "ellipsoidal height"): ellipsoidal; any other vertical CRS
  (a local datum, feet): refused, unless the caller states `vertical_datum`;
- a DTED file (.dt0/.dt1/.dt2): mean sea level (its header's vertical datum, E96 or MSL);
- no vertical CRS (most SRTM, Copernicus, ALOS, ASTER GeoTIFFs): orthometric, the common DEMs' datum (EGM96 for
  SRTM, EGM2008 for Copernicus). Both are converted with EGM2008: EGM96 - EGM2008 is under ~1 m almost
  everywhere (a few metres in high mountains), part of the DEM vertical sigma (docs/terrain.md).
"""

from __future__ import annotations

import contextlib
import re
import warnings
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np

from pipeline.errors import GeometryError, InputError
from pipeline.geometry.frames import enu_from_lla, lla_from_enu

MAX_POSTS = 2**26  # 67 M posts (8192 x 8192, 512 MB as float64): a larger DEM must be cropped first
MAX_SPAN_DEG = 10.0  # a DEM for targeting covers a few tens of km; this also bounds the geoid window read
MIN_POST_M = 0.01
VERTICAL_DATUMS = ("orthometric", "ellipsoidal")
_WGS84_GEOGRAPHIC = {4326, 4979, 9518, 9707}  # 2-D, 3-D, + EGM2008 height, + EGM96 height
_METRE = {"", "m", "metre", "meter", "metres", "meters"}



@contextlib.contextmanager
def _open_quietly(path: Path):
    """rasterio.open without its NotGeoreferencedWarning: a plain image given as the DEM is refused in one line
    ("has no coordinate reference system"), not after two lines of warning on stderr."""
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        ds = rasterio.open(path)
    with ds:
        yield ds

@dataclass(frozen=True)
class VerticalDatum:
    """How the DEM's heights relate to the WGS84 ellipsoid: `kind` "orthometric" (h = H + N) or "ellipsoidal",
    and `source`, a short phrase saying where that came from (the file's CRS, the caller, or the default)."""

    kind: str
    source: str


def _vertical_datum(wkt2: str, stated: str | None, path: Path, driver: str = "", tags=None) -> VerticalDatum:
    if stated is not None:
        if stated not in VERTICAL_DATUMS:
            raise InputError(f"vertical datum must be one of {', '.join(VERTICAL_DATUMS)}, got {stated!r}", path)
        return VerticalDatum(stated, "stated by the user")
    if driver == "DTED":  # DTED heights are above mean sea level (MIL-PRF-89020B); the header names the datum
        name = str((tags or {}).get("DTED_VerticalDatum", "")).strip() or "not named"
        if name.upper() in ("E96", "MSL", "E08", "not named".upper()):
            return VerticalDatum("orthometric", f"the DTED header (vertical datum {name}: mean sea level)")
        raise InputError(f"unknown DTED vertical datum '{name}'; state the DEM's vertical datum (orthometric or "
                         "ellipsoidal) if you know it", path)
    vert = re.search(r'VERTCRS\["([^"]*)"', wkt2)
    if vert:
        name = vert.group(1)
        unit = re.search(r'VERTCRS\[.*?LENGTHUNIT\["([^"]*)"', wkt2[vert.start():], re.S)
        metres = unit is None or unit.group(1).lower() in _METRE
        if re.search(r"EGM ?(96|2008)", name, re.I) and metres:
            return VerticalDatum("orthometric", f"the file's vertical CRS ({name})")
        if re.search(r"NAVD ?88", name, re.I) and metres:  # USGS 3DEP
            return VerticalDatum("orthometric", f"the file's vertical CRS ({name}), converted with EGM2008: NAVD88 "
                                                "is not EGM2008's geoid, count their difference (about a metre in "
                                                "the US) in the DEM's vertical sigma")
        raise InputError(f"unknown vertical datum '{name}' (known: EGM96 or EGM2008 height in metres, or "
                         f"ellipsoidal heights); state the DEM's vertical datum (orthometric or ellipsoidal) "
                         f"if you know it", path)
    if re.search(r'AXIS\["ellipsoidal height', wkt2):
        return VerticalDatum("ellipsoidal", "the file's 3-D geographic CRS (ellipsoidal heights)")
    return VerticalDatum("orthometric", "assumed: the file states no vertical datum (EGM96/EGM2008 heights, as "
                                        "SRTM and Copernicus DEMs)")


class Dem:
    """A DEM as a bilinear surface of WGS84 ellipsoidal heights. Build it with `Dem.open(path)`.

    Attributes: path; heights_m (rows, cols) float64 in the file's vertical datum, NaN where there is no data;
    vertical (VerticalDatum); crs (rasterio CRS); post_m (east-west, north-south post spacing in metres at the
    centre); h_min_m / h_max_m (bounds of the ellipsoidal heights, with 2 m to spare for an orthometric DEM);
    bounds_deg (lat_min, lat_max, lon_min, lon_max) of the posts.
    """

    def __init__(self, path: Path, heights_m: np.ndarray, transform, crs, vertical: VerticalDatum):
        self.path = path
        self.heights_m = heights_m
        self.vertical = vertical
        self.crs = crs
        self._to_grid = ~transform  # CRS x, y -> (col, row) of pixel corners; posts at +0.5
        self._from_grid = transform
        epsg = crs.to_epsg()
        self._identity = epsg in _WGS84_GEOGRAPHIC
        rows, cols = heights_m.shape
        # the posts' outline (edges sampled) in lat/lon: bounds, geoid window, search distances
        k = np.linspace(0.0, 1.0, 9)
        gx = np.concatenate([k * (cols - 1), np.full(9, cols - 1.0), k * (cols - 1), np.zeros(9)])
        gy = np.concatenate([np.zeros(9), k * (rows - 1), np.full(9, rows - 1.0), k * (rows - 1)])
        lat, lon = self._lla_of_grid(gx, gy)
        if not (np.isfinite(lat).all() and np.isfinite(lon).all() and (np.abs(lat) <= 90).all()
                and (np.abs(lon) <= 540).all()):
            raise InputError("its extent does not map to valid latitudes/longitudes (check its geotransform)", path)
        if max(np.ptp(lat), np.ptp(lon)) > MAX_SPAN_DEG:
            raise InputError(f"spans {np.ptp(lat):.3g} deg of latitude and {np.ptp(lon):.3g} deg of longitude, more "
                             f"than {MAX_SPAN_DEG:g} deg (crop the DEM to the area of interest)", path)
        self.outline_deg = np.stack([lat, lon], axis=-1)
        self.bounds_deg = (float(lat.min()), float(lat.max()), float(lon.min()), float(lon.max()))
        self._lon_base = self.bounds_deg[2] - 1.0
        self._geoid = None
        if vertical.kind == "orthometric":
            from pipeline.geometry.geoid import patch_around

            # a cached window of the geoid grid holding the DEM with 0.1 deg to spare (reading one costs ~0.1 s)
            lat_c, lon_c = round((lat.min() + lat.max()) / 2, 1), round((lon.min() + lon.max()) / 2, 1)
            half = max(lat.max() - lat_c, lat_c - lat.min(), lon.max() - lon_c, lon_c - lon.min()) + 0.1
            self._geoid = patch_around(lat_c, lon_c, float(np.ceil(half / 0.25) * 0.25))
        clat, clon = self._lla_of_grid(np.array([(cols - 1) / 2, (cols - 1) / 2 + 1, (cols - 1) / 2]),
                                       np.array([(rows - 1) / 2, (rows - 1) / 2, (rows - 1) / 2 + 1]))
        enu = enu_from_lla(clat, clon, 0.0, (clat[0], clon[0], 0.0))
        self.post_m = (float(np.hypot(*enu[1, :2])), float(np.hypot(*enu[2, :2])))
        if not (np.isfinite(self.post_m).all() and min(self.post_m) >= MIN_POST_M):
            raise InputError(f"has posts {min(self.post_m):.3g} m apart, under {MIN_POST_M:g} m (check its "
                             f"geotransform)", path)
        finite = np.isfinite(heights_m)
        if not finite.any():
            raise InputError("has no height data (every post is nodata)", path)
        # bounds of the ellipsoidal heights (they bound the ray search): the geoid over a 9 x 9 net of the DEM, with
        # 2 m to spare for its extremes between the net's points (the geoid is smooth at these scales)
        gx, gy = np.meshgrid(np.linspace(0, cols - 1, 9), np.linspace(0, rows - 1, 9))
        n = self._geoid_m(*self._lla_of_grid(gx.ravel(), gy.ravel()))
        pad = 2.0 if self._geoid is not None else 0.0
        self.h_min_m = float(np.nanmin(heights_m) + np.nanmin(n) - pad)
        self.h_max_m = float(np.nanmax(heights_m) + np.nanmax(n) + pad)

    # ---- reading ---------------------------------------------------------------------------------------------

    @classmethod
    def open(cls, path: str | PathLike, vertical_datum: str | None = None) -> Dem:
        """Reads band 1 of a GeoTIFF (or any raster GDAL reads) whole. `vertical_datum` ("orthometric" or
        "ellipsoidal") overrides what the file says; None takes it from the file (module docstring). Every
        problem is one InputError naming the file: missing, unreadable, no CRS or geotransform, a CRS that
        does not map to WGS84, an unknown vertical datum, heights not in metres, fewer than 2 x 2 posts, more
        than MAX_POSTS, no data."""
        import rasterio
        from rasterio.errors import RasterioError

        path = Path(path)
        if path.is_dir():
            raise InputError("is a directory, expected a GeoTIFF DEM", path)
        if not path.is_file():
            raise InputError("file not found", path)
        try:
            with rasterio.Env(GTIFF_REPORT_COMPD_CS=True, CPL_LOG="/dev/null"), _open_quietly(path) as ds:
                if ds.count < 1:
                    raise InputError("has no raster band", path)
                rows, cols = ds.height, ds.width
                if rows < 2 or cols < 2:
                    raise InputError(f"has {rows} x {cols} posts; a DEM needs at least 2 x 2", path)
                if rows * cols > MAX_POSTS:
                    raise InputError(f"has {rows} x {cols} posts, over the {MAX_POSTS:,} limit (crop the DEM to "
                                     f"the area of interest, e.g. gdal_translate -projwin)", path)
                if ds.crs is None:
                    raise InputError("has no coordinate reference system (not a georeferenced DEM)", path)
                transform, crs = ds.transform, ds.crs
                if transform.is_identity or not np.isfinite(list(transform)[:6]).all() \
                        or abs(transform.determinant) == 0:
                    raise InputError("has no usable geotransform (pixel to map coordinates)", path)
                try:
                    wkt2 = crs.to_wkt(version="WKT2_2019")
                except Exception as exc:  # rasterio raises its own CRSError or GDAL's for an odd CRS
                    raise InputError(f"unknown CRS: {str(exc).splitlines()[0][:120]}", path) from None
                units = (ds.units[0] or "").strip().lower() if ds.units else ""
                if units not in _METRE:
                    raise InputError(f"heights are in '{units}', only metres are supported", path)
                vertical = _vertical_datum(wkt2, vertical_datum, path, ds.driver, ds.tags())
                try:
                    _check_crs(crs, transform, rows, cols)
                except Exception:  # PROJ's own messages are long JSON dumps
                    name = re.search(r'^\w+\["([^"]*)"', wkt2)
                    raise InputError(f"unknown CRS '{name.group(1) if name else crs.to_string()[:60]}': it does not "
                                     f"map to WGS84 (a local or engineering CRS, another body, or one PROJ cannot "
                                     f"relate to WGS84)", path) from None
                heights = ds.read(1, out_dtype="float64")
                heights[ds.read_masks(1) == 0] = np.nan
                scale, offset = (ds.scales[0] if ds.scales else 1.0), (ds.offsets[0] if ds.offsets else 0.0)
        except InputError:
            raise
        except MemoryError:
            raise InputError("cannot be read within the memory available", path) from None
        except (RasterioError, OSError, ValueError, TypeError) as exc:
            msg = str(exc).splitlines()[0][:160] if str(exc) else type(exc).__name__
            raise InputError(f"not a readable GeoTIFF DEM: {msg}", path) from None
        if (scale, offset) != (1.0, 0.0):
            heights *= float(scale)
            heights += float(offset)
        with np.errstate(invalid="ignore"):
            heights[~(np.abs(heights) <= 20_000.0)] = np.nan  # no ground is 20 km from sea level; inf, NaN
        return cls(path, heights, transform, crs, vertical)

    # ---- coordinates -----------------------------------------------------------------------------------------

    def _grid_of_lla(self, lat_deg: np.ndarray, lon_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grid coordinates (gx, gy) of WGS84 points: the post of column i, row j is at (i, j)."""
        if self._identity:  # longitudes into the file's own 360 deg range (a DEM across 180 deg E writes 180.5)
            x, y = self._lon_base + (lon_deg - self._lon_base) % 360.0, lat_deg
        else:
            x, y = _transform_xy("EPSG:4326", self.crs, lon_deg, lat_deg)
        a, b, c, d, e, f = list(self._to_grid)[:6]
        return a * x + b * y + c - 0.5, d * x + e * y + f - 0.5

    def _lla_of_grid(self, gx: np.ndarray, gy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, c, d, e, f = list(self._from_grid)[:6]
        x, y = a * (gx + 0.5) + b * (gy + 0.5) + c, d * (gx + 0.5) + e * (gy + 0.5) + f
        if self._identity:
            return np.asarray(y, dtype=np.float64), np.asarray(x, dtype=np.float64)
        lon, lat = _transform_xy(self.crs, "EPSG:4326", x, y)
        return lat, lon

    def _geoid_m(self, lat_deg, lon_deg) -> np.ndarray:
        if self._geoid is None:
            return np.zeros(np.shape(lat_deg))
        return self._geoid(lat_deg, lon_deg)

    # ---- heights ---------------------------------------------------------------------------------------------

    def _bilinear(self, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
        """Heights in the file's datum at grid coordinates; NaN outside the posts or next to a nodata post."""
        rows, cols = self.heights_m.shape
        inside = (gx >= 0) & (gx <= cols - 1) & (gy >= 0) & (gy <= rows - 1)
        gx = np.where(inside, gx, 0.0)
        gy = np.where(inside, gy, 0.0)
        i = np.clip(np.floor(gx).astype(np.intp), 0, cols - 2)
        j = np.clip(np.floor(gy).astype(np.intp), 0, rows - 2)
        fx, fy = gx - i, gy - j
        z = self.heights_m
        h = ((z[j, i] * (1 - fx) + z[j, i + 1] * fx) * (1 - fy)
             + (z[j + 1, i] * (1 - fx) + z[j + 1, i + 1] * fx) * fy)
        return np.where(inside, h, np.nan)

    def height_wgs84_m(self, lat_deg, lon_deg) -> np.ndarray:
        """Ellipsoidal (WGS84) height of the bilinear DEM surface at lat/lon (degrees, any shape, broadcast);
        NaN outside the DEM's posts or in a cell touching a nodata post."""
        lat, lon = np.broadcast_arrays(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64))
        out = np.full(lat.shape, np.nan)
        ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90)
        if ok.any():
            gx, gy = self._grid_of_lla(lat[ok], lon[ok])
            h = self._bilinear(gx, gy)
            on = np.isfinite(h)  # the geoid only where there is ground (its window covers the DEM alone)
            h[on] += self._geoid_m(lat[ok][on], lon[ok][on])
            out[ok] = h
        return out

    def local(self, origin_lat_deg: float, origin_lon_deg: float, origin_h_m: float):
        """The terrain in the ENU frame at the origin (ellipsoid height origin_h_m): a function
        (e_m, n_m) -> (up_m, dup_de, dup_dn), arrays of the broadcast shape, where (e, n, up) is the point of the
        DEM surface above or below (e, n) along the frame's up axis, and the slopes are central differences at
        a twentieth of a post (the bilinear surface's own slope except within that of a cell edge). NaN outside
        the DEM."""
        origin = (float(origin_lat_deg), float(origin_lon_deg), float(origin_h_m))
        step = 0.05 * min(self.post_m)

        def up_at(e, n):
            u = np.zeros(e.shape)
            for _ in range(4):  # fixed point: u moves by (ground h - point h); lat/lon hardly move with u
                lla = lla_from_enu(np.stack([e, n, u], axis=-1), origin)
                u = u + (self.height_wgs84_m(lla[..., 0], lla[..., 1]) - lla[..., 2])
            return u

        def terrain(e_m, n_m):
            e, n = np.broadcast_arrays(np.asarray(e_m, dtype=np.float64), np.asarray(n_m, dtype=np.float64))
            u, e1, e0, n1, n0 = up_at(np.stack([e, e + step, e - step, e, e]), np.stack([n, n, n, n + step, n - step]))
            return u, (e1 - e0) / (2 * step), (n1 - n0) / (2 * step)

        return terrain

    # ---- rays ------------------------------------------------------------------------------------------------

    def intersect_many(self, origins_lla, directions_enu) -> tuple[np.ndarray, list[str | None]]:
        """Vectorised `intersect` of k rays, origins_lla (k, 3) and directions_enu (k, 3) (each in the ENU frame at
        its origin): lla (k, 3) of the hits (NaN rows for misses) and k reasons (None for a hit, else a phrase
        saying why the ray misses)."""
        from pipeline.terrain.raycast import intersect_rays

        return intersect_rays(self, origins_lla, directions_enu)

    def intersect(self, origin_lla, direction_enu, label: str | None = None) -> tuple[float, float, float]:
        """(lat_deg, lon_deg, h_wgs84_m) of the first point where the ray from `origin_lla` (lat_deg, lon_deg,
        ellipsoid height m) along `direction_enu` (3,) (any length; the ENU frame at the origin) meets the DEM
        surface. A GeometryError (an InputError) of one line naming `label` (e.g. the photo and pixel) and the
        DEM when the ray leaves the DEM, never meets it, or starts below it."""
        from pipeline.terrain.raycast import intersect_rays

        lla, reasons = intersect_rays(self, np.asarray(origin_lla, dtype=np.float64)[None],
                                      np.asarray(direction_enu, dtype=np.float64)[None])
        if reasons[0] is not None:
            raise GeometryError(f"{label + ': ' if label else ''}{reasons[0]} (DEM {self.path})")
        return float(lla[0, 0]), float(lla[0, 1]), float(lla[0, 2])


def _transform_xy(src, dst, x, y) -> tuple[np.ndarray, np.ndarray]:
    from rasterio.warp import transform

    x = np.asarray(x, dtype=np.float64)
    shape = x.shape
    xs, ys = transform(src, dst, x.ravel(), np.asarray(y, dtype=np.float64).ravel())
    return np.asarray(xs, dtype=np.float64).reshape(shape), np.asarray(ys, dtype=np.float64).reshape(shape)


def _check_crs(crs, transform, rows: int, cols: int) -> None:
    """Raises when the DEM's centre does not round-trip through WGS84 (an engineering or unknown CRS)."""
    if crs.to_epsg() in _WGS84_GEOGRAPHIC:
        return
    a, b, c, d, e, f = list(transform)[:6]
    x, y = a * cols / 2 + b * rows / 2 + c, d * cols / 2 + e * rows / 2 + f
    lon, lat = _transform_xy(crs, "EPSG:4326", [x], [y])
    if not (np.isfinite(lon).all() and np.isfinite(lat).all() and abs(lat[0]) <= 90):
        raise ValueError("the DEM's centre has no WGS84 latitude/longitude")
    x2, y2 = _transform_xy("EPSG:4326", crs, lon, lat)
    tol = 0.01 * min(np.hypot(transform.a, transform.d), np.hypot(transform.b, transform.e))  # of a pixel
    if not (abs(x2[0] - x) <= tol and abs(y2[0] - y) <= tol):
        raise ValueError("the DEM's centre does not round-trip through WGS84")
