"""truth.json: the ground truth and metadata of a synthetic flight (format in docs/synth.md).

Datum: WGS84 ellipsoidal heights (EPSG:4979) throughout; poses in ECEF metres.
"""

from __future__ import annotations

import cv2
import numpy as np
import pymap3d

from pipeline.geometry.rays import intersection_angle_deg
from pipeline.synth.config import SynthConfig
from pipeline.synth.telemetry import LaserTruth
from pipeline.synth.timeline import Timeline
from pipeline.synth.trajectory import R_OPTICAL_FROM_GIMBAL, Flight, TrueState

FORMAT_VERSION = 1
LOST_WINDOW_NS = 600_000_000  # a lost-target event covers +-0.6 s around its observation (its whole burst)


def _ecef(lla: np.ndarray) -> np.ndarray:
    return np.stack(pymap3d.geodetic2ecef(lla[..., 0], lla[..., 1], lla[..., 2]), axis=-1)


def project_target_px(cfg: SynthConfig, K: np.ndarray, states: TrueState, point_enu=(0.0, 0.0, 0.0)
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(n, 2) distorted pixels of the target (target ENU origin, or `point_enu`) and (n,) whether it is in front
    of the camera. K: (3, 3), or (n, 3, 3) per frame (zoom)."""
    K = np.broadcast_to(np.asarray(K, dtype=np.float64), (len(states.camera_enu), 3, 3))
    R_cam_from_enu = np.swapaxes(states.R_enu_from_optical, -1, -2)
    t = -np.einsum("nij,nj->ni", R_cam_from_enu, states.camera_enu - np.asarray(point_enu, dtype=np.float64))
    px = np.empty((len(t), 2))
    dist = np.asarray(cfg.camera.dist, dtype=np.float64)
    for i in range(len(t)):  # cv2.projectPoints takes one pose per call
        rvec, _ = cv2.Rodrigues(R_cam_from_enu[i])
        px[i] = cv2.projectPoints(np.zeros((1, 1, 3)), rvec, t[i], np.ascontiguousarray(K[i]), dist)[0].ravel()
    return px, t[:, 2] > 0


def target_in_frames(cfg: SynthConfig, tl: Timeline, states: TrueState, K: np.ndarray, point_enu,
                     occluded_observations) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One target (at `point_enu`, m) in every written frame: (n, 2) true distorted pixels, (n,) whether it is in
    front of the camera and inside the image, (n,) whether it is occluded (within LOST_WINDOW_NS of one of the
    `occluded_observations`, observation indices)."""
    px, in_front = project_target_px(cfg, K, states, point_enu)
    w, h = cfg.camera.width_px, cfg.camera.height_px
    inside = in_front & (px[:, 0] >= 0) & (px[:, 0] <= w - 1) & (px[:, 1] >= 0) & (px[:, 1] <= h - 1)
    occluded = np.zeros(len(px), bool)
    for k in occluded_observations:
        occluded |= np.abs(states.t_ns - tl.obs_t_ns[k]) <= LOST_WINDOW_NS
    return px, inside, occluded


def frame_truth(cfg: SynthConfig, tl: Timeline, flight: Flight, states: TrueState, K: np.ndarray) -> list[dict]:
    """One dict per written frame: times, true camera pose (ECEF), true target pixel and visibility."""
    px, inside, occluded = target_in_frames(cfg, tl, states, K, (0.0, 0.0, 0.0),
                                            cfg.lost_target.occluded_observations)
    extra = {x.name: target_in_frames(cfg, tl, states, K, (x.east_m, x.north_m, 0.0), x.occluded_observations)
             for x in cfg.site.extra_targets}  # the other targets' pixels, visibility and occlusion per frame
    cam_lla = flight.enu_to_lla(states.camera_enu)
    cam_ecef = _ecef(cam_lla)
    R_ecef_from_optical = flight.R_ecef_from_enu_t @ states.R_enu_from_optical
    pts = tl.frame_pts_ns(tl.written_frames)
    out = []
    for k in range(len(px)):
        out.append({
            "frame_index": k, "stream_frame": int(tl.written_frames[k]), "t_ns": int(states.t_ns[k]),
            "pts_ns": int(pts[k]), "camera_lla": [float(v) for v in cam_lla[k]],
            "camera_position_ecef_m": [float(v) for v in cam_ecef[k]],
            "R_ecef_from_optical": R_ecef_from_optical[k].tolist(),
            "true_target_pixel": [float(v) for v in px[k]],
            "target_visible": bool(inside[k] and not occluded[k]), "occluded": bool(occluded[k]),
        })
        if extra:
            out[-1]["targets"] = {name: {"pixel": [float(v) for v in xpx[k]], "visible": bool(xin[k] and not xocc[k]),
                                         "occluded": bool(xocc[k])} for name, (xpx, xin, xocc) in extra.items()}
    return out


def targets_truth(cfg: SynthConfig, flight: Flight, frames: list[dict], obs: list[dict]) -> list[dict]:
    """Every target of a flight with extra targets (the main one first): name, true position (WGS84, ellipsoid
    height), size, contrast, its mark (the first observation frame showing it, at its true pixel) and in which
    observations it is visible."""
    s = cfg.site

    def entry(name, lat_deg, lon_deg, alt_m, east_m, north_m, size_m, contrast, vis, pixel_in) -> dict:
        first = next((o["frame_index"] for o, v in zip(obs, vis, strict=True) if v), None)
        return {"name": name, "lat_deg": lat_deg, "lon_deg": lon_deg, "alt_m": alt_m, "east_m": east_m,
                "north_m": north_m, "size_m": size_m, "contrast": contrast,
                "mark": None if first is None else {"frame_index": first, "pixel": [
                    round(v, 2) for v in pixel_in(frames[first])]},
                "visible_observations": [i for i, v in enumerate(vis) if v]}

    out = [entry(s.target_name, s.lat_deg, s.lon_deg, s.alt_m, 0.0, 0.0, s.target_size_m, 1.0,
                 [o["target_visible"] for o in obs], lambda f: f["true_target_pixel"])]
    for x in s.extra_targets:
        lla = flight.enu_to_lla(np.array([[x.east_m, x.north_m, 0.0]]))[0]
        out.append(entry(x.name, float(lla[0]), float(lla[1]), float(lla[2]), x.east_m, x.north_m, x.size_m,
                         x.contrast, [frames[o["frame_index"]]["targets"][x.name]["visible"] for o in obs],
                         lambda f, name=x.name: f["targets"][name]["pixel"]))
    return out


def build_truth(cfg: SynthConfig, tl: Timeline, flight: Flight, laser: LaserTruth, frames: list[dict],
                files: dict[str, str], spacing_s: int) -> dict:
    s = cfg.site
    target_lla = np.array([s.lat_deg, s.lon_deg, s.alt_m])
    target_ecef = _ecef(target_lla)
    frame_of_stream = {f["stream_frame"]: f for f in frames}
    shot_of_frame = {int(j): i for i, j in enumerate(tl.laser_frames)}
    obs = []
    for k, j in enumerate(tl.obs_frames):
        f = frame_of_stream[int(j)]
        i = shot_of_frame[int(j)]
        logged = bool(laser.logged[i])
        valid = logged and cfg.laser.min_range_m <= laser.range_measured_m[i] <= cfg.laser.max_range_m
        obs.append({"index": k, "t_ns": int(tl.frame_time_ns(j)), "frame_index": f["frame_index"],
                    "range_valid": bool(valid), "range_outlier": bool(laser.outlier[i]),
                    "range_true_m": float(laser.range_true_m[i]),
                    "range_measured_m": float(laser.range_measured_m[i]) if logged else None,
                    "target_visible": f["target_visible"], "camera_position_ecef_m": f["camera_position_ecef_m"]})
    gamma = intersection_angle_deg(np.array([obs[0]["camera_position_ecef_m"], obs[-1]["camera_position_ecef_m"]]),
                                   target_ecef)
    mark = next((frames[o["frame_index"]] for o in obs if o["target_visible"]), None)
    K = cfg.camera
    speed = flight.path.span_m / ((tl.obs_t_ns[-1] - tl.obs_t_ns[0]) / 1e9)
    bag_images = "frames" in files
    return {
        "format_version": FORMAT_VERSION,
        "group": cfg.group,
        "description": cfg.description,
        "datum": "WGS84 ellipsoidal heights (EPSG:4979)",
        "target": {"lat_deg": s.lat_deg, "lon_deg": s.lon_deg, "alt_m": s.alt_m,
                   "ecef_m": [float(v) for v in target_ecef], "size_m": s.target_size_m},
        "origin": {"lat_deg": round(s.lat_deg, 2), "lon_deg": round(s.lon_deg, 2), "alt_m": float(round(s.alt_m))},
        "camera": {"width_px": K.width_px, "height_px": K.height_px, "fx_px": K.fx_px, "fy_px": K.fy_px,
                   "cx_px": K.cx_px, "cy_px": K.cy_px, "dist": list(K.dist), "fps": K.fps,
                   "R_optical_from_gimbal": R_OPTICAL_FROM_GIMBAL.tolist()},
        "lever_arms_m": {"camera": list(cfg.lever_arms_m.camera), "rangefinder": list(cfg.lever_arms_m.rangefinder),
                         "frame": "body FRD, relative to the GNSS antenna"},
        "metadata": {
            "clock": {"video_to_telemetry_offset_ns": 0 if bag_images else int(tl.video_offset_ns),
                      "telemetry_start_ns": int(tl.t0_ns), "telemetry_end_ns": int(tl.end_ns),
                      "note": ("frames in the bag are stamped on the telemetry clock" if bag_images else
                               "telemetry UNIX ns = video.frames.csv pts_ns + video_to_telemetry_offset_ns")},
            "geoid_separation_m": s.geoid_separation_m,
            "format": cfg.format,
            "files": files,
            "rates_hz": {"gps": cfg.rates.gps_hz, "attitude": cfg.rates.attitude_hz, "gimbal": cfg.rates.gimbal_hz,
                         "laser": cfg.rates.laser_hz, "system_time": cfg.rates.system_time_hz, "video": K.fps},
            "noise": {"gnss_m": float(np.hypot(cfg.noise.gnss_drift_m, cfg.noise.gnss_white_m)),
                      "attitude_deg": cfg.noise.attitude_deg, "gimbal_deg": cfg.noise.gimbal_deg,
                      "laser_m": cfg.noise.laser_m},
            "gimbal_yaw_in_vehicle_frame": cfg.gimbal.yaw_in_vehicle_frame,
            "laser_source": {"tlog": "CAMERA_TRACKING_GEO_STATUS.dist", "ros": "/uav/laser/range",
                             "mcap": "/uav/laser", "klv": "ST 0601 tag 21 (slant range)"
                             }[("ros" if cfg.format.startswith("ros") else cfg.format)],
            "video_mode": cfg.video.mode,
        },
        "flight": {"path": cfg.path.kind, "speed_mps": speed, "observation_spacing_s": spacing_s,
                   "duration_s": (tl.end_ns - tl.t0_ns) / 1e9, "height_m": cfg.path.height_m,
                   "slant_distance_m": cfg.path.slant_distance_m},
        "observations": obs,
        "target_mark": ({"frame_index": mark["frame_index"], "pixel": [round(v, 2) for v in mark["true_target_pixel"]]}
                        if mark else None),
        "intersection_angle_deg": gamma,
        "n_observations": len(obs),
        **({"targets": targets_truth(cfg, flight, frames, obs)} if s.extra_targets else {}),
        "laser_shots": {"t_ns": laser.t_ns.tolist(), "range_true_m": np.round(laser.range_true_m, 4).tolist(),
                        "logged": laser.logged.tolist(), "outlier": laser.outlier.tolist()},
        "frames": frames,
        "config": config_record(cfg),
        "seed": cfg.seed,
    }


# Keys added to the generator after the sample flights were written: recorded only when they differ from their
# default, so that regenerating a sample flight reproduces its committed truth.json (and the record still loads).
_LATER_KEYS = {"gimbal": {"ros_frame": "flu_enu", "quat_order": "wxyz"}}


def config_record(cfg: SynthConfig) -> dict:
    """The generator config as truth.json records it (SynthConfig.to_dict without later keys at their default)."""
    doc = cfg.to_dict()
    for section, keys in _LATER_KEYS.items():
        for key, default in keys.items():
            if doc[section].get(key) == default:
                del doc[section][key]
    return doc
