"""When things happen in a synthetic flight: telemetry start, the video clock, laser shots, observations.

The video clock starts at zero when recording starts; frame j of the continuous 25 Hz stream has
pts = j * frame_period_ns and happens at telemetry time (UNIX ns) pts + video_offset_ns. The laser is
triggered on video frames (every fps / laser_hz frames), so an observation's laser shot and its frame are
simultaneous.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.errors import ConfigError
from pipeline.synth.config import SynthConfig


@dataclass(frozen=True)
class Timeline:
    """t0_ns: telemetry start (UNIX ns); end_ns: telemetry end; video_offset_ns: telemetry = pts + offset.
    laser_frames (m,): continuous-stream frame numbers where the laser fires; obs_frames (n_obs,) likewise for
    the observations; written_frames (k,): stream frame numbers recorded to the video (bursts or all)."""

    t0_ns: int
    end_ns: int
    video_offset_ns: int
    frame_period_ns: int
    laser_frames: np.ndarray
    obs_frames: np.ndarray
    written_frames: np.ndarray
    obs_spacing_s: int

    def frame_time_ns(self, stream_frames) -> np.ndarray:
        """Telemetry-clock time (UNIX ns, int64) of continuous-stream frame numbers."""
        return self.video_offset_ns + np.asarray(stream_frames, dtype=np.int64) * self.frame_period_ns

    def frame_pts_ns(self, stream_frames) -> np.ndarray:
        """Video-clock presentation time (ns, int64) of continuous-stream frame numbers."""
        return np.asarray(stream_frames, dtype=np.int64) * self.frame_period_ns

    @property
    def obs_t_ns(self) -> np.ndarray:
        return self.frame_time_ns(self.obs_frames)

    def seconds(self, t_ns) -> np.ndarray:
        """Seconds since the telemetry start (float64)."""
        return (np.asarray(t_ns, dtype=np.int64) - self.t0_ns) / 1e9


def build_timeline(cfg: SynthConfig, spacing_s: int) -> Timeline:
    """The flight's schedule, with observations every `spacing_s` seconds (whole seconds, so each is a shot)."""
    fps = cfg.camera.fps
    if 1_000_000_000 % fps:
        raise ConfigError(f"'camera.fps' {fps} does not give a whole number of nanoseconds per frame")
    period_ns = 1_000_000_000 // fps
    frames_per_shot = round(fps / cfg.rates.laser_hz)
    spacing_frames = spacing_s * fps
    if spacing_frames % frames_per_shot:
        raise ConfigError(f"observation spacing {spacing_s} s is not a whole number of laser periods")
    t0_ns = cfg.start_time_ns
    video_offset_ns = t0_ns + round(cfg.video.start_delay_s * 1e9)
    j0 = math.ceil((cfg.observations.lead_in_s - cfg.video.start_delay_s) * fps)
    if j0 < cfg.video.burst_frames:
        raise ConfigError("'observations.lead_in_s' must leave room for the video start delay and a burst")
    obs_frames = j0 + spacing_frames * np.arange(cfg.observations.count, dtype=np.int64)
    n_stream = int(obs_frames[-1] + math.ceil(cfg.observations.lead_out_s * fps))
    phase = j0 % frames_per_shot
    laser_frames = np.arange(phase, n_stream, frames_per_shot, dtype=np.int64)
    if cfg.video.mode == "continuous":
        written = np.arange(n_stream, dtype=np.int64)
    else:
        b = cfg.video.burst_frames
        if b > spacing_frames:
            raise ConfigError(f"'video.burst_frames' ({b}) exceeds the observation spacing ({spacing_frames} frames)")
        offsets = np.arange(b, dtype=np.int64) - (b - 1) // 2
        written = (obs_frames[:, None] + offsets[None, :]).ravel()
    end_ns = video_offset_ns + n_stream * period_ns
    return Timeline(t0_ns=t0_ns, end_ns=end_ns, video_offset_ns=video_offset_ns, frame_period_ns=period_ns,
                    laser_frames=laser_frames, obs_frames=obs_frames, written_frames=written,
                    obs_spacing_s=spacing_s)
