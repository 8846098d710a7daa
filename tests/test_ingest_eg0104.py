"""MISB EG 0104 universal sets: values worked by hand from the standard's key table and IEEE 754, damaged and
unknown items counted, the KWIVER Fort A.P. Hill clips end to end, and the frame-centre cross-check on them and
on the synth's ST 0601 writer (right and deliberately wrong sensor-angle convention)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pipeline.geometry.grid_north import utm_convergence_deg
from pipeline.ingest import read_flight
from pipeline.ingest.frame_centre import GRID_NORTH, TRUE_NORTH, check_file, check_frame_centre
from pipeline.ingest.klv import KlvTable, decode_eg0104, read_klv_table, scan_packets
from support.writers import eg0104_set, klv_item

FMV = Path(__file__).resolve().parents[1].parent / "shared" / "fmv"  # ../shared from the repo root
# KLV sets, video frames (README there: aphill_short.ts has 96 access units, the two fields of each of 48 frames)
CLIPS = {"aphill_short.ts": (48, 48), "aphill_klv_10s.ts": (300, 10)}
SET_KEY = bytes.fromhex("060E2B34020101010E01010201010000")
UL = "060E2B34010101"  # EG 0104.5 table 1: every item key starts so; the 8th byte is the registry version


def _item(version: str, rest: str, value_hex: str) -> bytes:
    return klv_item(bytes.fromhex(UL + version + rest), bytes.fromhex(value_hex))


# (key after the version byte, version byte, value octets, the value worked by hand, column)
# IEEE 754 by hand: 0x4043200000000000 = +1.1953125 * 2^5 = 38.25; 0xC053400000000000 = -1.203125 * 2^6 = -77.0;
# 0x44838000 = 1.02734375 * 2^10 = 1052.0; 0xC2CD0000 = -1.6015625 * 2^6 = -102.5; 0x3FE00000 = 1.75;
# 0x3F800000 = 1.0; 0x3F400000 = 0.75; 0x44D80000 = 1.6875 * 2^10 = 1728.0; 0x42F60000 = 1.921875 * 2^6 = 123.0;
# 0xC2160000 = -1.171875 * 2^5 = -37.5; 0x4043180000000000 = 1.193359375 * 2^5 = 38.1875;
# 0xC053600000000000 = -1.2109375 * 2^6 = -77.5; 0x41200000 = 1.25 * 2^3 = 10.0.
HAND = [
    ("0701020102040200", "03", "4043200000000000", 38.25, "lat_deg"),  # Device Latitude
    ("0701020102060200", "03", "C053400000000000", -77.0, "lon_deg"),  # Device Longitude
    ("0701020102020000", "01", "44838000", 1052.0, "alt_msl_m"),  # Device Altitude (MSL)
    ("0701100106000000", "07", "C2CD0000", -102.5, "heading_deg"),  # Platform Heading Angle
    ("0701100105000000", "07", "3FE00000", 1.75, "pitch_deg"),  # Platform Pitch Angle
    ("0701100104000000", "07", "3F800000", 1.0, "roll_deg"),  # Platform Roll Angle
    ("0420020101080000", "02", "3F800000", 1.0, "hfov_deg"),  # Field of View (horizontal)
    ("04200201010A0100", "07", "3F400000", 0.75, "vfov_deg"),  # Field of View (vertical)
    ("0701080101000000", "01", "44D80000", 1728.0, "slant_range_m"),  # Slant Range
    ("0701100102000000", "01", "42F60000", 123.0, "sensor_az_deg"),  # Angle to North
    ("0701100103000000", "01", "C2160000", -37.5, "sensor_el_deg"),  # Obliquity Angle
    ("0701020103020000", "01", "4043180000000000", 38.1875, "centre_lat_deg"),  # Frame Center Latitude
    ("0701020103040000", "01", "C053600000000000", -77.5, "centre_lon_deg"),  # Frame Center Longitude
    ("0701020103160000", "0A", "41200000", 10.0, "centre_alt_m"),  # Frame Center Elevation
    ("0701020103070100", "03", "4043180000000000", 38.1875, "corner1_lat_deg"),  # Corner Latitude Point 1
    ("07010201030B0100", "03", "C053600000000000", -77.5, "corner1_lon_deg"),  # Corner Longitude Point 1
    ("0701090201000000", "01", "41200000", 10.0, "target_width_m"),  # Target Width
]
TIME = ("0702010101050000", "03", "000456F62CBCC960")  # User Defined Time Stamp: 1221515219356000 us


def test_the_key_table_against_values_worked_by_hand():
    items = [_item(TIME[1], TIME[0], TIME[2])] + [_item(v, k, x) for k, v, x, _, _ in HAND]
    row = decode_eg0104(eg0104_set(items))
    assert row["t_us"] == 1_221_515_219_356_000  # 2008-09-15 21:46:59.356 UTC
    assert row["_unknown"] == row["_damaged"] == 0 and row["set"] == "eg0104"
    for _, _, _, value, column in HAND:
        assert row[column] == value, column


def test_any_version_byte_matches_and_text_items_stay_out_of_the_numbers():
    t = _item("00", TIME[0], TIME[2])
    for version in ("01", "02", "0A", "FF"):
        row = decode_eg0104(eg0104_set([t, _item(version, "0701080101000000", "44D80000"),
                                  _item("01", "0101200100000000", "41424344")]))  # Device Designation "ABCD"
        assert row["slant_range_m"] == 1728.0 and "device_designation" not in row


def test_unknown_damaged_and_cut_off_items_are_skipped_and_counted():
    t = _item("03", TIME[0], TIME[2])
    items = [t,
             _item("01", "0E01020304050607", "3F800000"),  # a key outside the table
             bytes.fromhex("060E2B3401020101" + "0701080101000000") + b"\x04" + bytes.fromhex("3F800000"),  # not UL
             _item("01", "0701080101000000", "44D800"),  # 3-byte float: damaged
             _item("01", "0701100102000000", "7FC00000"),  # NaN azimuth: damaged
             _item("03", "0701020102040200", "4059000000000000"),  # latitude 100 deg: out of range
             _item("07", "0701100106000000", "C2CD0000")]  # a good heading after them
    row = decode_eg0104(eg0104_set(items))
    assert (row["_unknown"], row["_damaged"]) == (2, 3)
    assert row["heading_deg"] == -102.5 and "slant_range_m" not in row and "lat_deg" not in row
    # an item whose length runs past the set: the items before it are kept, the break counted
    past_end = bytes.fromhex(UL + "01" + "0701080101000000") + b"\x7f"  # claims 127 bytes, has none
    cut = eg0104_set([t, _item("07", "0701100106000000", "C2CD0000"), past_end])
    row = decode_eg0104(cut)
    assert row["heading_deg"] == -102.5 and row["_damaged"] == 1
    assert decode_eg0104(eg0104_set([_item("07", "0701100106000000", "C2CD0000")])) is None  # no time stamp


def test_a_raw_dump_reads_into_the_model_and_counts_in_a_warning(tmp_path):
    sets = []
    for k in range(3):
        t_us = 1_221_515_219_356_000 + k * 40_000
        sets.append(eg0104_set([_item("03", TIME[0], f"{t_us:016X}"), *[_item(v, key, x) for key, v, x, _, _ in HAND],
                          _item("01", "0E01020304050607", "3F800000")]))
    p = tmp_path / "eg.klv"
    p.write_bytes(b"\x00junk" + b"".join(sets))
    log = read_flight([p])
    assert log.position.alt_datum == "amsl" and log.position.clock == "unix"
    assert log.position.t_ns.tolist() == [(1_221_515_219_356_000 + k * 40_000) * 1000 for k in range(3)]
    np.testing.assert_allclose(log.position.alt_m, 1052.0)
    assert any("3 with an unknown key, 0 damaged" in w for w in log.warnings)
    # earth-referenced sensor angles: the optical axis at azimuth 123 deg from north, 37.5 deg below the horizon
    axis = Rotation.from_quat(log.gimbal.quat_wxyz, scalar_first=True).apply([1.0, 0.0, 0.0])[0]
    az, el = np.radians(123.0), np.radians(37.5)
    np.testing.assert_allclose(axis, [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], atol=1e-9)
    assert log.frame_centre.lat_deg[0] == 38.1875 and log.frame_centre.alt_m[0] == 10.0


def test_utm_convergence_by_hand():
    # zone 18 (central meridian -75 deg): atan(tan(-2.37 deg) sin(38.25 deg)) = atan(-0.041388 * 0.619094), the
    # sphere's value; the ellipsoid's terms change it by under 0.001 deg
    np.testing.assert_allclose(utm_convergence_deg(38.25, -77.37), -1.46777, atol=1e-3)
    np.testing.assert_allclose(utm_convergence_deg(10.0, 3.0), 0.0, atol=1e-9)  # zone 31's central meridian


# ---- the real clips -------------------------------------------------------------------------------------

def _clip(name: str) -> Path:
    p = FMV / name
    if not p.is_file():
        pytest.skip(f"{p} absent (the shared read-only material is not beside this checkout)")
    return p


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_the_kwiver_clips_read_every_quantity(name):
    n_sets, n_frames = CLIPS[name]
    log = read_flight([_clip(name)])
    assert log.missing_for_localization() == [] and log.formats == ["fmv"]
    assert log.frames.t_ns.size == n_frames
    for q in ("position", "attitude", "gimbal", "range", "field_of_view", "frame_centre"):
        assert getattr(log, q).t_ns.size == n_sets, q
    assert log.position.alt_datum == "amsl" and not any("skipped" in w for w in log.warnings)
    assert np.isnan(log.frame_centre.alt_m).all()  # these clips carry no frame-centre elevation
    np.testing.assert_allclose(log.field_of_view.hfov_deg, 0.8, atol=1e-6)
    from pipeline.ingest.inspect import format_result, inspect_paths

    (result,) = inspect_paths([str(_clip(name))])
    text = format_result(result)
    for what in (f"position {n_sets}", f"attitude {n_sets}", f"gimbal {n_sets}", "EG 0104 sensor angles",
                 f"range {n_sets}", "EG 0104 slant range", f"field_of_view {n_sets}", f"frames {n_frames}"):
        assert what in text, what
    assert "missing for localization: nothing" in text


@pytest.mark.parametrize("name, median_m", [("aphill_short.ts", 35.5), ("aphill_klv_10s.ts", 72.3)])
def test_the_frame_centre_on_the_kwiver_clips_is_off_by_the_utm_grid_convergence(name, median_m):
    """Read as earth-referenced angles from true north, the line of sight lands a constant ~1.47 deg of azimuth
    from the logged frame centre (35 m at 1.4 km, 72 m at 2.8 km horizontal); measured from UTM zone 18 grid
    north it lands within a metre: the payload's azimuth is a grid azimuth."""
    r = check_file(_clip(name))
    assert r.n == CLIPS[name][0] and r.horizontal_only
    assert r.median_m == pytest.approx(median_m, abs=0.5) and r.p95_m < median_m + 2
    assert r.alternatives[GRID_NORTH] < 1.0 and r.explained_by == GRID_NORTH
    platform = "sensor angles relative to the platform (ST 0601: platform ZYX, then sensor ZYX)"
    assert r.alternatives[platform] > 2000  # ST 0601's composition is kilometres off on these clips


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_the_grid_azimuth_switch_puts_the_line_of_sight_on_the_frame_centre(name, tmp_path):
    """`check` names the switch that explains the miss; with `mapping: {klv: {azimuth_north: grid}}` the
    reader turns the azimuths to true north and the frame centre is within 5 m (the alternative is then true
    north, 35-72 m off)."""
    r = check_file(_clip(name))
    assert "set `mapping: {klv: {azimuth_north: grid}}` in the flight config" in r.line()
    g = check_file(_clip(name), mapping={"azimuth_north": "grid"})
    assert g.median_m < 5.0 and g.explained_by is None and "grid north" in g.convention
    assert g.alternatives[TRUE_NORTH] == pytest.approx(r.median_m, abs=0.01)
    cfg = tmp_path / "clip.yaml"
    cfg.write_text(f"name: clip\nfiles: {{telemetry: [{_clip(name)}]}}\naltitude: {{geoid_separation_m: auto}}\n"
                   "mapping: {klv: {azimuth_north: grid}}\n")
    out = subprocess.run([sys.executable, "-m", "pipeline", "check", str(cfg), "--json", "--no-clock"],
                         capture_output=True, text=True, timeout=600)
    fc = json.loads(out.stdout)["frame_centre"]
    assert fc["median_m"] < 5.0 and fc["explained_by"] is None


def test_check_json_on_a_clip_prints_frame_centre():
    """A clip checked alone reads its azimuths as its frame centres say (azimuth_north: auto): from grid north,
    0.2 m from the frame centres, and says so among the warnings."""
    p = _clip("aphill_short.ts")
    out = subprocess.run([sys.executable, "-m", "pipeline", "check", str(p), "--json", "--no-clock"],
                         capture_output=True, text=True, timeout=600)
    doc = json.loads(out.stdout)
    fc = doc["frame_centre"]
    assert fc["n"] == 48 and fc["median_m"] < 1.0 and fc["p95_m"] >= fc["median_m"] and fc["explained_by"] is None
    assert "grid north" in fc["convention"]
    assert any("azimuths read from UTM grid north (klv.azimuth_north: auto)" in w
               and "35.5 m from it read from true north" in w for w in doc["warnings"]), doc["warnings"]


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_a_clip_run_alone_reads_its_azimuths_as_its_frame_centres_say(name):
    """`ridgeloc run clip.ts` (no config): the clip's config asks for azimuth_north auto, and the reader takes
    grid north where the frame-centre check finds the miss explained by it (both KWIVER clips), true north where
    the frame centres agree with it (the sample full-motion video) or where no config asks (the default)."""
    from pipeline.flight_config import flight_config_for_video

    config = flight_config_for_video(_clip(name))
    assert config.mapping == {"klv": {"azimuth_north": "auto"}}
    auto = read_flight([_clip(name)], mapping=config.mapping)
    assert next(iter(auto.klv_tables.values())).azimuth_north == "grid"
    assert sum("(klv.azimuth_north: auto)" in w for w in auto.warnings) == 1
    plain = read_flight([_clip(name)])
    assert next(iter(plain.klv_tables.values())).azimuth_north == "true"
    assert not any("azimuth_north: auto" in w for w in plain.warnings)
    sample = Path(__file__).resolve().parents[1] / "sample_data" / "fmv" / "flight.ts"
    synthetic = read_flight([sample], mapping=config.mapping)
    assert next(iter(synthetic.klv_tables.values())).azimuth_north == "true"
    assert not any("azimuth_north: auto" in w for w in synthetic.warnings)


def test_a_field_coded_clip_is_indexed_one_frame_per_field_pair():
    """aphill_short.ts is interlaced H.264 coded as fields: 96 packets, two per frame, 48 decoded frames. The
    index holds the 48 (29.97 Hz), each decodes once; it held 96, every second undecodable (and retried)."""
    from fractions import Fraction

    from pipeline.ingest import VideoFrames
    from pipeline.ingest.video import first_fields

    with VideoFrames(_clip("aphill_short.ts"), gray=True) as v:
        n = v.index.pts.size
        assert n == 48
        assert np.median(np.diff(v.index.frames.t_ns)) == pytest.approx(1e9 * 1001 / 30000, abs=1e5)
        assert len(v.read(list(range(n)))) == n and v.decoded == n
    tb = Fraction(1, 90000)
    fields = (np.round(np.arange(20) * 1501.5) + 129003).astype(np.int64)  # packets half a frame apart
    assert first_fields(fields, Fraction(30000, 1001), Fraction(60000, 1001), tb).tolist() == [True, False] * 10
    # progressive: the base rate is the frame rate, every packet a frame
    assert first_fields(fields, Fraction(60000, 1001), Fraction(60000, 1001), tb) is None
    frames = (np.arange(20) * 3003 + 129003).astype(np.int64)
    assert first_fields(frames, Fraction(30000, 1001), Fraction(60000, 1001), tb) is None  # no second fields


def test_a_cut_clip_gets_no_ridge_point_hundreds_of_metres_underground(tmp_path):
    """aphill_klv_10s.ts cut to its first 100 kB (two laser shots): fusion is not determined there, and ridge, fusion
    with a penalty, answered 336 m below sea level with a CE90 of 36 m. Now ridge is not determined where fusion is
    not, and the answer is the laser's point, as on the whole clip."""
    import csv

    from pipeline.cli import main as cli_main

    cut = tmp_path / "clip.ts"
    cut.write_bytes(_clip("aphill_klv_10s.ts").read_bytes()[:100_000])
    assert cli_main(["run", str(cut), "-o", str(tmp_path / "out"), "-q"]) == 0
    (answer,) = list(csv.DictReader((tmp_path / "out" / "targets.csv").open()))
    assert answer["status"] == "located" and answer["method"] == "los" and abs(float(answer["alt_msl_m"])) < 50
    rows = {r["method"]: r for r in csv.DictReader((tmp_path / "out" / "estimates.csv").open())}
    assert rows["fusion"]["determined"] == "false" and rows["ridge"]["determined"] == "false"
    assert "it is fusion with a penalty" in rows["ridge"]["reason"]


def test_a_clip_cut_after_one_metadata_packet_is_named_so_not_a_clock_error(tmp_path, capsys):
    """aphill_short.ts cut to 30 kB keeps one EG 0104 packet: the telemetry is a single instant; the run said "the
    video clock is off; set clock.video_start", which no clock setting fixes."""
    from pipeline.cli import main as cli_main

    cut = tmp_path / "clip.ts"
    cut.write_bytes(_clip("aphill_short.ts").read_bytes()[:30_000])
    assert cli_main(["run", str(cut), "-o", str(tmp_path / "out"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "the telemetry covers a single instant (-0.033 s)" in err and "is the file cut short?" in err
    assert "video clock is off" not in err


def test_check_on_a_clip_does_not_give_the_undetermined_meeting_point_a_small_sigma():
    """The ranges against where nearly parallel lines of sight meet: the line says the meeting point is
    undetermined (+-3 km along them), beside the warning; it printed the statistical +-14.6 m."""
    p = _clip("aphill_short.ts")
    out = subprocess.run([sys.executable, "-m", "pipeline", "check", str(p), "--no-clock"],
                         capture_output=True, text=True, timeout=600).stdout
    (line,) = [x for x in out.splitlines() if "laser range - distance to where the lines of sight meet" in x]
    assert re.search(r"\(undetermined: \+-\d{4} m along nearly parallel lines of sight\)$", line), line
    assert "warning: the lines of sight are nearly parallel" in out


@pytest.mark.parametrize("name", sorted(CLIPS))
def test_run_on_a_clip_locates_the_crosshair_near_the_frame_centre(name):
    import pipeline.ingest.klv as klv
    from pipeline.flight_config import load_run_config
    from pipeline.run import process_group

    (entry,) = load_run_config(_clip(name))
    tables, real_table = [], klv._fmv_table

    def fmv_table(*a, **k):  # the clip's KLV stream is demuxed and decoded once: the frame-centre check reuses it
        tables.append(a[0])
        return real_table(*a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(klv, "_fmv_table", fmv_table)
        result = process_group(entry.config)
    assert len(tables) == 1
    from pipeline.geometry.frames import lla_from_enu

    lat, lon, _ = lla_from_enu(result.estimates["los"].position_m, result.origin_lla)
    log = read_flight([_clip(name)])
    # the logged frame centres of the clip, within the grid-azimuth offset (35 m) and the camera's motion
    d_m = np.hypot((log.frame_centre.lat_deg - lat) * 111_000,
                   (log.frame_centre.lon_deg - lon) * 111_000 * np.cos(np.radians(lat)))
    assert d_m.min() < 100.0
    assert any(n.startswith(f"frame centre: {CLIPS[name][0]} packets") for n in result.settings["notes"])
    # the lines of sight are 1.3 and 7.9 deg apart, the ranges 1.7 km and 517 m shorter than where they meet
    # (docs/check.md): run carries check's warning into the notes and every estimate's reason in the exports
    warning, level = result.settings["geometry_warnings"]
    assert warning in result.settings["notes"] and level in result.settings["notes"]
    assert re.search(r"nearly parallel \(first to last \d+\.\d deg\): where they meet is undetermined", warning)
    # the payload's slant ranges end at sea level (no laser): said, in the answer's reason too
    assert level.startswith("the laser ranges all end at sea level (+0.")
    from pipeline.report.answers import answer_row
    from pipeline.report.exports import estimate_rows

    rows = {r["method"]: r for r in estimate_rows([result])}
    assert "vision" in result.estimates and "dlt" in result.estimates
    for m, e in result.estimates.items():
        if np.isfinite(e.position_m).all():
            assert warning in rows[m]["reason"], m
    # one answer, the laser's point, at the platform's own frame centre (within the grid-azimuth offset)
    answer = answer_row(result)
    assert answer["status"] == "located" and answer["method"] == "los"
    assert answer["reason"].endswith(f"; warning: {warning}; warning: {level}")

    def off_centre_m(row):
        return np.hypot((log.frame_centre.lat_deg - row["lat_deg"]) * 111_000,
                        (log.frame_centre.lon_deg - row["lon_deg"]) * 111_000 * np.cos(np.radians(lat))).min()

    assert off_centre_m(answer) < 100.0
    # the methods the nearly parallel lines of sight do not determine are no point anywhere: estimates.csv lists
    # them without coordinates and says why; every point exported is near the frame centre and not below the
    # laser's ground point by more than its own uncertainty
    undetermined = {m for m, r in rows.items() if r["determined"] is False}
    assert {"vision", "dlt", "fusion", "ridge"} <= undetermined
    for m in undetermined:
        assert rows[m]["lat_deg"] is None and ("not determined" in rows[m]["reason"] or m in ("range", "mle")), m
    for m, r in rows.items():
        if r["determined"]:
            assert off_centre_m(r) < 300.0, m
            assert r["alt_m"] > answer["alt_m"] - 3 * max(r["sigma_up_m"] or 0.0, 10.0), m


# ---- the synth's ST 0601 writer ------------------------------------------------------------------------

def _synth_tel(n: int = 40):
    """A platform circling 2 km from a point 400 m below, banked, its gimbal on the point; a laser each packet."""
    from pipeline.geometry.frames import lla_from_enu

    t = np.arange(n, dtype=np.int64) * 200_000_000 + 1_700_000_000 * 10**9
    a = np.linspace(0, 1.5, n)
    enu = np.column_stack([2000 * np.cos(a), 2000 * np.sin(a), np.full(n, 400.0)])
    origin = (47.3, 8.5, 500.0)
    lla = lla_from_enu(enu, origin)
    yaw_ned = np.degrees(np.arctan2(np.cos(a), -np.sin(a)))  # flying counter-clockwise (ENU): tangent heading
    body = Rotation.from_euler("ZYX", np.column_stack([yaw_ned, np.full(n, 4.0), np.full(n, 25.0)]), degrees=True)
    los_enu = -enu / np.linalg.norm(enu, axis=1)[:, None]
    los_ned = np.column_stack([los_enu[:, 1], los_enu[:, 0], -los_enu[:, 2]])
    gim = Rotation.from_euler("ZYX", np.column_stack([np.degrees(np.arctan2(los_ned[:, 1], los_ned[:, 0])),
                                                      np.degrees(np.arcsin(-los_ned[:, 2])), np.zeros(n)]),
                              degrees=True)
    q = lambda R: R.as_quat(scalar_first=True)  # noqa: E731
    return SimpleNamespace(gps_t_ns=t, gps_lla=lla, att_t_ns=t, att_quat_wxyz=q(body), gimbal_t_ns=t,
                           gimbal_quat_wxyz=q(gim), laser_t_ns=t, laser_range_m=np.linalg.norm(enu, axis=1)), t


@pytest.mark.parametrize("convention", ["platform", "earth"])
def test_frame_centre_on_the_synth_st0601_writer(tmp_path, convention):
    from pipeline.geometry.geoid import geoid_undulation_m
    from pipeline.synth.writers.fmv import klv_packets

    tel, t = _synth_tel()
    n_geoid = float(geoid_undulation_m(47.3, 8.5))
    packets = klv_packets(tel, t, (640, 480, 800.0, 800.0), np.ones(t.size), n_geoid, sensor_angles=convention)
    p = tmp_path / "synth.klv"
    p.write_bytes(b"".join(packets))
    r = check_file(p)
    assert r.n == t.size and not r.horizontal_only
    if convention == "platform":  # as the standard writes them: only the encoding's rounding
        assert r.median_m < 30.0 and r.median_horizontal_m < 1.0 and r.explained_by is None
        assert r.verdict.startswith("consistent")
    else:  # earth-referenced angles in tags 18/19: hundreds of metres, and the convention named
        assert r.median_m > 200.0 and r.verdict.startswith("a convention error")
        assert r.explained_by.startswith("sensor angles earth-referenced") and r.alternatives[r.explained_by] < 1.0


def test_a_wrong_sensor_altitude_datum_is_named(tmp_path):
    """Tag 15 (MSL) holding ellipsoid heights and no tag 75: the sensor ~48 m (the geoid's N there) too high,
    and the datum named."""
    from pipeline.geometry.geoid import geoid_undulation_m
    from pipeline.synth.writers.fmv import klv_packets

    tel, t = _synth_tel(12)
    n_geoid = float(geoid_undulation_m(47.3, 8.5))
    packets = klv_packets(tel, t, (640, 480, 800.0, 800.0), np.ones(t.size), n_geoid)
    table, _ = read_klv_table(_write(tmp_path, packets))
    rows = [{k: table.cols[k][i] for k in table.cols if np.isfinite(table.cols[k][i]) and k != "alt_hae_m"}
            | {"t_us": int(table.t_us[i]), "alt_msl_m": table.cols["alt_hae_m"][i]} for i in range(table.n)]
    r = check_frame_centre(KlvTable(rows, list(table.t_ns), "unix", "x"))
    assert 30.0 < r.median_m < 100.0 and r.explained_by == "sensor altitude on the other datum (MSL <-> ellipsoid)"


def _write(tmp_path, packets) -> Path:
    p = tmp_path / "x.klv"
    p.write_bytes(b"".join(packets))
    return p


def test_scan_finds_sets_among_junk():
    sets = [eg0104_set([_item("03", TIME[0], f"{1_221_515_219_356_000 + k:016X}")]) for k in range(4)]
    rows, bad, cut = scan_packets(b"xx" + sets[0] + b"\x06\x0e" + sets[1] + sets[2] + sets[3][:-3], SET_KEY,
                                  decode_eg0104)
    assert [r["t_us"] - 1_221_515_219_356_000 for r in rows] == [0, 1, 2] and cut == 1 and bad == 0


@pytest.mark.parametrize("convention, code", [("platform", 0), ("earth", 1)])
def test_check_json_on_a_raw_klv_dump(tmp_path, convention, code):
    from pipeline.geometry.geoid import geoid_undulation_m
    from pipeline.synth.writers.fmv import klv_packets

    tel, t = _synth_tel(10)
    p = _write(tmp_path, klv_packets(tel, t, (640, 480, 800.0, 800.0), np.ones(t.size),
                                     float(geoid_undulation_m(47.3, 8.5)), sensor_angles=convention))
    out = subprocess.run([sys.executable, "-m", "pipeline", "check", str(p), "--json"], capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == code, out.stderr
    fc = json.loads(out.stdout)["frame_centre"]
    assert fc["n"] == 10 and fc["file"] == str(p)
    assert (fc["median_m"] < 1.0) if code == 0 else (fc["median_m"] > 200.0 and fc["p95_m"] >= fc["median_m"])
