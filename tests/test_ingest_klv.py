"""MISB ST 0601 KLV: the standard's own example values, checksums, damaged and hostile input, the mapping of the
angles into the model's frames, the MPEG-TS round trip and per-frame intrinsics from the field of view."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.errors import ConfigError, InputError, LogReadError
from pipeline.flight_config import load_run_config
from pipeline.ingest import detect_format, read_flight
from pipeline.ingest.ber import ber_length
from pipeline.ingest.klv import ST0601_KEY, decode_packet, scan_packets
from pipeline.intrinsics import K_from_field_of_view, frame_K, resolve_camera

# ST 0601's worked example of each tag (ST 0601.14a, the "Example Value" and "Example Octets" of sections 8.x):
# tag -> (value octets, the value the standard prints).
EXAMPLES = {5: ("71C2", 159.974365), 6: ("FD3D", -0.431531724), 7: ("08B8", 3.40586566),
            13: ("5595B66D", 60.176822966978335), 14: ("5B5360C4", 128.42675904204452), 15: ("C221", 14190.7195),
            16: ("CD9C", 144.571298), 17: ("D917", 152.643626), 18: ("724A0A20", 160.71921143697557),
            19: ("87F84B86", -168.79232483394085), 20: ("7DC55ECE", 176.86543764939194),
            21: ("03830926", 68590.983298744770), 23: ("F101A229", -10.542388633146132),
            24: ("14BC082B", 29.157890122923014), 25: ("34F3", 3216.03723), 40: ("8F695262", -79.163850051892850),
            41: ("765457F2", 166.40081296041646), 42: ("F823", 18389.0471)}
EXAMPLE_TIME = "000459F4A6AA4AA8"  # Oct. 24, 2008. 00:13:29.913 (tag 2's example)
COLUMN = {5: "heading_deg", 6: "pitch_deg", 7: "roll_deg", 13: "lat_deg", 14: "lon_deg", 15: "alt_msl_m",
          16: "hfov_deg", 17: "vfov_deg", 18: "sensor_az_deg", 19: "sensor_el_deg", 20: "sensor_roll_deg",
          21: "slant_range_m", 23: "centre_lat_deg", 24: "centre_lon_deg", 25: "centre_alt_m", 40: "target_lat_deg",
          41: "target_lon_deg", 42: "target_alt_m"}


def _packet(items: dict[int, str]) -> bytes:
    """An ST 0601 packet of hex-valued items (tag 2 first), with the checksum computed by hand as the standard
    defines it: the 16-bit sum of the bytes as big-endian words, from the key to tag 1's length byte."""
    body = b"".join(bytes([t, len(bytes.fromhex(v))]) + bytes.fromhex(v) for t, v in items.items())
    value_len = len(body) + 4
    head = ST0601_KEY + (bytes([value_len]) if value_len < 128 else bytes([0x81, value_len]))
    pk = head + body + b"\x01\x02"
    s = sum(b << (8 * ((i + 1) % 2)) for i, b in enumerate(pk)) & 0xFFFF
    return pk + s.to_bytes(2, "big")


def _hex_items(**angles) -> dict[int, str]:
    """Items of a packet at time t_us with the given values, encoded as the standard maps them."""
    maps = {5: (0, 360, 2, False), 6: (-20, 20, 2, True), 7: (-50, 50, 2, True), 13: (-90, 90, 4, True),
            14: (-180, 180, 4, True), 75: (-900, 19000, 2, False), 16: (0, 180, 2, False), 17: (0, 180, 2, False),
            18: (0, 360, 4, False), 19: (-180, 180, 4, True), 20: (0, 360, 4, False), 21: (0, 5e6, 4, False)}
    tag_of = {"heading": 5, "pitch": 6, "roll": 7, "lat": 13, "lon": 14, "hae": 75, "hfov": 16, "vfov": 17,
              "az": 18, "el": 19, "sroll": 20, "range": 21}
    out = {2: f"{angles.pop('t_us'):016X}"}
    for name, v in angles.items():
        lo, hi, n, signed = maps[tag_of[name]]
        if signed:
            m = (1 << (8 * n - 1)) - 1
            i = round(v * m / hi)
        else:
            offset = lo
            i = round((v - offset) * ((1 << (8 * n)) - 1) / (hi - lo))
        out[tag_of[name]] = i.to_bytes(n, "big", signed=signed).hex()
    return out


def test_the_standards_example_values():
    pk = _packet({2: EXAMPLE_TIME, **{t: v for t, (v, _) in EXAMPLES.items()}, 65: "0D"})
    row = decode_packet(pk)
    assert row["t_us"] == 0x000459F4A6AA4AA8
    for tag, (_, value) in EXAMPLES.items():
        assert row[COLUMN[tag]] == pytest.approx(value, rel=1e-8, abs=1e-6), tag


def test_bad_checksum_and_cut_off_packets_are_skipped_and_counted(tmp_path):
    good = [_packet(_hex_items(t_us=1_700_000_000_000_000 + k * 40_000, heading=10.0 + k, pitch=1.0, roll=-2.0,
                               lat=47.0, lon=8.0, hae=1500.0)) for k in range(5)]
    bad = bytearray(good[1])
    bad[-5] ^= 0x01  # a flipped bit in a value: the checksum no longer matches
    data = b"junk" + good[0] + bytes(bad) + b"\x00\x17" + good[2] + good[3] + good[4][:-7]
    p = tmp_path / "dump.klv"
    p.write_bytes(data)
    assert detect_format(p) == "klv"
    log = read_flight([p])
    assert log.attitude.t_ns.tolist() == [(1_700_000_000_000_000 + k * 40_000) * 1000 for k in (0, 2, 3)]
    assert log.attitude.clock == log.position.clock == "unix"
    assert any("skipped 2 KLV packet(s) of 5 (1 bad checksum or undecodable, 1 cut off)" in w for w in log.warnings)
    yaw = Rotation.from_quat(log.attitude.quat_wxyz, scalar_first=True).as_euler("ZYX", degrees=True)[:, 0]
    np.testing.assert_allclose(yaw, [10.0, 12.0, 13.0], atol=0.01)
    np.testing.assert_allclose(log.position.alt_m, 1500.0, atol=0.2)
    assert log.position.alt_datum == "ellipsoid"


def test_sensor_angles_compose_on_the_platform_attitude(tmp_path):
    """Heading 90 deg (east) and the sensor turned 90 deg right and 30 deg down: it looks south, 30 deg below
    the horizon. Heading 0, elevation -90: straight down."""
    pks = [_packet(_hex_items(t_us=1_000_000, heading=90.0, pitch=0.0, roll=0.0, az=90.0, el=-30.0, sroll=0.0)),
           _packet(_hex_items(t_us=2_000_000, heading=0.0, pitch=0.0, roll=0.0, az=0.0, el=-90.0, sroll=0.0))]
    p = tmp_path / "angles.klv"
    p.write_bytes(b"".join(pks))
    g = read_flight([p]).gimbal
    axis = Rotation.from_quat(g.quat_wxyz, scalar_first=True).apply([1.0, 0.0, 0.0])  # gimbal x: optical axis, NED
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    np.testing.assert_allclose(axis, [[-c, 0.0, s], [0.0, 0.0, 1.0]], atol=1e-4)
    assert not g.yaw_in_vehicle_frame.any()


def test_hostile_bytes_get_one_line_errors_and_stay_bounded(tmp_path):
    rng = np.random.default_rng(3)
    cases = {"random.klv": rng.integers(0, 256, 200_000, dtype=np.uint8).tobytes(),
             # keys that claim lengths running past the end, many times over
             "keys.klv": (ST0601_KEY + b"\x83\x00\xff\xff") * 5000,
             "huge.klv": ST0601_KEY + b"\x88" + b"\xff" * 8,
             "empty.klv": b""}
    for name, data in cases.items():
        p = tmp_path / name
        p.write_bytes(data)
        with pytest.raises(LogReadError) as exc:
            read_flight([p])
        assert "\n" not in str(exc.value) and name in str(exc.value)
    rows, bad, cut = scan_packets((ST0601_KEY + b"\x83\x00\xff\xff") * 5000)
    assert rows == [] and bad + cut == 5000



def test_ber_length_short_long_malformed_and_cut_off():
    # X.690 8.1.3 by hand: 0x7F = 127 (short form); 0x82 01 00 = 256; 0x84 00 01 00 00 = 65536
    assert ber_length(b"\x7f", 0) == (127, 1)
    assert ber_length(b"ab\x82\x01\x00xyz", 2) == (256, 5)
    assert ber_length(b"\x84\x00\x01\x00\x00", 0) == (65536, 5)
    assert ber_length(b"\x80", 0) is None and ber_length(b"\x85" + bytes(5), 0) is None  # indefinite, too long
    data = b"\x83\x00\x01"  # a 3-byte length with 2 bytes left: cut off, reported past the end
    assert ber_length(data, 0)[1] > len(data) and ber_length(data, 3)[1] > len(data)

def _tiny_fmv(path, zoom_at_frame: int = 6, n: int = 12):
    from pipeline.synth.writers.fmv import write_fmv

    frames = []
    rng = np.random.default_rng(0)
    for _ in range(n):
        frames.append(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
    pts = np.arange(n, dtype=np.int64) * 40_000_000 + 1_000_000_000  # the video starts 1 s into its clock
    packets = []
    for k in range(n):
        hfov = 20.0 if k < zoom_at_frame else 10.0
        items = _hex_items(t_us=1_700_000_000_000_000 + k * 40_000, heading=45.0, pitch=0.0, roll=0.0,
                           lat=47.0, lon=8.0, hae=1500.0, az=0.0, el=-30.0, sroll=0.0, hfov=hfov, vfov=hfov * 0.75)
        if k % 5 == 0:
            items[21] = (round(4000.0 * ((1 << 32) - 1) / 5e6)).to_bytes(4, "big").hex()
        packets.append((int(pts[k]), _packet(items)))
    write_fmv(path, frames, pts, packets, 25, (64, 48), preset="ultrafast")
    return frames


def test_mpegts_round_trip_and_intrinsics_from_the_field_of_view(tmp_path):
    p = tmp_path / "tiny.ts"
    _tiny_fmv(p)
    log = read_flight([p])
    assert log.formats == ["fmv"] and log.missing_for_localization() == []
    np.testing.assert_array_equal(log.frames.t_ns, np.arange(12) * 40_000_000)  # video clock: 0 = first frame
    np.testing.assert_array_equal(log.attitude.t_ns, log.frames.t_ns)  # each packet carries its frame's PTS
    assert log.range.t_ns.tolist() == [0, 200_000_000, 400_000_000]
    np.testing.assert_allclose(log.range.range_m, 4000.0, atol=0.01)
    link = log.clock_links[0]
    assert (link.a, link.b) == ("video", "unix") and link.b_ns[0] == 1_700_000_000_000_000_000
    (entry,) = load_run_config(p)  # the file alone: no camera in the config
    cam, source = resolve_camera(entry.config, log)
    assert source.startswith("field of view") and cam.dist == (0.0,) * 5
    K = frame_K(cam, source, log, log.frames.t_ns)
    fx = K[:, 0, 0]
    np.testing.assert_allclose(fx[:6], 64 / (2 * np.tan(np.radians(10.0))), rtol=1e-4)  # hfov 20 deg
    np.testing.assert_allclose(fx[6:], 64 / (2 * np.tan(np.radians(5.0))), rtol=1e-4)  # zoomed in: 10 deg
    np.testing.assert_allclose(K[:, 0, 2], 31.5)
    np.testing.assert_allclose(K[:, 1, 2], 23.5)


def test_field_of_view_intrinsics_and_their_errors():
    K = K_from_field_of_view([90.0], [np.nan], 1000, 500)
    np.testing.assert_allclose(K[0], [[500.0, 0, 499.5], [0, 500.0, 249.5], [0, 0, 1]])
    with pytest.raises(InputError, match="field of view"):
        K_from_field_of_view([0.0], [10.0], 100, 100)
    from pipeline.flight_config import Files, FlightConfig
    from pipeline.ingest.model import FlightLog

    with pytest.raises(ConfigError, match="no camera intrinsics"):
        resolve_camera(FlightConfig(name="x", files=Files(telemetry=("x.ts",))), FlightLog(path="x"))


def test_a_video_file_alone_is_a_flight(tmp_path):
    p = tmp_path / "sortie 7.ts"
    _tiny_fmv(p)
    (entry,) = load_run_config(p)
    cfg = entry.config
    assert cfg.name == "sortie_7" and not cfg.camera.has_intrinsics and cfg.target is None
    assert cfg.files.telemetry == (str(p.resolve()),)


def test_a_video_without_klv_is_refused_as_telemetry(tmp_path):
    import av

    p = tmp_path / "plain.ts"
    rng = np.random.default_rng(1)
    with av.open(str(p), "w", format="mpegts") as out:
        vs = out.add_stream("libx264", rate=25)
        vs.width, vs.height, vs.pix_fmt = 64, 48, "yuv420p"
        for i in range(12):
            f = av.VideoFrame.from_ndarray(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), format="rgb24")
            f.pts = i
            out.mux(vs.encode(f))
        out.mux(vs.encode(None))
    log = read_flight([p])
    assert log.frames.t_ns.size == 12 and log.position is None and log.formats == ["video"]


@pytest.mark.parametrize("suffix", [".mp4", ".ts"])
def test_variable_frame_rate_times_from_the_demux_and_chosen_frames(tmp_path, suffix):
    """Irregular pts survive indexing; frames decoded by seeking equal those decoded in sequence."""
    import av

    from pipeline.ingest import VideoFrames, read_video

    t_ms = [0, 40, 100, 133, 500, 540, 1000, 1040, 1080, 2000, 2040, 2080, 2120, 2160, 2200, 2240]
    p = tmp_path / f"vfr{suffix}"
    rng = np.random.default_rng(2)
    with av.open(str(p), "w") as out:
        vs = out.add_stream("libx264", rate=25)
        vs.width, vs.height, vs.pix_fmt = 64, 48, "yuv420p"
        vs.codec_context.time_base = vs.time_base = Fraction(1, 1000)
        vs.options = {"g": "4", "preset": "ultrafast"}
        for t in t_ms:
            f = av.VideoFrame.from_ndarray(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), format="rgb24")
            f.pts, f.time_base = t, Fraction(1, 1000)
            out.mux(vs.encode(f))
        out.mux(vs.encode(None))
    fs = read_video(p)
    np.testing.assert_array_equal(fs.t_ns, np.array(t_ms) * 1_000_000)
    with VideoFrames(p) as v:
        seq = v.read(range(len(t_ms)))
    with VideoFrames(p, seek_after=1) as v:
        for i in (13, 2, 9, 0, 15, 5):
            np.testing.assert_array_equal(v[i], seq[i])
