"""The readers that take user files, as a table for fuzzing (tests/test_fuzz_readers.py, scripts/fuzz.py).

Each `Target` is a seed (a small valid input built by `make_seed(folder) -> path`) and a `read(path)` that goes
through the same code a user's command does. Fuzzing mutates the seed's bytes (or, for YAML/JSON documents,
its parsed tree) and checks the promise of docs/damaged_input.md: every input either reads (warnings allowed)
or raises a `RidgelocError` whose message is one line naming the file; any other exception is a failure.

To add a reader: write a `_seed_<name>` that builds a small valid file in the given folder (a few KB: fuzzing
speed is proportional to it) and add one `Target(...)` line to `TARGETS`. If the input is a folder (a ROS 2
bag), `make_seed` returns the file inside it to mutate; `read` is called with that file's path.
"""

from __future__ import annotations

import json
import math
import random
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import RidgelocError

ROOT = Path(__file__).resolve().parents[2]  # the checkout: seeds come from its sample data
SHARED = ROOT.parent / "shared"
T0_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class Target:
    """One reader: `make_seed(folder) -> path of the file to mutate`, `read(path)` raises RidgelocError or
    returns; `tree` is "json" or "yaml" for documents that also get structural (parsed-tree) mutations."""

    name: str
    make_seed: Callable[[Path], Path]
    read: Callable[[Path], object]
    tree: str | None = None


# ---- read functions: the user's code paths --------------------------------------------------------------

def _read_log(path: Path) -> None:
    """`ridgeloc inspect` (every stream timed, summary rendered) and `ridgeloc run`'s read of the same file."""
    from pipeline.ingest.dispatch import detect_format, read_file
    from pipeline.ingest.inspect import InspectResult, format_result, result_as_dict

    target = path.parent if (path.parent / "metadata.yaml").is_file() else path
    log = read_file(target, scan_all=True)
    result = InspectResult(str(target), detect_format(target), log)
    format_result(result)
    json.dumps(result_as_dict(result))
    read_file(target, scan_all=False)  # `run` reads fewer streams: a different path through some readers


def _read_video(path: Path) -> None:
    """The video reader (frame times from frames.csv or the container), decoding the first and last frame, and
    the container's creation time (`ridgeloc init`: None when absent or unreadable, never an error)."""
    from pipeline.ingest.video import VideoFrames, read_video
    from pipeline.ingest.video_time import creation_time_ns

    frames = read_video(path)
    with VideoFrames(path) as vf:
        vf.read([int(frames.index.min()), int(frames.index.max())])
    creation_time_ns(path)


def _read_frames_csv(path: Path) -> None:
    video = path.parent / "video.mp4"
    from pipeline.ingest.video import read_video

    read_video(video, frames_csv=path)


def _read_marks(path: Path) -> None:
    """A flight's marks file (a marks CSV or an ODM gcp_list.txt), as `marks_file:` reads it."""
    from pipeline.targets import read_marks_file

    read_marks_file(path)


def _seed_photo_marks(folder: Path) -> Path:
    """`ridgeloc locate --marks`: a photo and a marks CSV `photo,x_px,y_px` naming it."""
    _seed_photo(folder)
    path = folder / "marks.csv"
    path.write_text("photo,x_px,y_px\nDJI_0001.JPG,31.5,23.0\n")
    return path


def _read_photo_marks(path: Path) -> None:
    """The marks CSV of `ridgeloc locate --marks`, read against the photo beside it and checked in its image."""
    from pipeline.ingest.photo import read_photos
    from pipeline.locate import check_pixels, read_marks

    photos, _ = read_photos([path.parent / "DJI_0001.JPG"])
    check_pixels(photos, read_marks(str(path), photos))


def _read_flight_config(path: Path) -> None:
    from pipeline.flight_config import load_flight_config

    load_flight_config(path)


def _read_run_config(path: Path) -> None:
    from pipeline.flight_config import load_run_config

    load_run_config(path)


def _read_observations(path: Path) -> None:
    from pipeline.observation_file import load

    load(path)


# ---- seeds -------------------------------------------------------------------------------------------------

def _tlog_records(data: bytes, limit: int) -> bytes:
    """The leading whole records (8-byte time + MAVLink 1/2 packet) of a tlog, up to `limit` bytes."""
    from pipeline.ingest.tlog import _record_length

    pos = 0
    while (rec := _record_length(data, pos, len(data))) is not None and pos + 8 + rec[1] <= limit:
        pos += 8 + rec[1]
    return data[:pos]


def _seed_tlog(folder: Path) -> Path:
    path = folder / "flight.tlog"
    path.write_bytes(_tlog_records((ROOT / "sample_data" / "group6" / "flight.tlog").read_bytes(), 12_000))
    return path


def _seed_dataflash(folder: Path) -> Path:
    from support.writers import DataFlashWriter

    path = folder / "flight.bin"
    with DataFlashWriter(path) as w:
        w.fmt("GPS", "QBIHLLe", "TimeUS,Status,GMS,GWk,Lat,Lng,Alt")
        w.fmt("ATT", "QccC", "TimeUS,Roll,Pitch,Yaw")
        w.fmt("MNT", "Qfffff", "TimeUS,Roll,Pitch,YawB,YawE,Dist")
        w.fmt("RFND", "QBCBB", "TimeUS,Instance,Dist,Stat,Orient")
        for i in range(12):
            t_us = 1_000_000 + i * 200_000
            w.write("GPS", t_us, 1 if i == 0 else 3, 100_000 + i * 200, 2300, 473977419, 85455939, 48812)
            w.write("ATT", t_us + 10, 500, -250, 27000)
            w.write("MNT", t_us + 20, 0.0, -30.0, 15.0, 285.0, 1234.5 if i % 2 else 0.0)
            w.write("RFND", t_us + 30, 0, 1234 + i, 4 if i % 3 else 2, 25)
    return path


def _seed_dataflash_text(folder: Path) -> Path:
    from support.writers import dataflash_text_from_binary

    path = folder / "flight.log"
    dataflash_text_from_binary(_seed_dataflash(folder), path)
    return path


def _head(src: Path, folder: Path, name: str, limit: int) -> Path:
    path = folder / name
    with open(src, "rb") as f:
        path.write_bytes(f.read(limit))
    return path


def _seed_ulog(folder: Path) -> Path:
    return _head(SHARED / "logs" / "foxglove_mcap_test_ulog.ulg", folder, "flight.ulg", 48_000)


def _bag_rows(n: int = 6) -> list:
    from support.writers import ros_message

    rows = []
    s45 = math.sin(math.pi / 4)
    for i in range(n):
        t = T0_NS + i * 100_000_000
        rows.append(("/uav/gps/fix", t + 50, *ros_message("navsat", t, lat=47.0 + i * 1e-5, lon=8.5, alt=512.25)))
        rows.append(("/uav/imu", t + 51, *ros_message("imu", t + 1, q_xyzw=[0, 0, s45, s45])))
        rows.append(("/uav/gimbal/attitude", t + 52, *ros_message("quat", t + 2, q_xyzw=[0, 0.13, 0, 0.99])))
        rows.append(("/uav/laser/range", t + 53, *ros_message("range", t + 3, range=812.5 + i)))
    jpeg = _tiny_jpeg()
    rows.append(("/uav/camera/image/compressed", T0_NS + 54, *ros_message("compressed", T0_NS + 4, data=jpeg)))
    return rows


def _tiny_jpeg() -> bytes:
    import cv2
    import numpy as np

    img = np.zeros((16, 24, 3), np.uint8)
    img[4:12, 6:18] = 200
    return cv2.imencode(".jpg", img)[1].tobytes()


def _seed_ros1(folder: Path) -> Path:
    from support.writers import write_ros_bag

    path = folder / "flight.bag"
    write_ros_bag(path, _bag_rows(), "ros1")
    return path


def _seed_ros2(storage: str) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        from support.writers import write_ros_bag

        bag = folder / "flight_ros2"
        write_ros_bag(bag, _bag_rows(), storage)
        return next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))

    return make


def _seed_ros2_metadata(folder: Path) -> Path:
    return _seed_ros2("mcap")(folder).parent / "metadata.yaml"


def _seed_mcap(folder: Path) -> Path:
    from support.writers import write_json_mcap

    path = folder / "flight.mcap"
    msgs = {
        "/uav/gps": [{"t_ns": T0_NS + i * 10**8, "latitude_deg": 46.5 + i * 1e-6, "longitude_deg": 7.25,
                      "altitude_m": 1500.5, "altitude_datum": "ellipsoid"} for i in range(6)],
        "/uav/attitude": [{"t_ns": T0_NS + i * 10**8 + 1, "q_wxyz": [0.94, 0, 0, 0.34], "frame": "body_frd_to_ned"}
                          for i in range(6)],
        "/uav/gimbal": [{"t_ns": T0_NS + i * 10**8 + 2, "q_wxyz": [1, 0, 0, 0], "frame": "gimbal_frd_to_ned",
                         "yaw_in_vehicle_frame": False} for i in range(6)],
        "/uav/laser": [{"t_ns": T0_NS + i * 10**8 + 3, "range_m": 1234.5 if i % 3 else None, "valid": i % 3 != 0}
                       for i in range(6)],
    }
    write_json_mcap(path, msgs, chunk_size=2048)
    return path


def _seed_srt(folder: Path) -> Path:
    path = folder / "flight.SRT"
    path.write_bytes((SHARED / "srt" / "ruz76_DJI_M300RTK.SRT").read_bytes())
    return path


def _klv_packets(n: int) -> list[bytes]:
    """n ST 0601 packets 40 ms apart, encoded by the stanag4609 library (not by our reader's own code)."""
    from stanag4609 import st0601

    return [st0601.encode_uas_local_set({
        2: T0_NS // 1000 + k * 40_000, 65: 19, 5: 45.0 + k, 6: 1.5, 7: -2.0, 13: 47.0 + k * 1e-5, 14: 8.5,
        15: 1450.0, 75: 1500.0, 16: 20.0, 17: 15.0, 18: 10.0, 19: -30.0, 20: 0.0,
        **({21: 4000.0 + k} if k % 3 == 0 else {})}) for k in range(n)]


def _seed_klv_dump(folder: Path) -> Path:
    path = folder / "flight.klv"
    path.write_bytes(b"".join(_klv_packets(6)))
    return path


def _eg0104_sets(n: int) -> list[bytes]:
    """n MISB EG 0104 universal sets 40 ms apart: 16-byte item keys (EG 0104.5's table), BER lengths, IEEE 754
    big-endian values, as the KWIVER Fort A.P. Hill clips carry them (doubles for latitudes/longitudes)."""
    from support.writers import eg0104_set, klv_item

    def item(key_hex: str, value: bytes) -> bytes:
        return klv_item(bytes.fromhex(ul + key_hex), value)

    ul = "060E2B34010101"
    out = []
    for k in range(n):
        out.append(eg0104_set([
            item("030702010101050000", struct.pack(">Q", T0_NS // 1000 + k * 40_000)),
            item("010101200100000000", b"ABCD"),
            item("030701020102040200", struct.pack(">d", 38.25 + k * 1e-5)),
            item("030701020102060200", struct.pack(">d", -77.37)),
            item("010701020102020000", struct.pack(">f", 1054.4)),
            item("070701100104000000", struct.pack(">f", 1.8)),
            item("070701100105000000", struct.pack(">f", 1.1)),
            item("070701100106000000", struct.pack(">f", -102.8 + k)),
            item("020420020101080000", struct.pack(">f", 0.8)),
            item("0704200201010A0100", struct.pack(">f", 0.6)),
            item("010701080101000000", struct.pack(">f", 1730.0)),
            item("010701100102000000", struct.pack(">f", 124.5)),
            item("010701100103000000", struct.pack(">f", -37.5)),
            item("010701020103020000", struct.pack(">d", 38.2456)),
            item("010701020103040000", struct.pack(">d", -77.3537)),
            item("030701020103070100", struct.pack(">d", 38.2456))]))
    return out


def _seed_eg0104_dump(folder: Path) -> Path:
    path = folder / "eg0104.klv"
    path.write_bytes(b"".join(_eg0104_sets(5)))
    return path


def _read_klv_checked(path: Path) -> None:
    """`ridgeloc inspect` of a raw KLV dump, then `ridgeloc check FILE`'s frame-centre check of it."""
    from pipeline.ingest.frame_centre import check_file

    _read_log(path)
    r = check_file(path)
    if r is not None:
        json.dumps(r.to_dict())


def _fmv(folder: Path, name: str, packets: list[bytes]) -> Path:
    """A 6-frame 32x24 H.264 MPEG-TS whose KLV data stream carries `packets` (one per frame), ~6 KB."""
    import numpy as np

    from pipeline.synth.writers.fmv import write_fmv

    path = folder / name
    frames = []
    for i in range(6):
        img = np.zeros((24, 32, 3), np.uint8)
        img[4:20, 2 + i:10 + i] = 255
        frames.append(img)
    pts = np.arange(6, dtype=np.int64) * 40_000_000 + 1_000_000_000
    write_fmv(path, frames, pts, list(zip(pts.tolist(), packets, strict=True)), 25, (32, 24), preset="ultrafast")
    return path


def _seed_fmv(folder: Path) -> Path:
    """An MPEG-TS with ST 0601 packets (the synth's MISB writer)."""
    return _fmv(folder, "flight.ts", _klv_packets(6))


def _seed_fmv_eg0104(folder: Path) -> Path:
    """An MPEG-TS whose KLV stream carries EG 0104 sets, as the KWIVER Fort A.P. Hill clips do."""
    return _fmv(folder, "eg0104.ts", _eg0104_sets(6))


def _seed_video(folder: Path) -> Path:
    import cv2
    import numpy as np

    path = folder / "video.mp4"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (32, 24))
    for i in range(6):
        img = np.zeros((24, 32, 3), np.uint8)
        img[4:20, 2 + i:10 + i] = 255
        w.write(img)
    w.release()
    return path


def _seed_frames_csv(folder: Path) -> Path:
    _seed_video(folder)
    path = folder / "video.frames.csv"
    path.write_text("frame_index,pts_ns\n" + "".join(f"{i},{5_560_000_000 + i * 40_000_000}\n" for i in range(6)))
    return path


def _seed_marks_csv(folder: Path) -> Path:
    (folder / "chip.jpg").write_bytes(_tiny_jpeg())
    path = folder / "marks.csv"
    path.write_text("name,frame_or_image,x_px,y_px\npanel,4,301.5,198.0\npanel,9,310.0,190.5\n"
                    "pole_1,chip.jpg,12.0,8.5\n")
    return path


def _seed_truth_file(folder: Path) -> Path:
    """A flight's `truth_file`: the truth.json keys ridgeloc reads (target, named targets), and others it does not."""
    path = folder / "truth.json"
    path.write_text(json.dumps({
        "format_version": 1, "target": {"lat_deg": 34.36, "lon_deg": 108.76, "alt_m": 372.0, "size_m": 36.0},
        "targets": [{"name": "panel", "lat_deg": 34.36, "lon_deg": 108.76, "alt_m": 372.0},
                    {"name": "pole_1", "lat_deg": 34.3588, "lon_deg": 108.7641, "alt_m": 372.01,
                     "mark": {"frame_index": 4}}]},
        indent=1))
    return path


def _read_truth_file(path: Path) -> None:
    """`truth_file:` as a flight config's load reads it."""
    from pipeline.targets import read_truth_file

    read_truth_file(path)


def _seed_gcp_list(folder: Path) -> Path:
    path = folder / "gcp_list.txt"
    path.write_text("EPSG:4326\n112.9390 28.2284 61.5 301.5 198.0 4 panel\n112.9391 28.2285 60.0 120.0 80.5 9 pole_1\n"
                    "112.9390 28.2284 61.5 310.0 190.5 9 panel\n")
    return path


def _seed_flight_config(folder: Path) -> Path:
    import yaml

    doc = yaml.safe_load((ROOT / "configs" / "flights" / "group6.yaml").read_text())
    base = ROOT / "configs" / "flights"
    doc["files"] = {k: ([str((base / p).resolve()) for p in v] if isinstance(v, list) else str((base / v).resolve()))
                    for k, v in doc["files"].items()}
    doc["truth_file"] = str((base / doc["truth_file"]).resolve())
    path = folder / "flight.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _seed_run_config(folder: Path) -> Path:
    flight = _seed_flight_config(folder)
    path = folder / "run.yaml"
    path.write_text(f"description: fuzz seed\ngroups:\n  - {flight.name}\n")
    return path


def _seed_observations(folder: Path) -> Path:
    doc = json.loads((ROOT / "configs" / "example_observations.json").read_text())
    doc["observations"] = doc["observations"][:4]
    doc["observations"][1]["pixel"] = None
    doc["observations"][2]["range_m"] = None
    path = folder / "obs.json"
    path.write_text(json.dumps(doc, indent=1))
    return path


def _seed_photo(folder: Path) -> Path:
    """A 64x48 DJI-style photo with laser (EXIF GPS + drone-dji XMP), ~3 KB."""
    import numpy as np

    from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo

    flight = simulate_photo_flight(PhotoFlightSpec(seed=1, n_photos=1, width_px=64, height_px=48, fx_px=110.0))
    return write_photo(folder / "DJI_0001.JPG", flight.tags[0], np.random.default_rng(0))


def _read_photo(path: Path) -> None:
    """`ridgeloc inspect PHOTO` and the first step of `ridgeloc locate PHOTO`: the reader, the pose chain and the
    observations (the solvers have their own target: observations)."""
    from pipeline.ingest.photo import read_photo_checked
    from pipeline.ingest.photo_views import photo_views
    from pipeline.locate import photo_observations

    photo = read_photo_checked(path)
    if photo.intrinsics is not None:
        photo_observations(photo_views([photo]))



def _seed_maker_photo(maker: str):
    """A 64x48 photo with `maker`'s pose tags (support.maker_photos: Skydio, Parrot, Pix4D Camera:, Teal), ~3 KB."""

    def seed(folder: Path) -> Path:
        from support.maker_photos import write_maker_photo

        return write_maker_photo(folder / "P0001.jpg", maker, yaw=120.0, pitch=-35.0, roll=1.5,
                                 platform=(300.0, -3.0, -1.0), exif_extra={40962: 64, 40963: 48})
    return seed


def _read_maker_photo(path: Path) -> None:
    """`ridgeloc inspect PHOTO` (text and JSON) and `ridgeloc locate PHOTO --ground-height-m H`: the makers'
    readers, the pose chain and the level-ground answer with its covariance."""
    from pipeline.errors import RidgelocError
    from pipeline.ingest.photo import read_photo_checked
    from pipeline.ingest.photo_inspect import format_photo, photo_as_dict
    from pipeline.locate import GroundAssumption, locate_photos

    photo = read_photo_checked(path)
    format_photo(photo)
    json.dumps(photo_as_dict(photo))
    if photo.intrinsics is not None:
        try:
            locate_photos([photo], methods=["ground"], ground=GroundAssumption("height", photo.alt_m - 50.0))
        except RidgelocError:
            pass  # a refusal in one line is an answer (check() tests the message of what read_photo raises)


def _seed_dem(folder: Path) -> Path:
    """A 12 x 12 int16 GeoTIFF DEM (EPSG:4326, EGM2008 heights, deflate, nodata -32768), ~1 KB."""
    from pipeline.synth.dem import Hills, write_dem

    return write_dem(folder / "dem.tif", Hills(46.5, 7.5, base_m=600.0), extent_m=330.0, post_m=30.0,
                     crs="EPSG:4326+3855", dtype="int16", nodata=-32768, compress="deflate")


def _read_dem(path: Path) -> None:
    """`ridgeloc locate --dem` and a flight's `terrain.dem`: open, a height, the terrain function, a ray cast."""
    import numpy as np

    from pipeline.errors import GeometryError
    from pipeline.terrain import Dem

    dem = Dem.open(path)
    lat = (dem.bounds_deg[0] + dem.bounds_deg[1]) / 2
    lon = (dem.bounds_deg[2] + dem.bounds_deg[3]) / 2
    dem.height_wgs84_m(lat, lon)
    with np.errstate(invalid="ignore"):
        dem.local(lat, lon, dem.h_max_m)(np.array([0.0, 30.0]), np.array([0.0, -30.0]))
    try:
        dem.intersect((lat, lon, dem.h_max_m + 100.0), (0.3, 0.2, -1.0), label="fuzz pixel (0, 0)")
    except GeometryError as exc:
        if str(path) not in str(exc):
            raise AssertionError(f"a ray error does not name the DEM: {exc}") from None


def _seed_cot(folder: Path) -> Path:
    """A CoT event file as `ridgeloc run` writes it (OUT/cot/<target>.cot), ~1 KB."""
    from datetime import datetime, timezone

    from pipeline.tak.cot import CotTarget, event_xml

    target = CotTarget("ridgeloc-fuzz", "panel", 34.36, 108.76, 391.1, 9.7, 15.0, "ridgeloc mle\nMGRS 49S BU",
                       {"method": "mle", "ce90_m": "9.7"})
    path = folder / "panel.cot"
    path.write_bytes(event_xml(target, datetime(2026, 1, 1, tzinfo=timezone.utc)))
    return path


def _read_cot(path: Path) -> None:
    """`ridgeloc send`: the event read and re-stamped, then encoded as sent (XML, and protobuf by takproto)."""
    from pipeline.commands.send import load_events
    from pipeline.tak.send import encode, parse_destination

    for event in load_events([path], None, None):
        for url in ("udp://127.0.0.1:6969", "tcp://127.0.0.1:8087"):
            encode(event, parse_destination(url), protobuf=True)


TARGETS: tuple[Target, ...] = (
    Target("tlog", _seed_tlog, _read_log),
    Target("dataflash-bin", _seed_dataflash, _read_log),
    Target("dataflash-text", _seed_dataflash_text, _read_log),
    Target("ulog", _seed_ulog, _read_log),
    Target("ros1-bag", _seed_ros1, _read_log),
    Target("ros2-sqlite3", _seed_ros2("sqlite3"), _read_log),
    Target("ros2-mcap", _seed_ros2("mcap"), _read_log),
    Target("ros2-metadata", _seed_ros2_metadata, _read_log, tree="yaml"),
    Target("mcap", _seed_mcap, _read_log),
    Target("srt", _seed_srt, _read_log),
    Target("klv-dump", _seed_klv_dump, _read_log),
    Target("fmv-ts", _seed_fmv, _read_log),
    Target("eg0104-dump", _seed_eg0104_dump, _read_klv_checked),
    Target("fmv-eg0104-ts", _seed_fmv_eg0104, _read_klv_checked),
    Target("video", _seed_video, _read_video),
    Target("frames-csv", _seed_frames_csv, _read_frames_csv),
    Target("marks-csv", _seed_marks_csv, _read_marks),
    Target("gcp-list", _seed_gcp_list, _read_marks),
    Target("photo-marks", _seed_photo_marks, _read_photo_marks),
    Target("truth-file", _seed_truth_file, _read_truth_file, tree="json"),
    Target("flight-config", _seed_flight_config, _read_flight_config, tree="yaml"),
    Target("run-config", _seed_run_config, _read_run_config, tree="yaml"),
    Target("observations", _seed_observations, _read_observations, tree="json"),
    Target("photo", _seed_photo, _read_photo),
    Target("photo-skydio", _seed_maker_photo("skydio"), _read_maker_photo),
    Target("photo-parrot", _seed_maker_photo("parrot"), _read_maker_photo),
    Target("photo-pix4d", _seed_maker_photo("parrot-disco"), _read_maker_photo),
    Target("photo-teal", _seed_maker_photo("teal"), _read_maker_photo),
    Target("dem", _seed_dem, _read_dem),
    Target("cot-event", _seed_cot, _read_cot),
)
BY_NAME = {t.name: t for t in TARGETS}


# ---- mutations ----------------------------------------------------------------------------------------------

HUGE = (b"\xff\xff\xff\xff", b"\xff\xff\xff\x7f", b"\x7f\xff\xff\xff", b"\x00\x00\x00\x80", b"\x00\x00\x00\x00",
        b"\xff\xff\xff\xff\xff\xff\xff\xff", b"\xff\xff\xff\xff\xff\xff\xff\x7f")
BYTE_OPS = ("truncate", "bitflip", "overwrite", "huge_length", "insert", "delete", "duplicate", "magic_random")


def mutate_bytes(data: bytes, rng: random.Random, n_ops: int | None = None) -> tuple[bytes, list[str]]:
    """1-3 random byte-level damages of `data` (truncation at every length class, bit flips, overwrites, huge
    declared lengths, inserted/deleted/duplicated runs, random bytes after the right magic). Returns the bytes
    and a description of what was done."""
    done = []
    buf = bytearray(data)
    for _ in range(n_ops or rng.choice((1, 1, 2, 3))):
        op = rng.choice(BYTE_OPS)
        n = len(buf)
        at = rng.randrange(n) if n else 0
        if op == "truncate":
            cls = rng.choice(("zero", "tiny", "header", "fraction", "minus"))
            keep = {"zero": 0, "tiny": rng.randrange(1, 9), "header": rng.randrange(8, 256),
                    "fraction": int(n * rng.random()), "minus": max(0, n - rng.randrange(1, 16))}[cls]
            del buf[min(keep, n):]
            done.append(f"truncate to {min(keep, n)} ({cls})")
        elif op == "bitflip" and n:
            for _ in range(rng.choice((1, 1, 2, 8))):
                i = rng.randrange(n)
                buf[i] ^= 1 << rng.randrange(8)
            done.append(f"bitflip near {at}")
        elif op == "overwrite" and n:
            k = rng.randrange(1, 9)
            buf[at:at + k] = bytes(rng.randrange(256) for _ in range(k))[: max(0, n - at)]
            done.append(f"overwrite {k} at {at}")
        elif op == "huge_length" and n:
            v = rng.choice((*HUGE, struct.pack("<I", rng.randrange(2**32))))
            buf[at:at + len(v)] = v[: max(0, n - at)]
            done.append(f"huge length {v.hex()} at {at}")
        elif op == "insert":
            k = rng.choice((1, 4, 64, 1024))
            buf[at:at] = bytes(rng.randrange(256) for _ in range(k))
            done.append(f"insert {k} at {at}")
        elif op == "delete" and n:
            k = rng.choice((1, 4, 64, 1024))
            del buf[at:at + k]
            done.append(f"delete {k} at {at}")
        elif op == "duplicate" and n:
            k = rng.choice((8, 64, 512))
            buf[at:at] = buf[at:at + k]
            done.append(f"duplicate {k} at {at}")
        elif op == "magic_random":
            keep = min(n, rng.choice((2, 4, 8, 13, 16)))
            buf = bytearray(buf[:keep] + bytes(rng.randrange(256) for _ in range(rng.choice((0, 16, 256, 4096)))))
            done.append(f"magic {keep} + random")
    return bytes(buf), done


WRONG_VALUES = (None, True, -1, 0, 2**63, 1e308, -1e-300, "x", "", [], {}, [1, 2], {"a": 1}, "nan", ".inf",
                [[[[[[[[[[[]]]]]]]]]]], "../../../../etc/passwd", "/nonexistent/file.tlog")


def mutate_tree(text: str, kind: str, rng: random.Random) -> tuple[str, list[str]]:
    """Replace, delete or add a node of a parsed JSON/YAML document with a wrong-typed or extreme value."""
    import yaml

    doc = json.loads(text) if kind == "json" else yaml.safe_load(text)
    nodes = []  # (container, key) pairs

    def walk(v):
        if isinstance(v, dict):
            for k in list(v):
                nodes.append((v, k))
                walk(v[k])
        elif isinstance(v, list):
            for i in range(len(v)):
                nodes.append((v, i))
                walk(v[i])

    walk(doc)
    done = []
    for _ in range(rng.choice((1, 1, 2))):
        if not nodes:
            break
        container, key = rng.choice(nodes)
        action = rng.choice(("replace", "replace", "delete", "add"))
        try:
            if action == "replace":
                value = rng.choice(WRONG_VALUES)
                container[key] = value
                done.append(f"{key!r} = {value!r}")
            elif action == "delete":
                del container[key]
                done.append(f"delete {key!r}")
            elif isinstance(container, dict):
                container["unknown_" + str(rng.randrange(99))] = 1
                done.append("add unknown key")
        except (IndexError, KeyError):
            pass
    if kind == "json":
        out = json.dumps(doc, allow_nan=True)
        if rng.random() < 0.2:  # non-finite tokens are not JSON but json.dumps writes them
            out = out.replace("1e+308", rng.choice(("NaN", "Infinity", "-Infinity", "1e999")), 1)
        return out, done
    return yaml.safe_dump(doc, sort_keys=False), done


def mutate(target: Target, seed: bytes, rng: random.Random) -> tuple[bytes, list[str]]:
    """A damaged variant of `seed`: byte-level, or for documents a structural change half of the time."""
    if target.tree and rng.random() < 0.5:
        text, done = mutate_tree(seed.decode(), target.tree, rng)
        return text.encode(), done
    return mutate_bytes(seed, rng)


# ---- the check ------------------------------------------------------------------------------------------------

def check(target: Target, path: Path) -> str | None:
    """Run `target.read(path)`. None if it read or refused properly; otherwise what was wrong (a traceback summary
    or a badly formed error message)."""
    try:
        target.read(path)
    except RidgelocError as exc:
        msg = str(exc)
        if "\n" in msg.strip():
            return f"multi-line error: {msg[:300]!r}"
        names = {path.name, path.parent.name, str(path.parent)}
        if not any(n and n in msg for n in names):
            return f"error does not name the file: {msg[:300]!r}"
        return None
    except RecursionError:
        return "RecursionError"
    except Exception as exc:  # anything else reaching the user is a traceback
        import traceback

        tb = traceback.extract_tb(exc.__traceback__)
        where = next((f"{Path(f.filename).name}:{f.lineno}" for f in reversed(tb) if "pipeline" in f.filename),
                     f"{Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else "?")
        return f"{type(exc).__name__} at {where}: {str(exc).splitlines()[0][:200] if str(exc) else ''}"
    return None
