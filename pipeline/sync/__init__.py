"""Synchronization: every source on the telemetry clock, vehicle state interpolated to the observation frames,
laser ranges matched to them, and the result assembled into the `Observations` every estimator reads."""

from pipeline.sync.assemble import FrameStates, assemble_observations, frame_states
from pipeline.sync.interpolate import interpolate_linear, interpolate_rotations, nearest_within
from pipeline.sync.select import ObservationPlan, plan_observations

__all__ = [
    "FrameStates",
    "ObservationPlan",
    "assemble_observations",
    "frame_states",
    "interpolate_linear",
    "interpolate_rotations",
    "nearest_within",
    "plan_observations",
]
