"""The target mark, acquired one way for `run`, `check` and the clock estimate (pipeline/flight/mark.py): the given
frame and pixel (the frame must exist), a template (must be a readable image), or the crosshair of the first
observation frame; each refusal is the same error type whoever asks."""

import numpy as np
import pytest

from pipeline.errors import ConfigError, InputError
from pipeline.flight import TargetMark, acquire_mark
from pipeline.flight_config import Camera, Target
from pipeline.ingest.model import FrameSeries

FRAMES = FrameSeries(t_ns=np.array([0, 40_000_000, 80_000_000], dtype=np.int64), index=np.array([10, 11, 12]))
CAMERA = Camera(width_px=640, height_px=480, fx_px=800.0, fy_px=800.0, cx_px=319.5, cy_px=241.0,
                dist=(0.0, 0.0, 0.0, 0.0, 0.0))


class _NoTracker:
    def acquire(self, *args):
        raise AssertionError("a given mark needs no tracker")


def _mark(target, plan=(11, 12), tracker=None):
    return acquire_mark(target, frames=FRAMES, plan_frame_index=np.array(plan), camera=CAMERA,
                        decoder=lambda idx: {}, tracker=tracker or _NoTracker(), config_path="f.yaml")


def test_a_given_mark_is_used_as_given():
    assert _mark(Target(frame_index=12, pixel=(100.0, 50.5))) == TargetMark(12, (100.0, 50.5))


def test_a_mark_in_no_frame_of_the_video_is_a_config_error():
    with pytest.raises(ConfigError, match=r"target\.frame_index 13 is not a frame of the video"):
        _mark(Target(frame_index=13, pixel=(100.0, 50.0)))


def test_a_run_names_the_config_file_once_and_the_frames_there_are():
    """A flight config's `target:` reaches `run` as a mark whose source already names the config file
    (pipeline.targets.flight_targets); the error said the file twice ("f.yaml: f.yaml: target: ...")."""
    from pipeline.targets import Mark

    with pytest.raises(ConfigError) as exc:
        _mark(Mark(frame_index=999, pixel=(100.0, 50.0), source="f.yaml: target"))
    assert str(exc.value) == "f.yaml: target: frame_index 999 is not a frame of the video (the video has frames 10..12)"


def test_without_a_mark_the_crosshair_of_the_first_observation():
    m = _mark(None)
    assert (m.frame_index, m.pixel_px) == (11, (319.5, 241.0)) and "image centre of frame 11" in m.note
    assert m.to_dict() == {"frame_index": 11, "pixel_px": [319.5, 241.0]}
    with pytest.raises(InputError, match="no observation frame"):
        _mark(None, plan=())


def test_an_unreadable_template_is_a_config_error_naming_the_file(tmp_path):
    bad = tmp_path / "template.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(ConfigError, match=r"target\.template: not a readable image") as exc:
        _mark(Target(template=str(bad)))
    assert str(bad) in str(exc.value)


def test_a_template_is_found_by_the_tracker_in_the_observation_frames(tmp_path):
    import cv2

    path = tmp_path / "template.png"
    cv2.imwrite(str(path), np.full((8, 8), 128, np.uint8))
    seen = {}

    class Tracker:
        def acquire(self, template, template_px, decode, candidates):
            seen.update(shape=template.shape, px=template_px, candidates=candidates)
            return 12, (5.0, 6.0)

    m = _mark(Target(template=str(path), template_pixel=(3.0, 4.0)), tracker=Tracker())
    assert m == TargetMark(12, (5.0, 6.0))
    assert seen == {"shape": (8, 8), "px": (3.0, 4.0), "candidates": [11, 12]}
