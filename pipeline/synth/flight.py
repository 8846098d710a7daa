"""Generate one synthetic flight folder from a config: true flight, telemetry, frames, files, truth.json.

The folder is built under a hidden temporary name next to the destination and renamed into place when
complete, so an error never leaves a partial flight behind.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import InputError
from pipeline.synth.config import SynthConfig
from pipeline.synth.flight_config import write_flight_config as write_operator_config
from pipeline.synth.render import Renderer, ground_texture
from pipeline.synth.telemetry import make_telemetry
from pipeline.synth.timeline import Timeline, build_timeline
from pipeline.synth.trajectory import Flight, TrueState, observation_spacing_s
from pipeline.synth.truth import build_truth, frame_truth
from pipeline.synth.writers.mcap_json import write_mcap
from pipeline.synth.writers.rosbag import encode_jpeg, write_bag
from pipeline.synth.writers.tlog import write_tlog
from pipeline.synth.writers.video import write_video

FLIGHT_CONFIG_NAME = "flight.yaml"  # the name `ridgeloc run FOLDER` discovers
RNG_STREAMS = ("wobble", "jitter", "gnss", "attitude", "gimbal", "laser", "pixels")


@dataclass(frozen=True)
class SynthResult:
    out_dir: Path
    files: dict[str, str]
    n_frames: int
    n_observations: int
    intersection_angle_deg: float
    seconds: float
    flight_config: Path | None = None  # out_dir/flight.yaml when written (write_flight_config and a mark)


def camera_matrix(cfg: SynthConfig) -> np.ndarray:
    c = cfg.camera
    return np.array([[c.fx_px, 0.0, c.cx_px], [0.0, c.fy_px, c.cy_px], [0.0, 0.0, 1.0]])


def zoom_factors(cfg: SynthConfig, pts_ns: np.ndarray) -> np.ndarray:
    """(n,) zoom factor of frames at video times pts_ns: `camera.zoom` steps, 1 before the first."""
    z = np.ones(len(pts_ns))
    for t_s, factor in sorted(cfg.camera.zoom):
        z[np.asarray(pts_ns) >= round(t_s * 1e9)] = factor
    return z


def camera_matrices(cfg: SynthConfig, zoom: np.ndarray) -> np.ndarray:
    """(n, 3, 3) K of each frame: focal lengths times its zoom factor, principal point unchanged."""
    K = np.repeat(camera_matrix(cfg)[None], len(zoom), axis=0)
    K[:, 0, 0] *= zoom
    K[:, 1, 1] *= zoom
    return K


class FrameSource:
    """Renders the written frames in order from the true camera poses (lazily: video can be long)."""

    def __init__(self, cfg: SynthConfig, tl: Timeline, states: TrueState, truth_frames: list[dict]):
        self.cfg, self.tl, self.states, self.truth_frames = cfg, tl, states, truth_frames
        tex = ground_texture(cfg.scene.seed, cfg.scene.texture_px, cfg.scene.texture_res_m)
        self.renderer = Renderer(camera_matrix(cfg), cfg.camera.dist, (cfg.camera.width_px, cfg.camera.height_px),
                                 tex, cfg.scene.texture_res_m, cfg.site.target_size_m, cfg.scene.supersample,
                                 cfg.scene.haze_km, [(t.east_m, t.north_m, t.size_m, t.contrast)
                                                     for t in cfg.site.extra_targets])
        self.n = len(tl.written_frames)
        self.zoom = zoom_factors(cfg, tl.frame_pts_ns(tl.written_frames))

    def __iter__(self) -> Iterator[np.ndarray]:
        cfg = self.cfg
        for k in range(self.n):
            R_cam_from_enu = self.states.R_enu_from_optical[k].T
            ft = self.truth_frames[k]
            rng = np.random.default_rng([cfg.seed, RNG_STREAMS.index("pixels"), int(self.tl.written_frames[k])])
            cloud = tuple(ft["true_target_pixel"]) if ft["occluded"] else None
            more = [tuple(x["pixel"]) for x in ft.get("targets", {}).values() if x["occluded"]]
            yield self.renderer.render(R_cam_from_enu, self.states.camera_enu[k], rng, cfg.noise.pixel_noise_dn,
                                       cloud, zoom=float(self.zoom[k]), more_clouds_px=more)


def generate(cfg: SynthConfig, out_dir: str | Path, overwrite: bool = False,
             write_flight_config: bool = False) -> SynthResult:
    """Write the flight `cfg` into `out_dir` (created; must not exist unless overwrite) and return a summary.

    With write_flight_config, also out_dir/flight.yaml: the flight config an operator would write for it
    (pipeline/synth/flight_config.py), so that `ridgeloc run out_dir/flight.yaml` processes it; not written when
    the target is visible in no observation frame (no mark to give)."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise InputError("output folder already exists (use --overwrite)", out_dir)
    spacing = observation_spacing_s(cfg)
    tl = build_timeline(cfg, spacing)
    rngs = {name: np.random.default_rng([cfg.seed, i]) for i, name in enumerate(RNG_STREAMS)}
    flight = Flight(cfg, tl.t0_ns, tl.end_ns, tl.obs_t_ns, rngs["wobble"], rngs["jitter"])
    tel, laser_truth = make_telemetry(cfg, tl, flight, rngs)
    frame_t = tl.frame_time_ns(tl.written_frames)
    states = flight.state(frame_t)
    truth_frames = frame_truth(cfg, tl, flight, states,
                               camera_matrices(cfg, zoom_factors(cfg, tl.frame_pts_ns(tl.written_frames))))
    frames = FrameSource(cfg, tl, states, truth_frames)

    tmp = out_dir.with_name(f".tmp-{out_dir.name}")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    try:
        files = _write_files(cfg, tl, tel, frames, tmp)
        truth = build_truth(cfg, tl, flight, laser_truth, truth_frames, files, spacing)
        (tmp / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")
        config_path = None
        if write_flight_config and truth["target_mark"] is not None:
            write_operator_config(tmp / FLIGHT_CONFIG_NAME, truth, tmp, f"Synthetic flight {cfg.group}")
            config_path = out_dir / FLIGHT_CONFIG_NAME
        if out_dir.exists():
            shutil.rmtree(out_dir)
        tmp.rename(out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return SynthResult(out_dir=out_dir, files=files, n_frames=frames.n, n_observations=cfg.observations.count,
                       intersection_angle_deg=truth["intersection_angle_deg"], seconds=time.perf_counter() - t_start,
                       flight_config=config_path)


def _write_files(cfg: SynthConfig, tl: Timeline, tel, frames: FrameSource, folder: Path) -> dict[str, str]:
    files: dict[str, str] = {}
    home_alt_m = cfg.site.alt_m  # take-off from ground level near the target
    if cfg.format == "klv":
        from pipeline.synth.writers.fmv import klv_packets, write_fmv

        pts = tl.frame_pts_ns(tl.written_frames)
        c = cfg.camera
        packets = klv_packets(tel, tl.frame_time_ns(tl.written_frames), (c.width_px, c.height_px, c.fx_px, c.fy_px),
                              frames.zoom, cfg.site.geoid_separation_m)
        write_fmv(folder / "flight.ts", frames, pts, list(zip(pts.tolist(), packets, strict=True)), c.fps,
                  (c.width_px, c.height_px))
        files["telemetry"] = "flight.ts"
        return files
    if cfg.format == "tlog":
        write_tlog(folder / "flight.tlog", tel, cfg.site.geoid_separation_m, home_alt_m)
        files["telemetry"] = "flight.tlog"
    elif cfg.format == "mcap":
        write_mcap(folder / "flight.mcap", tel, cfg.gimbal.quat_order)
        files["telemetry"] = "flight.mcap"
    else:
        name = "flight.bag" if cfg.format == "ros1" else "flight_ros2"
        camera = {"K": camera_matrix(cfg), "dist": list(cfg.camera.dist), "width": cfg.camera.width_px,
                  "height": cfg.camera.height_px}
        images = None
        if cfg.video.images_in_bag:
            t_img = tl.frame_time_ns(tl.written_frames)
            images = ((int(t), encode_jpeg(img, cfg.video.jpeg_quality)) for t, img in zip(t_img, frames, strict=True))
        gps_sigma = float(np.hypot(cfg.noise.gnss_drift_m, cfg.noise.gnss_white_m))
        write_bag(folder / name, cfg.format, tel, camera, gps_sigma, float(np.radians(cfg.noise.attitude_deg)),
                  (cfg.laser.min_range_m, cfg.laser.max_range_m), images, cfg.gimbal.ros_frame)
        files["telemetry"] = name
        if images is not None:
            files["frames"] = f"{name}:/uav/camera/image/compressed"
    if "frames" not in files:
        pts = tl.frame_pts_ns(tl.written_frames)
        write_video(folder / "video.mp4", frames, pts, cfg.camera.fps, (cfg.camera.width_px, cfg.camera.height_px),
                    start_ns=int(tl.video_offset_ns))
        files["video"] = "video.mp4"
        files["frames_csv"] = "video.frames.csv"
    return files


