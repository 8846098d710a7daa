"""Where a flight's camera intrinsics come from: one function, in order of precedence.

1. the flight config's `camera:` (width_px .. cy_px, dist);
2. the logs' CameraInfo (ROS sensor_msgs/CameraInfo: K, D in OpenCV order for plumb_bob / rational_polynomial);
3. the payload's reported field of view (FieldOfViewSeries: MISB KLV, DJI SRT), where a reader supplies it.
The camera's mounting (`camera.R_optical_from_gimbal`) always comes from the config (default: gimbal FRD).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.errors import ConfigError
from pipeline.flight_config import Camera, FlightConfig
from pipeline.ingest.model import FlightLog

OPENCV_DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "")


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
    raise ConfigError("no camera intrinsics: the flight config has no `camera:` (width_px, height_px, fx_px, fy_px, "
                      "cx_px, cy_px, dist) and the logs carry no CameraInfo", config.path)
