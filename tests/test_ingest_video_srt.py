"""Video frame times (container and frames CSV) and decoding of chosen frames; DJI SRT variants."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import LogReadError
from pipeline.ingest import VideoFrames, read_flight, read_video
from pipeline.ingest.srt import parse_srt


def _video(path, n=40, fps=20.0, size=(64, 48)):
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    for i in range(n):
        img = np.zeros((size[1], size[0], 3), np.uint8)
        cv2.putText(img, str(i), (4, 36), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2)
        img[:, :, 1] = (i * 6) % 256
        w.write(img)
    w.release()


def test_container_times_and_chosen_frames(tmp_path):
    p = tmp_path / "v.mp4"
    _video(p)
    fs = read_video(p)
    assert fs.t_ns.size == 40 and fs.clock == "video" and (fs.width_px, fs.height_px) == (64, 48)
    np.testing.assert_array_equal(fs.t_ns, np.arange(40) * 50_000_000)
    cap = cv2.VideoCapture(str(p))
    seq = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        seq.append(img)
    with VideoFrames(p, seek_after=5) as v:  # forces the seek path for the jumps
        got = v.read([33, 2, 17, 17])
        back = v[1]
    assert sorted(got) == [2, 17, 33]
    for i in (2, 17, 33):
        np.testing.assert_array_equal(got[i], seq[i])
    np.testing.assert_array_equal(back, seq[1])
    with VideoFrames(p) as v, pytest.raises(LogReadError, match="ends before frame 99"):
        v[99]


def test_prefetched_frames_are_the_frames_decoded_one_by_one(tmp_path):
    """Worker threads decoding a planned order ahead give the same pixels as decoding each frame in turn, also
    when the caller skips planned frames, asks for one outside the plan or goes back; a new plan replaces the old."""
    p = tmp_path / "v.mp4"
    _video(p)
    with VideoFrames(p, gray=True) as v:
        one_by_one = {i: v[i] for i in range(40)}
    plan = [5, 6, 7, 20, 33, 39, 4, 2]
    with VideoFrames(p, gray=True) as v:
        v.prefetch(plan, workers=2, ahead=1)
        got = {i: v[i] for i in (5, 7, 20, 12, 39, 2)}  # 6, 33 and 4 skipped; 12 is not in the plan
        v.prefetch([30, 31], workers=1)
        got.update(v.read([31, 30, 0]))
    for i, img in got.items():
        assert img.shape == (48, 64) and img.flags.owndata
        np.testing.assert_array_equal(img, one_by_one[i])


def test_a_prefetched_frame_asked_for_again_is_decoded_again(tmp_path):
    """A retry of a frame already taken from the plan (a decoder retrying a frame it could not use) gets the frame
    from the caller's own reader; it once waited forever for a worker that had moved on."""
    p = tmp_path / "v.mp4"
    _video(p)
    with VideoFrames(p, gray=True) as v:
        want = v[5]
    got = {}
    def ask_twice():
        with VideoFrames(p, gray=True) as v:
            v.prefetch([5, 20, 33], workers=1, ahead=1)  # the worker waits after 5's group for the caller
            got["first"], got["again"], got["next"] = v[5], v[5], v[20]
    t = threading.Thread(target=ask_twice, daemon=True)
    t.start()
    t.join(timeout=60)
    assert not t.is_alive(), "asking for a taken frame again hangs"
    np.testing.assert_array_equal(got["first"], want)
    np.testing.assert_array_equal(got["again"], want)


def test_frames_csv_gives_variable_rate_times(tmp_path):
    p = tmp_path / "video.mp4"
    _video(p, n=6)
    t = [0, 100_000_000, 133_333_333, 166_666_667, 500_000_000, 1_000_000_000]
    (tmp_path / "video.frames.csv").write_text("frame_index,pts_ns\n" + "".join(f"{i},{v}\n" for i, v in enumerate(t)))
    fs = read_video(p)
    assert fs.t_ns.tolist() == t and fs.index.tolist() == list(range(6))
    assert read_video(p, frames_csv=False).t_ns[1] == 50_000_000
    log = read_flight([p])
    assert log.frames.t_ns.tolist() == t and log.missing_for_localization() == ["position", "attitude", "gimbal",
                                                                               "range"]
    (tmp_path / "video.frames.csv").write_text("frame,t\n0,0\n")
    with pytest.raises(LogReadError, match="expected header 'frame_index,pts_ns'"):
        read_video(p)
    (tmp_path / "video.frames.csv").write_text("frame_index,pts_ns\n0,0\n9,10\n")
    with pytest.raises(LogReadError, match="lists frame 9 but the video has 6 frames"):
        read_video(p)


def test_bad_videos(tmp_path):
    e = tmp_path / "empty.mp4"
    e.write_bytes(b"")
    with pytest.raises(LogReadError, match=r"empty\.mp4: empty video file"):
        read_video(e)
    g = tmp_path / "garbage.mp4"
    g.write_bytes(bytes(range(256)) * 40)
    with pytest.raises(LogReadError, match=r"garbage\.mp4: "):
        read_video(g)
    z = tmp_path / "zero.mp4"
    w = cv2.VideoWriter(str(z), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (32, 32))
    w.release()
    with pytest.raises(LogReadError, match=r"zero\.mp4: "):
        read_video(z)
    d = tmp_path / "DCIM"  # a folder given as files.video: said so, not "no such video file"
    d.mkdir()
    with pytest.raises(LogReadError, match=r"DCIM: a folder, not a video file$"):
        read_video(d)


MAVIC3 = """1
00:00:00,000 --> 00:00:00,033
<font size="28">FrameCnt: 1, DiffTime: 33ms
2023-04-01 10:00:00.123
[iso: 100] [shutter: 1/1000.0] [fnum: 2.8] [ev: 0] [focal_len: 24.00] [latitude: 22.543210] [longitude: 113.943210] [rel_alt: 50.100 abs_alt: 120.250] </font>

2
00:00:00,033 --> 00:00:00,066
<font size="28">FrameCnt: 2, DiffTime: 33ms
[latitude : 22.543220] [longitude : 113.943230] [rel_alt: 50.200 abs_alt: 120.350] [gb_yaw: 45.0 gb_pitch: -30.0 gb_roll: 0.0]</font>

3
00:00:00,066 --> 00:00:00,100
[latitude: 0.000000] [longitude: 0.000000] [rel_alt: 0.000 abs_alt: 0.000]
"""  # noqa: E501

P4RTK = """1
00:00:01,000 --> 00:00:02,000
F/2.8, SS 1000, ISO 100, EV 0, GPS (8.6521, 47.3852, 19), D 25.17m, H 38.00m, H.S 0.00m/s, V.S 0.00m/s, F.PRY (-1.2°, 0.9°, 64.3°), G.PRY (-30.0°, 0.0°, 64.4°)
"""  # noqa: E501

P4 = """1
00:00:00,000 --> 00:00:01,000
HOME(113.9427,22.5392) 2018.06.07 16:22:34
GPS(113.9431,22.5396,18) BAROMETER:31.2
ISO:100 Shutter:60 EV:0 Fnum:F2.8
"""

M300 = """1
00:00:00,000 --> 00:00:00,033
FrameCnt : 1 DiffTime : 33ms 2021-06-01 10:00:00,100 GPS(47.385200,8.652100,512.3m) D:120.00m H:100.00m
"""


def test_srt_variants():
    a = parse_srt(MAVIC3)
    assert a["t_ns"].tolist() == [0, 33_000_000]  # the no-fix block (0, 0) is dropped
    assert a["lat"].tolist() == [22.54321, 22.54322] and a["lon"][1] == 113.94323
    assert a["alt"].tolist() == [120.25, 120.35] and not a["rel"].any()
    assert (a["g_yaw"][1], a["g_pitch"][1], a["g_roll"][1]) == (45.0, -30.0, 0.0) and np.isnan(a["g_yaw"][0])
    assert parse_srt(MAVIC3, alt="rel")["alt"].tolist() == [50.1, 50.2]
    b = parse_srt(P4RTK)  # GPS (lon, lat, sats)
    assert (b["lat"][0], b["lon"][0], b["alt"][0], bool(b["rel"][0])) == (47.3852, 8.6521, 38.0, True)
    assert (b["f_pitch"][0], b["f_roll"][0], b["f_yaw"][0]) == (-1.2, 0.9, 64.3)
    assert (b["g_pitch"][0], b["g_yaw"][0]) == (-30.0, 64.4) and b["t_ns"][0] == 10**9
    c = parse_srt(P4)
    assert (c["lat"][0], c["lon"][0], c["alt"][0]) == (22.5396, 113.9431, 31.2)
    d = parse_srt(M300)
    assert (d["lat"][0], d["lon"][0], d["alt"][0], bool(d["rel"][0])) == (47.3852, 8.6521, 512.3, False)


def test_srt_reader_and_gimbal_frame(tmp_path):
    p = tmp_path / "DJI_0001.SRT"
    p.write_text(P4RTK)
    log = read_flight([p])
    assert log.position.alt_datum == "relative" and log.position.clock == "video"
    fwd = Rotation.from_quat(log.gimbal.quat_wxyz[0], scalar_first=True).apply([1, 0, 0])
    y, pch = math.radians(64.4), math.radians(-30.0)
    np.testing.assert_allclose(fwd, [math.cos(y) * math.cos(pch), math.sin(y) * math.cos(pch), -math.sin(pch)],
                               atol=1e-12)
    e = tmp_path / "e.srt"
    e.write_text("1\n00:00:00,000 --> 00:00:01,000\nhello\n")
    with pytest.raises(LogReadError, match=r"e\.srt: no subtitle with a GPS position"):
        read_flight([e])


def test_a_transport_stream_cut_mid_packet_says_it_looks_cut_off(tmp_path):
    """`head -c N clip.ts` (a copy or recording that stopped): read as far as it goes, with a warning in the log
    that inspect, check and run print; the whole file has none."""
    from pipeline.ingest import read_flight
    from pipeline.ingest.video import demux_index

    whole = Path(__file__).resolve().parents[1] / "sample_data" / "fmv" / "flight.ts"
    assert demux_index(whole).warnings == [] and not any("cut off" in w for w in read_flight([whole]).warnings)
    cut = tmp_path / "cut.ts"
    cut.write_bytes(whole.read_bytes()[:188 * 4000 + 100])
    (w,) = demux_index(cut).warnings
    assert w.startswith("cut.ts: ends inside a transport packet (752,100 bytes, 100 past") and "cut off" in w
    assert sum("looks cut off" in x for x in read_flight([cut]).warnings) == 1


def test_a_video_without_telemetry_is_refused_with_what_it_does_supply(tmp_path):
    """A plain video given as the flight's only file: one line saying it supplies only frames and that its
    telemetry logs belong beside it (it said 'check `mapping:`', which cannot help)."""
    from pipeline.errors import InputError
    from pipeline.flight.flight import read_flight_logs
    from pipeline.flight_config import Files, FlightConfig

    video = next((Path(__file__).resolve().parents[1] / "sample_data" / "group1").glob("*.mp4"))
    config = FlightConfig(name="plain", files=Files(telemetry=(str(video),)), path=str(tmp_path / "f.yaml"))
    with pytest.raises(InputError) as info:
        read_flight_logs(config)
    msg = str(info.value)
    assert "supply only frames: no position, attitude, gimbal; a video without KLV metadata needs the flight's " \
           "telemetry logs beside it (files.telemetry)" in msg and "\n" not in msg


def _ts_video(path, n=40, fps=20, size=(64, 48)):
    """A plain MPEG transport stream (no KLV), as a camera's recorder writes one."""
    from fractions import Fraction

    import av

    with av.open(str(path), "w", format="mpegts") as out:
        s = out.add_stream("mpeg2video", rate=fps)
        s.width, s.height, s.pix_fmt = size[0], size[1], "yuv420p"
        for i in range(n):
            img = np.full((size[1], size[0], 3), (i * 6) % 256, np.uint8)
            frame = av.VideoFrame.from_ndarray(img, format="bgr24").reformat(format="yuv420p")
            frame.pts, frame.time_base = i, Fraction(1, fps)
            for pkt in s.encode(frame):
                out.mux(pkt)
        for pkt in s.encode():
            out.mux(pkt)


def test_a_cut_off_video_beside_the_telemetry_says_so(tmp_path):
    """files.video cut mid-packet (a tlog flight's recorder stopped): the flight's notes say it looks cut off, as
    they do for a full-motion video read as telemetry, and an observation frame lost with the tail says why."""
    import dataclasses

    from pipeline.errors import InputError
    from pipeline.flight import Flight
    from pipeline.flight_config import load_flight_config

    whole = tmp_path / "v.ts"
    _ts_video(whole)
    data = whole.read_bytes()
    cut = tmp_path / "cut.ts"
    cut.write_bytes(data[: len(data) // 2 + 100])
    base = load_flight_config(Path(__file__).resolve().parents[1] / "configs" / "flights" / "group1.yaml")

    def flight(video, frames):
        return dataclasses.replace(base, files=dataclasses.replace(base.files, video=str(video), frames_csv=None),
                                   observations=dataclasses.replace(base.observations, mode="frames",
                                                                    frame_indices=frames))

    with Flight.open(flight(whole, (1, 2))) as f:
        assert not any("cut off" in w for w in f.notes)
    with Flight.open(flight(cut, (1, 2))) as f:
        assert sum("cut.ts: ends inside a transport packet" in w and "looks cut off" in w for w in f.notes) == 1
    with Flight.open(flight(cut, (1, 39))) as f, pytest.raises(InputError) as info:
        f.require_plan()
    msg = str(info.value)
    assert "observation frame(s) not in the video: [39]" in msg and "cut.ts: ends inside a transport packet" in msg
    assert "\n" not in msg
