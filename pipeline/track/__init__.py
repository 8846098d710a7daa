"""Target tracking: carry the operator's mark (a pixel in one frame, or a template image) through the frames
that are observations (`sift.SiftTracker`)."""

from pipeline.track.sift import FrameTrack, SiftTracker, TrackerSettings, TrackResult

__all__ = ["FrameTrack", "SiftTracker", "TrackResult", "TrackerSettings"]
