import numpy as np

from pipeline.errors import LogReadError
from pipeline.flight.frames import TimedDecoder
from pipeline.geometry.rays import intersection_angle_deg


def test_decoder_keeps_the_frames_that_decode_and_converts_to_gray():
    def read(indices):
        if 7 in indices:
            raise LogReadError("video ends before frame 7", path="v.mp4")
        return {i: np.full((4, 6, 3), i, np.uint8) for i in indices}

    dec = TimedDecoder(read)
    out = dec([3, 7, 5, 3])
    assert sorted(out) == [3, 5] and out[5].shape == (4, 6) and out[5][0, 0] == 5
    assert dec.failed == [7] and dec.decoded == 2 and dec.seconds >= 0


def test_intersection_angle_of_two_lines_of_sight():
    platform = np.array([[1000.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1000.0, 0.0]])
    target = np.array([0.0, 0.0, -1000.0])
    # first (1000, 0, 0) and last (0, 1000, 0), both 1000 m above the target: cos = 1/2 -> 60 deg
    np.testing.assert_allclose(intersection_angle_deg(platform, target), 60.0, atol=1e-12)
