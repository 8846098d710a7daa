"""Where a flight's camera intrinsics come from: one function, in order of precedence.

1. the flight config's `camera:` (width_px .. cy_px, dist);
2. the logs' CameraInfo (ROS sensor_msgs/CameraInfo: K, D in OpenCV order for plumb_bob / rational_polynomial);
3. the payload's reported field of view (FieldOfViewSeries: MISB KLV, DJI SRT), where a reader supplies it: an
   ideal pinhole with no distortion, principal point at the image centre ((w - 1) / 2, (h - 1) / 2 with pixel
   centres at integers), fx = w / (2 tan(hfov / 2)), fy = h / (2 tan(vfov / 2)) (fy = fx where vfov is not
   stated). `resolve_camera` gives the K of the first sample (for checks); `frame_K` the K of every frame,
   the field of view interpolated (linearly) at each frame's time, so a zoom changes K frame by frame.
The camera's mounting (`camera.R_optical_from_gimbal`) always comes from the config (default: gimbal FRD).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.errors import ConfigError, InputError
from pipeline.flight_config import Camera, FlightConfig
from pipeline.ingest.model import FlightLog

OPENCV_DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "")
FIELD_OF_VIEW = "field of view"  # how resolve_camera's source string starts for intrinsics from the field of view


def K_from_field_of_view(hfov_deg, vfov_deg, width_px: int, height_px: int) -> np.ndarray:
    """(m, 3, 3) pinhole K from (m,) horizontal and vertical fields of view in degrees (vfov NaN: square pixels)."""
    h = np.atleast_1d(np.asarray(hfov_deg, dtype=np.float64))
    v = np.atleast_1d(np.asarray(vfov_deg, dtype=np.float64))
    if not (np.isfinite(h) & (h > 0) & (h < 180)).all():
        raise InputError("the horizontal field of view must be in (0, 180) degrees at every frame")
    fx = width_px / (2.0 * np.tan(np.radians(h) / 2.0))
    fy = np.where(np.isfinite(v) & (v > 0) & (v < 180), height_px / (2.0 * np.tan(np.radians(v) / 2.0)), fx)
    K = np.zeros((h.size, 3, 3))
    K[:, 0, 0], K[:, 1, 1] = fx, fy
    K[:, 0, 2], K[:, 1, 2], K[:, 2, 2] = (width_px - 1) / 2.0, (height_px - 1) / 2.0, 1.0
    return K


def _fov_at(fov, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(fov.t_ns, dtype=np.int64)
    out = []
    for col in (fov.hfov_deg, fov.vfov_deg):
        ok = np.isfinite(col)
        out.append(np.interp(t_ns, t[ok], col[ok]) if ok.any() else np.full(len(t_ns), np.nan))
    return out[0], out[1]


def frame_K(cam: Camera, cam_source: str, log: FlightLog, t_ns) -> np.ndarray:
    """(m, 3, 3) K of frames at times t_ns (m,) (the field-of-view series' clock): per frame when the intrinsics
    come from the field of view, else the camera's one K for every frame."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if cam_source.startswith(FIELD_OF_VIEW):
        h, v = _fov_at(log.field_of_view, t_ns)
        return K_from_field_of_view(h, v, cam.width_px, cam.height_px)
    return np.broadcast_to(cam.K, (t_ns.size, 3, 3)).copy()


def resolve_camera(config: FlightConfig, log: FlightLog) -> tuple[Camera, str]:
    """(the flight's Camera with intrinsics, where they came from: "config", "CameraInfo <source>", ...).

    Raises ConfigError naming the config when no source gives intrinsics, or when the CameraInfo disagrees with
    the frames' size or uses a distortion model OpenCV's does not match."""
    cam = config.camera
    if cam.has_intrinsics:
        return cam, "config (camera:)"
    info = log.camera_info
    if info is not None:
        model = info.distortion_model
        if model not in OPENCV_DISTORTION_MODELS:
            raise ConfigError(f"the logs' CameraInfo ({info.source}) uses distortion model {model!r}, which ridgeloc "
                              "does not read: give `camera:` in the flight config", config.path)
        frames = log.frames
        if frames is not None and frames.width_px and (frames.width_px, frames.height_px) != (info.width_px,
                                                                                              info.height_px):
            raise ConfigError(f"the logs' CameraInfo is for {info.width_px}x{info.height_px} px images, the frames "
                              f"are {frames.width_px}x{frames.height_px}: give `camera:` in the flight config",
                              config.path)
        K = np.asarray(info.K, dtype=np.float64)
        D = tuple(float(d) for d in np.asarray(info.D, dtype=np.float64).ravel())
        if len(D) not in (4, 5, 8):
            D = (D + (0.0,) * 5)[:5] if len(D) < 5 else D[:8]
        resolved = dataclasses.replace(cam, width_px=int(info.width_px), height_px=int(info.height_px),
                                       fx_px=float(K[0, 0]), fy_px=float(K[1, 1]), cx_px=float(K[0, 2]),
                                       cy_px=float(K[1, 2]), dist=D)
        return resolved, f"CameraInfo {info.source}".strip()
    fov, frames = log.field_of_view, log.frames
    if fov is not None and frames is not None and frames.width_px and frames.height_px:
        ok = np.isfinite(fov.hfov_deg)
        if ok.any():
            i = int(np.flatnonzero(ok)[0])
            K = K_from_field_of_view(fov.hfov_deg[i], fov.vfov_deg[i], frames.width_px, frames.height_px)[0]
            resolved = dataclasses.replace(cam, width_px=int(frames.width_px), height_px=int(frames.height_px),
                                           fx_px=float(K[0, 0]), fy_px=float(K[1, 1]), cx_px=float(K[0, 2]),
                                           cy_px=float(K[1, 2]), dist=(0.0, 0.0, 0.0, 0.0, 0.0))
            return resolved, f"{FIELD_OF_VIEW} {fov.source}".strip()
    raise ConfigError("no camera intrinsics: the flight config has no `camera:` (width_px, height_px, fx_px, fy_px, "
                      "cx_px, cy_px, dist) and the logs carry neither a CameraInfo nor a field of view", config.path)
