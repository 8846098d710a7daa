"""The target mark: the frame and pixel a target is tracked from. A value passed to the per-target stages (the
tracker, the clock estimate), not a part of the flight, so one flight can carry several targets."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.errors import ConfigError, InputError
from pipeline.flight_config import Camera, Target
from pipeline.ingest.model import FrameSeries
from pipeline.targets import Mark


@dataclass(frozen=True)
class TargetMark:
    """frame_index: the frame number the target is marked in; pixel_px (x, y) in it (as recorded: distorted);
    note: how it was found, when not given outright (None)."""

    frame_index: int
    pixel_px: tuple[float, float]
    note: str | None = None

    def to_dict(self) -> dict:
        return {"frame_index": int(self.frame_index), "pixel_px": [float(self.pixel_px[0]), float(self.pixel_px[1])]}


def acquire_mark(target: Target | Mark | None, *, frames: FrameSeries, plan_frame_index, camera: Camera, decoder,
                 tracker, config_path=None) -> TargetMark:
    """The mark of `target` (a flight config's `target:`, or one mark of a named target, `pipeline.targets.Mark`):
    the given frame and pixel (ConfigError when the frame is not one of `frames`); the template found in the
    observation frames `plan_frame_index` (ConfigError when the template is not a readable image); or, with no target,
    the laser's crosshair (the principal point) in the first observation frame (InputError when there is none)."""
    if target is None:
        if len(plan_frame_index) == 0:
            raise InputError("no observation frame to take the target from", config_path)
        index = int(plan_frame_index[0])
        return TargetMark(index, (float(camera.cx_px), float(camera.cy_px)),
                          f"target: the image centre of frame {index}, where the laser points (no mark given)")
    if target.template is not None:
        import cv2

        template = cv2.imread(target.template, cv2.IMREAD_GRAYSCALE)
        if template is None:
            raise ConfigError("target.template: not a readable image", target.template)
        index, pixel = tracker.acquire(template, target.template_pixel, decoder, np.asarray(plan_frame_index).tolist())
        return TargetMark(int(index), (float(pixel[0]), float(pixel[1])))
    indices = set(np.asarray(frames.index).tolist())
    if target.frame_index not in indices:
        source = getattr(target, "source", "target")
        where = f"{source}: " if source and source != "target" else "target."
        if config_path is not None and where.startswith(f"{config_path}: "):
            config_path = None  # the mark's source already names the config file
        have = f" (the video has frames {min(indices)}..{max(indices)})" if indices else ""
        raise ConfigError(f"{where}frame_index {target.frame_index} is not a frame of the video{have}", config_path)
    return TargetMark(int(target.frame_index), (float(target.pixel[0]), float(target.pixel[1])))
