"""Geodetic frames: WGS84 latitude/longitude/height <-> a local ENU frame at a chosen origin, and the rotation
from a vehicle's own local level frame (NED at its position) into that common ENU frame.

Heights are above the WGS84 ellipsoid (EPSG:4979) unless a name says otherwise; `ellipsoid_from_amsl_m` converts
mean-sea-level altitudes with the geoid separation N (ellipsoid height = AMSL height + N) the flight states.
Geodesy is pymap3d's; this module only names the compositions.
"""

from __future__ import annotations

import numpy as np
import pymap3d

from pipeline.errors import GeometryError

# The same local frame written NED or ENU: ENU vector = R_ENU_FROM_NED @ NED vector.
R_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def ellipsoid_from_amsl_m(alt_amsl_m, geoid_separation_m: float) -> np.ndarray:
    """Ellipsoidal height (m) from an AMSL altitude and the geoid separation N = h_ellipsoid - H_amsl (m)."""
    return np.asarray(alt_amsl_m, dtype=np.float64) + float(geoid_separation_m)


def enu_from_lla(lat_deg, lon_deg, alt_m, origin_lla: tuple[float, float, float]) -> np.ndarray:
    """(..., 3) ENU metres at `origin_lla` = (lat_deg, lon_deg, ellipsoid height m) of WGS84 points (ellipsoid
    heights)."""
    lat0, lon0, h0 = origin_lla
    e, n, u = pymap3d.geodetic2enu(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64),
                                   np.asarray(alt_m, dtype=np.float64), lat0, lon0, h0)
    return np.stack(np.broadcast_arrays(e, n, u), axis=-1).astype(np.float64)


def lla_from_enu(enu_m, origin_lla: tuple[float, float, float]) -> np.ndarray:
    """(..., 3) (lat_deg, lon_deg, ellipsoid height m) of ENU points (..., 3) at `origin_lla`."""
    enu = np.asarray(enu_m, dtype=np.float64)
    lat0, lon0, h0 = origin_lla
    lat, lon, h = pymap3d.enu2geodetic(enu[..., 0], enu[..., 1], enu[..., 2], lat0, lon0, h0)
    return np.stack(np.broadcast_arrays(lat, lon, h), axis=-1).astype(np.float64)


def ecef_from_lla(lat_deg, lon_deg, alt_m) -> np.ndarray:
    """(..., 3) ECEF metres of WGS84 points (ellipsoid heights)."""
    x, y, z = pymap3d.geodetic2ecef(np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64),
                                    np.asarray(alt_m, dtype=np.float64))
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1).astype(np.float64)


def R_ecef_from_enu(lat_deg, lon_deg) -> np.ndarray:
    """(..., 3, 3) rotation taking ENU vectors at (lat, lon) into ECEF; its columns are east, north, up."""
    lat = np.asarray(lat_deg, dtype=np.float64)
    lon = np.asarray(lon_deg, dtype=np.float64)
    lat, lon = np.broadcast_arrays(lat, lon)
    cols = []
    for basis in np.eye(3):  # rotate the three ENU unit vectors with pymap3d
        x, y, z = pymap3d.enu2uvw(basis[0], basis[1], basis[2], lat, lon)
        cols.append(np.stack(np.broadcast_arrays(x, y, z), axis=-1))
    return np.stack(cols, axis=-1).astype(np.float64)


def R_ecef_from_ned(lat_deg, lon_deg) -> np.ndarray:
    """(..., 3, 3) rotation taking NED vectors at (lat, lon) into ECEF."""
    return R_ecef_from_enu(lat_deg, lon_deg) @ R_ENU_FROM_NED


def R_enu0_from_ned_at(lat_deg, lon_deg, origin_lla: tuple[float, float, float]) -> np.ndarray:
    """(..., 3, 3) rotation from the local NED frame at each (lat, lon) into the ENU frame at the origin, through
    ECEF: R_enu0_from_ecef @ R_ecef_from_ned(lat, lon). At the origin itself it is R_ENU_FROM_NED; it tilts by
    about 0.16 mrad per km away from it."""
    R0 = R_ecef_from_enu(origin_lla[0], origin_lla[1])
    return np.swapaxes(R0, -1, -2) @ R_ecef_from_ned(lat_deg, lon_deg)


def check_origin(origin_lla) -> tuple[float, float, float]:
    """The origin as a validated (lat_deg, lon_deg, alt_m) tuple of floats."""
    try:
        lat, lon, alt = (float(v) for v in origin_lla)
    except (TypeError, ValueError):
        raise GeometryError(f"origin must be (lat_deg, lon_deg, alt_m), got {origin_lla!r}") from None
    if not (np.isfinite([lat, lon, alt]).all() and -90 <= lat <= 90 and -180 <= lon <= 360):
        raise GeometryError(f"origin out of range: {origin_lla!r}")
    return lat, lon, alt
