"""The flight as one object (flight.py: `Flight`), its frames as an interface (frames.py: `FrameSource`), and the
target mark a per-target stage starts from (mark.py: `TargetMark`, `acquire_mark`)."""

from pipeline.flight.flight import (
    Flight,
    flight_origin,
    geoid_separation_m,
    plan_flight_observations,
    read_flight_logs,
)
from pipeline.flight.frames import FrameSource, TimedDecoder, open_frames
from pipeline.flight.mark import TargetMark, acquire_mark

__all__ = ["Flight", "FrameSource", "TargetMark", "TimedDecoder", "acquire_mark", "flight_origin",
           "geoid_separation_m", "open_frames", "plan_flight_observations", "read_flight_logs"]
