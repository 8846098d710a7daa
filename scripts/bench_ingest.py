"""Ingest throughput and peak memory per reader, next to the underlying library's raw iteration in the same run.

    python scripts/bench_ingest.py [--messages 1200000] [--only tlog,mcap,ros2,dflog,srt,klv,real] [--out FILE]

Generates (in a temp dir) a MAVLink 2 .tlog with >= 1 M messages (position 10 Hz, attitude 50 Hz, gimbal 50 Hz,
laser 10 Hz, SYSTEM_TIME 1 Hz, and 16 other common message types that our reader only counts), a plain MCAP
with JSON channels, a ROS 2 bag (MCAP storage) of the synthetic-flight layout, a text DataFlash log (.log, GPS
10 Hz, ATT/MNT 50 Hz, RFND 10 Hz, IMU/BARO 50 Hz only counted) and a DJI SRT of a 30 fps video in the Mavic 3
layout (focal length and zoom changing), a STANAG 4609 MPEG-TS (tiny H.264 frames, one MISB ST 0601 Local Set per
frame, by pipeline.synth.writers.fmv) and the same packets as a raw .klv dump, then times each in a fresh
subprocess (peak RSS = VmHWM, reset through /proc/self/clear_refs after all imports, minus the RSS then) for:
- ours:  pipeline.ingest.read_flight (full conversion into the model);
- raw:   the library alone: pymavlink mavutil recv_msg() over every message, mcap iter_messages + json.loads,
         rosbags AnyReader.messages + deserialize, DFReader recv_msg (binary and text), pyulog ULog(...),
         srt.parse (cues only: the library that splits our SRT cues, without the telemetry in them), PyAV demux
         of the .ts data stream / stanag4609 iter_klv over the .klv, each packet decoded by stanag4609's
         st0601.decode_uas_local_set (checksum verified);
and the same on every file in ../shared/logs and ../shared/srt, and on ../shared/logs' .BIN converted to text.
msgs/s = messages in the file / wall time. Each child first runs
its reader once on a small file of the same format (untimed), so one-time costs (type stores, generated
deserializers, first calls into numpy/scipy) are left out on both sides.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LOGS = REPO / ".." / "shared" / "logs"
SRTS = REPO / ".." / "shared" / "srt"
T0_NS = 1_700_000_000 * 10**9


def gen_tlog(path: Path, n_target: int) -> int:
    """A tlog with about n_target messages at realistic relative rates. Each message type cycles through 500
    distinct pre-packed packets (varying payload and sequence numbers), so writing stays fast."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink.dialects.v20 import ardupilotmega as ml

    mav = ml.MAVLink(None, srcSystem=1, srcComponent=1)

    def variants(make, k=500):
        return [make(i).pack(mav) for i in range(k)]

    nan = float("nan")
    per_s = {  # rate Hz, packets
        "pos": (10, variants(lambda i: ml.MAVLink_global_position_int_message(
            i, 473977419 + i, 85455939 - i, 500000 + i, 100000, 1, 2, 3, 9000))),
        "att": (50, variants(lambda i: ml.MAVLink_attitude_message(i, 0.01 * i, 0.02, 1.0 + 0.001 * i, 0, 0, 0))),
        "gim": (50, variants(lambda i: ml.MAVLink_gimbal_device_attitude_status_message(
            0, 0, i, 64, [math.cos(0.001 * i), 0.0, math.sin(0.001 * i), 0.0], nan, nan, nan, 0, 0.0, nan, 0))),
        "rng": (10, variants(lambda i: ml.MAVLink_camera_tracking_geo_status_message(
            1, 0, 0, nan, nan, nan, nan, nan, nan, nan, 1000.0 + i, nan, nan))),
        "sys": (1, variants(lambda i: ml.MAVLink_system_time_message(T0_NS // 1000 + i * 10**6, i * 1000))),
    }
    others = [
        lambda i: ml.MAVLink_vfr_hud_message(20.0, 20.0, 90, 50, 500.0, 0.1),
        lambda i: ml.MAVLink_raw_imu_message(i, 1, 2, 3, 4, 5, 6, 7, 8, 9),
        lambda i: ml.MAVLink_scaled_imu2_message(i, 1, 2, 3, 4, 5, 6, 7, 8, 9),
        lambda i: ml.MAVLink_sys_status_message(1, 1, 1, 500, 12000, 100, 90, 0, 0, 0, 0, 0, 0),
        lambda i: ml.MAVLink_gps_raw_int_message(i, 3, 473977419, 85455939, 500000, 100, 100, 10, 9000, 12),
        lambda i: ml.MAVLink_local_position_ned_message(i, 1.0, 2.0, -3.0, 0.1, 0.2, 0.3),
        lambda i: ml.MAVLink_servo_output_raw_message(i, 0, 1500, 1500, 1500, 1500, 1500, 1500, 1500, 1500),
        lambda i: ml.MAVLink_rc_channels_message(i, 8, *([1500] * 18), 255),
        lambda i: ml.MAVLink_nav_controller_output_message(0.1, 0.2, 90, 90, 100, 0.5, 0.1, 0.1),
        lambda i: ml.MAVLink_scaled_pressure_message(i, 1013.0, 0.1, 2000),
        lambda i: ml.MAVLink_ahrs2_message(0.1, 0.2, 0.3, 500.0, 473977419, 85455939),
        lambda i: ml.MAVLink_vibration_message(i, 0.1, 0.1, 0.1, 0, 0, 0),
        lambda i: ml.MAVLink_wind_message(90.0, 3.0, 0.1),
        lambda i: ml.MAVLink_mission_current_message(3),
        lambda i: ml.MAVLink_ekf_status_report_message(0, 0.1, 0.1, 0.1, 0.1, 0.1),
        lambda i: ml.MAVLink_terrain_report_message(473977419, 85455939, 0, 100.0, 80.0, 0, 0),
    ]
    for k, make in enumerate(others):
        per_s[f"o{k}"] = (20, variants(make, 50))
    hz_total = sum(r for r, _ in per_s.values())
    seconds = math.ceil(n_target / hz_total)
    count = 0
    pack_t = struct.Struct(">Q").pack
    with open(path, "wb") as f:
        buf = []
        for s in range(seconds):
            for _name, (rate, pkts) in per_s.items():
                for j in range(rate):
                    t_us = (T0_NS // 1000) + s * 10**6 + (j * 10**6) // rate
                    buf.append(pack_t(t_us) + pkts[(s * rate + j) % len(pkts)])
                    count += 1
            if len(buf) > 50_000:
                f.write(b"".join(buf))
                buf.clear()
        f.write(b"".join(buf))
    return count


def gen_mcap(path: Path, n_target: int) -> int:
    """Plain MCAP, JSON channels /uav/gps 10 Hz, /uav/attitude 50 Hz, /uav/gimbal 50 Hz, /uav/laser 10 Hz."""
    from mcap.writer import CompressionType, Writer

    rates = {"/uav/gps": 10, "/uav/attitude": 50, "/uav/gimbal": 50, "/uav/laser": 10}
    seconds = math.ceil(n_target / sum(rates.values()))
    n = 0
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start()
        ch = {}
        for topic in rates:
            sid = w.register_schema(name=topic, encoding="jsonschema", data=b'{"type": "object"}')
            ch[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        for s in range(seconds):
            for topic, rate in rates.items():
                for j in range(rate):
                    t = T0_NS + s * 10**9 + j * 10**9 // rate
                    if topic == "/uav/gps":
                        d = {"t_ns": t, "latitude_deg": 47.0 + s * 1e-6, "longitude_deg": 8.5, "altitude_m": 600.0,
                             "altitude_datum": "ellipsoid"}
                    elif topic == "/uav/laser":
                        d = {"t_ns": t, "range_m": 1000.0 + j, "valid": True}
                    else:
                        d = {"t_ns": t, "q_wxyz": [1.0, 0.0, 0.0, 0.0],
                             "frame": "body_frd_to_ned" if topic == "/uav/attitude" else "gimbal_frd_to_ned"}
                    w.add_message(ch[topic], log_time=t, publish_time=t, data=json.dumps(d).encode())
                    n += 1
        w.finish()
    return n


def gen_ros2(path: Path, n_target: int) -> int:
    """ROS 2 bag (MCAP storage): NavSatFix 10 Hz, Imu 50 Hz, QuaternionStamped 50 Hz, Range 10 Hz."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    sys.path.insert(0, str(REPO / "tests"))
    from support.writers import ros_message

    ts = get_typestore(Stores.ROS2_HUMBLE)
    kinds = {"/uav/gps/fix": (10, "navsat"), "/uav/imu": (50, "imu"), "/uav/gimbal/attitude": (50, "quat"),
             "/uav/laser/range": (10, "range")}
    args = {"navsat": {"lat": 47.0, "lon": 8.5, "alt": 600.0}, "imu": {"q_xyzw": [0, 0, 0, 1]},
            "quat": {"q_xyzw": [0, 0, 0, 1]}, "range": {"range": 1000.0}}
    # serialize one message per topic and patch its stamp bytes (CDR: 4-byte header, then sec int32, nanosec
    # uint32): the bag then holds distinct, valid messages without a million Python message constructions
    templates = {}
    for topic, (_, kind) in kinds.items():
        ty, msg = ros_message(kind, T0_NS, **args[kind])
        templates[topic] = (ty, bytearray(ts.serialize_cdr(msg, ty)))
    seconds = math.ceil(n_target / sum(r for r, _ in kinds.values()))
    n = 0
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {topic: w.add_connection(topic, templates[topic][0], typestore=ts) for topic in kinds}
        for s in range(seconds):
            for topic, (rate, _) in kinds.items():
                raw = templates[topic][1]
                for j in range(rate):
                    t = T0_NS + s * 10**9 + j * 10**9 // rate
                    struct.pack_into("<iI", raw, 4, t // 10**9, t % 10**9)
                    w.write(conns[topic], t, bytes(raw))
                    n += 1
    return n


def gen_dataflash_text(path: Path, n_target: int) -> int:
    """Text DataFlash (Mission Planner's conversion layout) with modern TimeUS records."""
    fmts = ["FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns",
            "FMT, 130, 46, GPS, QBIHBcLLefffB, TimeUS,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,U",
            "FMT, 131, 27, ATT, QccccCCCC, TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw",
            "FMT, 132, 43, MNT, Qffffffff, TimeUS,DRoll,Roll,DPitch,Pitch,DYawB,YawB,DYawE,YawE",
            "FMT, 133, 12, RFND, QBCBB, TimeUS,Instance,Dist,Stat,Orient",
            "FMT, 134, 53, IMU, QffffffIIfBBHH, TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
            "FMT, 135, 37, BARO, QffcfIff, TimeUS,Alt,Press,Temp,CRt,SMS,Offset,GndTemp"]
    seconds = math.ceil(n_target / (10 + 50 * 4 + 10))
    n = 0
    with open(path, "w") as f:
        f.write("\n".join(fmts) + "\n")
        for s in range(seconds):
            lines = []
            for j in range(50):
                t = 60_000_000 + s * 1_000_000 + j * 20_000
                if j % 5 == 0:
                    lines.append(f"GPS, {t}, 3, {100_000_000 + s * 1000 + j * 20}, 2300, 12, 0.7, "
                                 f"{47.3977419 + s * 1e-6:.7f}, 8.5455939, 488.12, 5.0, 90.0, 0.1, 1")
                    lines.append(f"RFND, {t + 5}, 0, {1234.5 + j:.2f}, 4, 0")
                lines.append(f"ATT, {t + 1}, 0.0, 5.0, 0.0, -2.5, 0.0, {j * 7.2:.2f}, 0.1, 0.0")
                lines.append(f"MNT, {t + 2}, 0.0, 0.0, -30.0, -30.0, 15.0, 15.0, 285.0, 285.0")
                lines.append(f"IMU, {t + 3}, 0.001, 0.002, 0.003, 0.1, 0.2, -9.8, 0, 0, 45.0, 1, 1, 400, 400")
                lines.append(f"BARO, {t + 4}, 12.5, 101300.0, 25.0, 0.1, {t // 1000}, 0.0, 25.0")
            n += len(lines)
            f.write("\n".join(lines) + "\n")
    return n


def gen_srt(path: Path, n_cues: int) -> int:
    """DJI SRT, Mavic 3 layout, 30 fps, with the focal length and digital zoom changing every 10 s."""
    with open(path, "w") as f:
        for i in range(n_cues):
            t0, t1 = i * 1000 // 30, (i + 1) * 1000 // 30
            ts = [f"{t // 3_600_000:02d}:{t // 60_000 % 60:02d}:{t // 1000 % 60:02d},{t % 1000:03d}" for t in (t0, t1)]
            zoom = 1 + (i // 300) % 4
            f.write(f"{i + 1}\n{ts[0]} --> {ts[1]}\n<font size=\"28\">FrameCnt: {i + 1}, DiffTime: 33ms\n"
                    f"2023-01-14 12:{51 + t0 // 60_000 % 8}:{t0 // 1000 % 60:02d}.{t0 % 1000:03d}\n"
                    f"[iso: 100] [shutter: 1/1600.0] [fnum: 1.7] [ev: 0] [focal_len: 24.00] [dzoom_ratio: {zoom}.00] "
                    f"[latitude: {45.4631 + i * 1e-6:.6f}] [longitude: {9.1882 + i * 1e-6:.6f}] "
                    f"[rel_alt: {50 + i * 1e-3:.3f} abs_alt: {180 + i * 1e-3:.3f}] "
                    f"[gb_yaw: {i % 360 - 180:.1f} gb_pitch: -30.0 gb_roll: 0.0]</font>\n\n")
    return n_cues


def gen_klv(path: Path, n_packets: int) -> int:
    """A STANAG 4609 MPEG-TS (`.ts`: 64x48 H.264 frames at 30 fps, one ST 0601 Local Set per frame with a laser
    range every 30th, written by the synth's FMV writer) or, for a `.klv` path, the same packets as a raw dump."""
    import types

    import numpy as np
    from scipy.spatial.transform import Rotation

    from pipeline.synth.writers.fmv import klv_packets, write_fmv

    t = T0_NS + np.arange(n_packets, dtype=np.int64) * 10**9 // 30
    s = (t - T0_NS) / 1e9
    q_body = Rotation.from_euler("ZYX", np.column_stack([s % 360, 2 + 0 * s, 1 + 0 * s]), degrees=True)
    q_gim = q_body * Rotation.from_euler("ZYX", [[30.0, -20.0, 0.0]] * n_packets, degrees=True)
    tel = types.SimpleNamespace(
        gps_t_ns=t, gps_lla=np.column_stack([45.0 + s * 1e-5, 9.0 + s * 1e-5, 500.0 + 0 * s]),
        att_t_ns=t, att_quat_wxyz=q_body.as_quat(scalar_first=True),
        gimbal_t_ns=t, gimbal_quat_wxyz=q_gim.as_quat(scalar_first=True),
        laser_t_ns=t[::30], laser_range_m=1500.0 + s[::30])
    zoom = 1.0 + (np.arange(n_packets) // 300) % 4
    packets = klv_packets(tel, t, (64, 48, 60.0, 60.0), zoom, geoid_separation_m=47.0)
    if path.suffix == ".klv":
        path.write_bytes(b"".join(packets))
        return n_packets
    pts = t - T0_NS
    frame = np.full((48, 64, 3), 128, np.uint8)
    write_fmv(path, (frame for _ in range(n_packets)), pts, list(zip(pts.tolist(), packets, strict=True)), 30,
              (64, 48), preset="ultrafast")
    return n_packets


CHILD = r'''
import json, sys, time
sys.path.insert(0, {repo!r})
kind, path, warm_path = sys.argv[1], sys.argv[2], sys.argv[3]
import pipeline.ingest, pymavlink.mavutil, pymavlink.DFReader, mcap.reader, rosbags.highlevel, pyulog, numpy, scipy, srt
import pipeline.ingest.tlog, pipeline.ingest.ulog, pipeline.ingest.dataflash, pipeline.ingest.rosbag
import pipeline.ingest.mcap_plain, pipeline.ingest.srt, pipeline.ingest.video, mcap_ros2.decoder
import pipeline.ingest.klv, av, stanag4609.st0601
from rosbags.typesys import Stores, get_typestore
for fmt in pipeline.ingest.mapping.FORMATS:
    pipeline.ingest.mapping_for(fmt)  # imports and package data loaded before timing, for both sides

def status_kib(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1])

def run(path):
    n = 0
    if kind == "ours":
        pipeline.ingest.read_flight([path])
    elif kind == "raw-tlog":
        m = pymavlink.mavutil.mavlink_connection(path, dialect="ardupilotmega")
        while m.recv_msg() is not None:
            n += 1
    elif kind == "raw-dataflash":
        r = pymavlink.DFReader.DFReader_binary(path, zero_time_base=True)
        while r.recv_msg() is not None:
            n += 1
    elif kind == "raw-dataflash-text":
        r = pymavlink.DFReader.DFReader_text(path, zero_time_base=True)
        while r.recv_msg() is not None:
            n += 1
    elif kind == "raw-srt":
        import srt
        with open(path, encoding="utf-8", errors="replace") as f:
            n = sum(1 for _ in srt.parse(f.read(), ignore_errors=True))
    elif kind == "raw-klv-ts":  # PyAV demux of the data stream + stanag4609 decode of each packet
        import av
        from stanag4609 import st0601
        with av.open(path) as c:
            for pkt in c.demux(c.streams.data[0]):
                if pkt.size:
                    st0601.decode_uas_local_set(bytes(pkt), verify_checksum=True, require_version=False)
                    n += 1
    elif kind == "raw-klv":  # stanag4609's KLV stream splitter + decode of each packet
        import stanag4609
        from stanag4609 import st0601
        with open(path, "rb") as f:
            for p in stanag4609.iter_klv(f):
                st0601.decode_uas_local_set(p.raw, verify_checksum=True, require_version=False)
                n += 1
    elif kind == "raw-ulog":
        pyulog.ULog(path)
    elif kind == "raw-mcap":
        with open(path, "rb") as f:
            for _s, _c, m in mcap.reader.make_reader(f).iter_messages():
                json.loads(m.data)
                n += 1
    elif kind == "raw-rosbags":
        with rosbags.highlevel.AnyReader([__import__("pathlib").Path(path)],
                                         default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
            for c, _t, raw in r.messages():
                r.deserialize(raw, c.msgtype)
                n += 1
    return n

run(warm_path)  # one-time costs (type stores, generated deserializers, first numpy/scipy calls) on a small file
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # reset the peak RSS (VmHWM) to the current RSS
base = status_kib("VmRSS:")
t = time.perf_counter()
n = run(path)
dt = time.perf_counter() - t
peak = status_kib("VmHWM:")
print(json.dumps({{"seconds": dt, "peak_mib": (peak - base) / 1024, "n": n}}))
'''


def run_child(kind: str, path: Path, warm_path: Path) -> dict:
    code = CHILD.format(repo=str(REPO))
    out = subprocess.run([sys.executable, "-c", code, kind, str(path), str(warm_path)], capture_output=True,
                         text=True, check=False)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else "failed"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def count_messages(path: Path) -> int:
    """Messages in the file as `ridgeloc inspect` counts them (all streams)."""
    sys.path.insert(0, str(REPO))
    from pipeline.ingest import inspect_paths

    (res,) = inspect_paths([path])
    return sum(s.count for s in res.log.streams)


RAW = {"tlog": "raw-tlog", "dataflash": "raw-dataflash", "ulog": "raw-ulog", "mcap": "raw-mcap",
       "ros1": "raw-rosbags", "ros2": "raw-rosbags", "dataflash-text": "raw-dataflash-text", "srt": "raw-srt",
       "klv": "raw-klv"}


def raw_kind(fmt: str, path: Path) -> str:
    """The raw-library baseline of a file: text DataFlash is read by DFReader_text."""
    if fmt == "dataflash" and path.is_file() and not path.read_bytes()[:2] == b"\xa3\x95":
        return RAW["dataflash-text"]
    if path.suffix == ".ts":
        return "raw-klv-ts"
    return RAW[fmt]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=1_200_000, help="messages in the generated tlog")
    ap.add_argument("--mcap-messages", type=int, default=600_000)
    ap.add_argument("--ros2-messages", type=int, default=300_000)
    ap.add_argument("--dflog-messages", type=int, default=600_000, help="records in the generated text DataFlash")
    ap.add_argument("--srt-cues", type=int, default=54_000, help="cues in the generated SRT (30 min at 30 fps)")
    ap.add_argument("--klv-packets", type=int, default=5_400,
                    help="ST 0601 packets (= frames, 30 fps) in the generated FMV .ts and .klv dump")
    ap.add_argument("--only", default="tlog,mcap,ros2,dflog,srt,klv,real",
                    help="comma-separated subset of: tlog, mcap, ros2, dflog (text DataFlash), srt, klv, real")
    ap.add_argument("--out", type=Path, default=None, help="also write the table (markdown) here")
    args = ap.parse_args()
    only = set(args.only.split(","))
    sys.path.insert(0, str(REPO))
    sys.path.insert(0, str(REPO / "tests"))
    from pipeline.ingest import detect_format
    from support.writers import dataflash_text_from_binary

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t = time.perf_counter()
        gens = {"tlog": ("large.tlog", gen_tlog, args.messages, 5000),
                "mcap": ("large.mcap", gen_mcap, args.mcap_messages, 2000),
                "ros2": ("large_ros2", gen_ros2, args.ros2_messages, 2000),
                "dflog": ("large_text_dataflash.log", gen_dataflash_text, args.dflog_messages, 2000),
                "srt": ("large_30min_30fps.SRT", gen_srt, args.srt_cues, 300),
                "klv": ("fmv_30fps.ts", gen_klv, args.klv_packets, 60),
                "klv-dump": ("fmv_30fps.klv", gen_klv, args.klv_packets, 60)}
        files, warm = [], {}
        for key, (name, gen, n_target, n_warm) in gens.items():
            if key in only or (key == "klv-dump" and "klv" in only):
                files.append((tmp / name, gen(tmp / name, n_target)))
                warm[name] = tmp / ("warm_" + name)
                gen(warm[name], n_warm)
        print(f"generated {', '.join(f'{p.name}: {n} msgs' for p, n in files)} in {time.perf_counter() - t:.1f} s",
              file=sys.stderr)
        if "real" in only:
            for p in sorted(LOGS.iterdir()) + sorted(SRTS.iterdir()):
                if p.name != "README.md":
                    files.append((p, count_messages(p)))
                if p.suffix == ".BIN":
                    txt = tmp / (p.stem + "_as_text.log")
                    dataflash_text_from_binary(p, txt)
                    files.append((txt, count_messages(txt)))
        for path, n in files:
            fmt = detect_format(path)
            size_mib = (sum(f.stat().st_size for f in path.iterdir()) if path.is_dir() else path.stat().st_size) / 2**20
            warm_path = warm.get(path.name, path)  # real logs are small: warm up on the file itself
            ours = run_child("ours", path, warm_path)
            raw = run_child(raw_kind(fmt, path), path, warm_path)
            rows.append((path.name, fmt, n, size_mib, ours, raw, raw_kind(fmt, path)))
            print(f"{path.name}: ours {ours} raw {raw}", file=sys.stderr)
    head = ("| file | format | messages | MiB | ours s | ours msgs/s | ours peak MiB | raw library | raw s | "
            "raw msgs/s | raw peak MiB | ours/raw time |")
    lines = [head, "|" + "---|" * 12]
    def cells(d, n):
        if "error" in d:
            return ["error", "-", "-"]
        return [f"{d['seconds']:.3f}", f"{n / d['seconds']:,.0f}", f"{d['peak_mib']:.1f}"]

    for name, fmt, n, mib, o, r, rk in rows:
        ratio = "-" if "error" in o or "error" in r else f"{o['seconds'] / r['seconds']:.2f}"
        lines.append(f"| {name} | {fmt} | {n:,} | {mib:.1f} | " + " | ".join(cells(o, n)) + f" | {rk} | "
                     + " | ".join(cells(r, n)) + f" | {ratio} |")
    table = "\n".join(lines)
    print(table)
    if args.out:
        args.out.write_text(table + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
