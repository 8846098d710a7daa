"""Photos as camera views: each photo's pose in one ENU frame, its projection matrix and its pixel rays.

Chain (pipeline.geometry.pose): R_enu0_from_optical = R_enu0_from_ned(photo lat, lon) * R_ned_from_gimbal *
R_gimbal_from_optical, with R_ned_from_gimbal the ZYX Euler rotation of the photo's gimbal (yaw, pitch, roll) in DJI's
convention, whatever the maker wrote (pipeline.ingest.photo_makers; yaw earth-referenced) and the camera's optical
axis along gimbal x. Heights become ellipsoidal with the EGM2008
undulation when the photo's altitude is AMSL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import InputError
from pipeline.geometry.frames import lla_from_enu
from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.geometry.lens import undistort_pixels
from pipeline.geometry.pose import frame_poses
from pipeline.ingest.frames import quat_ned_from_frd_euler
from pipeline.ingest.photo import Photo


def _quat_ned_from_ypr_deg(ypr_deg) -> np.ndarray:
    """(n, 4) quaternions (w, x, y, z) FRD -> local NED from (n, 3) yaw, pitch, roll degrees (the photos' tags)."""
    r = np.radians(np.asarray(ypr_deg, dtype=np.float64).reshape(-1, 3))
    return quat_ned_from_frd_euler(r[:, 2], r[:, 1], r[:, 0])


def photo_heights_ellipsoid_m(photos: list[Photo]) -> np.ndarray:
    """(n,) ellipsoidal heights of the photos' positions (AMSL + EGM2008 N where the datum is amsl)."""
    alt = np.array([p.alt_m for p in photos], dtype=np.float64)
    amsl = np.array([p.alt_datum == "amsl" for p in photos])
    if amsl.any():
        lat = np.array([p.lat_deg for p in photos])
        lon = np.array([p.lon_deg for p in photos])
        alt[amsl] += geoid_undulation_m(lat[amsl], lon[amsl])
    return alt


@dataclass(frozen=True)
class PhotoViews:
    """n photos as views in the ENU frame at origin_lla (lat, lon, ellipsoidal height): K (n, 3, 3), dist (n, 5),
    R_enu0_from_optical (n, 3, 3), camera_m (n, 3), P (n, 3, 4) = K [R | -R c]."""

    photos: tuple[Photo, ...]
    origin_lla: tuple[float, float, float]
    K: np.ndarray
    dist: np.ndarray
    R_enu0_from_optical: np.ndarray
    camera_m: np.ndarray
    P: np.ndarray
    rotations_deg: tuple[int, ...] = ()

    def file_to_camera_pixels(self, pixel_px, idx=None) -> np.ndarray:
        """(m, 2) camera pixels of (m, 2) pixels of the files of photos idx (m,) (default: all n): the same unless a
        file was turned by 180 degrees after capture (its rotation 180: u -> w - 1 - u, v -> h - 1 - v)."""
        px = np.asarray(pixel_px, dtype=np.float64).reshape(-1, 2)
        idx = np.arange(len(self.photos)) if idx is None else np.asarray(idx)
        turned = np.array([self.rotations_deg[i] == 180 for i in idx]) if self.rotations_deg else np.zeros(0, bool)
        if not turned.any():
            return px
        wh = np.array([[self.photos[i].width_px - 1, self.photos[i].height_px - 1] for i in idx], dtype=np.float64)
        return np.where(turned[:, None], wh - px, px)

    def pinhole_pixels(self, pixel_px, idx=None) -> np.ndarray:
        """(m, 2) ideal pinhole pixels of (m, 2) pixels of the files of photos idx (m,) (default: all n), lens
        distortion removed per photo (NaN rows stay NaN)."""
        idx = np.arange(len(self.photos)) if idx is None else np.asarray(idx)
        px = self.file_to_camera_pixels(pixel_px, idx)
        return np.vstack([undistort_pixels(px[j:j + 1], self.K[i], self.dist[i]) for j, i in enumerate(idx)])

    def lla(self, enu_m) -> np.ndarray:
        return lla_from_enu(enu_m, self.origin_lla)


def photo_views(photos: list[Photo], origin_lla: tuple[float, float, float] | None = None,
                rotation_deg=0) -> PhotoViews:
    """Views of photos that all have intrinsics (InputError naming the first that has none). The origin defaults
    to the first photo's position. rotation_deg (one for all, or one per photo) 180: the file's pixels were turned
    upside down after capture (an image viewer's lossless rotation; see docs/ingest.md, the Brighton photos)."""
    if not photos:
        raise InputError("no photos")
    rotations = tuple(int(r) for r in np.broadcast_to(np.asarray(rotation_deg), (len(photos),)))
    if any(r not in (0, 180) for r in rotations):
        raise InputError(f"image rotation must be 0 or 180 degrees, got {sorted(set(rotations))}")
    for p in photos:
        if p.intrinsics is None:
            raise InputError("no intrinsics (no calibrated focal length, DewarpData or stated field of view, no camera "
                             f"database entry for {p.make}{p.model}, no EXIF FocalLengthIn35mmFilm)", path=p.path)
    lat = np.array([p.lat_deg for p in photos])
    lon = np.array([p.lon_deg for p in photos])
    h = photo_heights_ellipsoid_m(photos)
    if origin_lla is None:
        origin_lla = (float(lat[0]), float(lon[0]), float(h[0]))
    gimbal = _quat_ned_from_ypr_deg([p.gimbal_ypr_deg for p in photos])
    body = _quat_ned_from_ypr_deg([p.flight_ypr_deg or (p.gimbal_ypr_deg[0], 0.0, 0.0) for p in photos])
    poses = frame_poses(lat, lon, h, body, gimbal, np.zeros(len(photos), bool), origin_lla)
    K = np.stack([p.intrinsics.K for p in photos])
    dist = np.array([p.intrinsics.dist for p in photos], dtype=np.float64)
    return PhotoViews(tuple(photos), tuple(float(v) for v in origin_lla), K, dist, poses.R_enu0_from_optical,
                      poses.camera_m, poses.projection_matrices(K), rotations)
