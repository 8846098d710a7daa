"""MISB ST 0601 UAS Datalink Local Set (STANAG 4609 full-motion video metadata) -> the time-series model.

Packets are split out of a byte stream here (bounded, resynchronising on the 16-byte Universal Key) and each is
decoded and checksum-verified by the `stanag4609` library (docs/ingest.md says why that one). Where they come
from:
- an MPEG-TS (or any container PyAV reads) with a KLV data stream: `read_fmv` demuxes it with PyAV once, taking
  the video packets' presentation times as the frame index and each KLV packet's PTS as its time, all on the
  "video" clock (0 = the first video frame's pts), plus a "video" -> "unix" clock link from tag 2;
- a raw dump of consecutive Local Set packets (`ffmpeg -map 0:d -f data`): `read_klv_dump`, times from tag 2 on
  the "unix" clock.
Packets with a bad checksum, cut off or otherwise undecodable are skipped and counted in one warning.

Tags taken (ST 0601): 2 time, 5/6/7 platform heading/pitch/roll (90/91, the full-range pitch and roll, where a
packet has them), 13/14 sensor lat/lon with 75 (ellipsoid
height) or else 15 (true altitude, MSL), 16/17 field of view, 18/19/20 sensor azimuth/elevation/roll relative to
the platform, 21 slant range, 23/24/25 frame centre, 40/41/42 target location, 1 checksum (verified).
Sensor attitude = platform ZYX (heading, pitch, roll) then sensor ZYX (azimuth, elevation, roll), both FRD.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import LogReadError
from pipeline.ingest.frames import quat_wxyz_from_rotation
from pipeline.ingest.model import (
    AttitudeSeries,
    ClockLink,
    FieldOfViewSeries,
    FlightLog,
    GimbalSeries,
    PositionSeries,
    RangeSeries,
    StreamInfo,
)

ST0601_KEY = bytes.fromhex("060E2B34020B01010E01030101000000")
EG0104_KEY = bytes.fromhex("060E2B34020101010E01010201010000")
KEY_PREFIX = ST0601_KEY[:4]
MAX_PACKET_BYTES = 65536  # far above any ST 0601 packet; a longer BER length is garbage, not a packet
# ST 0601 tag -> column name of the decoded table
TAGS = {5: "heading_deg", 6: "pitch_deg", 7: "roll_deg", 13: "lat_deg", 14: "lon_deg", 15: "alt_msl_m",
        75: "alt_hae_m", 16: "hfov_deg", 17: "vfov_deg", 18: "sensor_az_deg", 19: "sensor_el_deg",
        20: "sensor_roll_deg", 21: "slant_range_m", 23: "centre_lat_deg", 24: "centre_lon_deg",
        25: "centre_alt_m", 40: "target_lat_deg", 41: "target_lon_deg", 42: "target_alt_m",
        90: "pitch_full_deg", 91: "roll_full_deg"}
TAG_OF = {name: tag for tag, name in TAGS.items()}


def _checksum_ok(packet: bytes) -> bool:
    """ST 0601's checksum (tag 1, the packet's last 2 bytes): the 16-bit sum of the bytes before it read as
    big-endian words. Checked here with numpy before the library decodes, so damaged or hostile bytes cost a
    vectorised sum, not a decode."""
    if len(packet) < 20 or packet[-4:-2] != b"\x01\x02":
        return False
    body = np.frombuffer(packet, dtype=np.uint8, count=len(packet) - 2).astype(np.uint32)
    s = int(body[0::2].sum()) * 256 + int(body[1::2].sum())
    return (s & 0xFFFF) == int.from_bytes(packet[-2:], "big")


def scan_packets(data: bytes, key: bytes = ST0601_KEY) -> tuple[list[dict], int, int]:
    """Decode consecutive KLV packets with Universal Key `key` in `data` -> (rows of `decode_packet`, bad, cut off).

    A packet is taken when its BER length fits (at most MAX_PACKET_BYTES), its checksum holds and the library
    decodes it; then scanning goes on after it. Anything else (a false key match, a bad checksum, a packet running
    past the end) is skipped by resuming just past its key, so one damaged packet costs only itself. Work is
    linear in len(data) times at most MAX_PACKET_BYTES / 16 per key occurrence, all in numpy."""
    rows: list[dict] = []
    bad = cut = 0
    pos, n = 0, len(data)
    while True:
        k = data.find(key, pos)
        if k < 0:
            return rows, bad, cut
        pos = k + 16
        if pos >= n:
            cut += 1
            continue
        first = data[pos]
        nb = 0 if first < 0x80 else first & 0x7F
        if nb > 4 or (first >= 0x80 and nb == 0):
            bad += 1
            continue
        if pos + 1 + nb > n:
            cut += 1
            continue
        length = first if nb == 0 else int.from_bytes(data[pos + 1:pos + 1 + nb], "big")
        start = pos + 1 + nb
        if length > MAX_PACKET_BYTES:
            bad += 1
            continue
        if start + length > n:
            cut += 1
            continue
        packet = data[k:start + length]
        row = decode_packet(packet) if _checksum_ok(packet) else None
        if row is None:
            bad += 1
            continue
        rows.append(row)
        pos = start + length


def _st0601():
    from stanag4609 import st0601  # imported on first use: the package import takes ~0.6 s

    return st0601


def decode_packet(packet: bytes) -> dict[str, float] | None:
    """One ST 0601 packet -> {"t_us": int, column: value (NaN for reserved/out-of-range values)}, or None when
    the packet fails its checksum or does not decode (the library's checks: structure, tag 2 first, lengths)."""
    st = _st0601()
    from stanag4609.errors import Stanag4609Error

    try:
        ls = st.decode_uas_local_set(packet, verify_checksum=True, require_version=False,
                                     field_decoding=st.FieldDecodingMode.PRESERVE)
    except (Stanag4609Error, ValueError, TypeError, OverflowError):
        return None
    t_us = ls.misp_timestamp_microseconds
    if t_us is None:
        return None
    row: dict[str, float] = {"t_us": t_us}
    for field in ls.fields:
        name = TAGS.get(field.definition.tag)
        if name is None:
            continue
        v = field.value
        row[name] = float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan
    return row


class KlvTable:
    """Decoded packets as columns: t_us (n,) int64 tag-2 times, t_ns (n,) int64 times on `clock`, and one float
    column per name in TAGS (NaN where a packet lacks the tag). Counts of skipped packets by reason."""

    def __init__(self, rows: list[dict], t_ns: list[int], clock: str, source: str):
        self.n = len(rows)
        self.t_us = np.array([r["t_us"] for r in rows], dtype=np.int64)
        self.t_ns = np.array(t_ns, dtype=np.int64)
        self.cols = {name: np.array([r.get(name, math.nan) for r in rows], dtype=np.float64) for name in TAGS.values()}
        self.clock = clock
        self.source = source


def _has(table: KlvTable, *names: str) -> np.ndarray:
    return np.logical_and.reduce([np.isfinite(table.cols[n]) for n in names])


def _series(table: KlvTable, mask: np.ndarray):
    order = np.argsort(table.t_ns[mask], kind="stable")
    return table.t_ns[mask][order], order


def _platform_rotation(c: dict[str, np.ndarray], mask: np.ndarray) -> Rotation:
    return Rotation.from_euler("ZYX", np.radians(np.column_stack(
        [c["heading_deg"][mask], c["pitch_deg"][mask], c["roll_deg"][mask]])))


def table_to_log(table: KlvTable, path: str, warnings: list[str]) -> FlightLog:
    """The model's series from decoded ST 0601 packets (see the module docstring for the tag mapping)."""
    c, src = table.cols, table.source
    for short, full in (("pitch_deg", "pitch_full_deg"), ("roll_deg", "roll_full_deg")):
        c[short] = np.where(np.isfinite(c[full]), c[full], c[short])  # 90/91 cover what 6/7 cannot (+-20/50 deg)
    log = FlightLog(path=path, warnings=warnings)
    if table.n == 0:
        return log

    hae = _has(table, "lat_deg", "lon_deg", "alt_hae_m")
    msl = _has(table, "lat_deg", "lon_deg", "alt_msl_m")
    if hae.any() or msl.any():
        use_hae = hae.sum() >= msl.sum()
        m = hae if use_hae else msl
        t, o = _series(table, m)
        alt = c["alt_hae_m" if use_hae else "alt_msl_m"][m][o]
        log.position = PositionSeries(t, c["lat_deg"][m][o], c["lon_deg"][m][o], alt,
                                      "ellipsoid" if use_hae else "amsl",
                                      source=f"{src}:tags 13/14/{75 if use_hae else 15}", clock=table.clock)
    att = _has(table, "heading_deg", "pitch_deg", "roll_deg")
    if att.any():
        t, o = _series(table, att)
        log.attitude = AttitudeSeries(t, quat_wxyz_from_rotation(_platform_rotation(c, att))[o],
                                      source=f"{src}:tags 5/6/7", clock=table.clock)
    gim = att & _has(table, "sensor_az_deg", "sensor_el_deg")
    if gim.any():
        t, o = _series(table, gim)
        roll = np.nan_to_num(c["sensor_roll_deg"][gim], nan=0.0)
        rel = Rotation.from_euler("ZYX", np.radians(np.column_stack(
            [c["sensor_az_deg"][gim], c["sensor_el_deg"][gim], roll])))
        q = quat_wxyz_from_rotation(_platform_rotation(c, gim) * rel)[o]
        log.gimbal = GimbalSeries(t, q, np.zeros(t.size, bool), source=f"{src}:tags 18/19/20 on 5/6/7",
                                  clock=table.clock)
    rng = _has(table, "slant_range_m")
    if rng.any():
        t, o = _series(table, rng)
        r = c["slant_range_m"][rng][o]
        log.range = RangeSeries(t, r, r > 0, source=f"{src}:tag 21", clock=table.clock)
    fov = np.isfinite(c["hfov_deg"]) | np.isfinite(c["vfov_deg"])
    if fov.any():
        t, o = _series(table, fov)
        log.field_of_view = FieldOfViewSeries(t, c["hfov_deg"][fov][o], c["vfov_deg"][fov][o],
                                              source=f"{src}:tags 16/17", clock=table.clock)
    for attr, names, tags in (("frame_centre", ("centre_lat_deg", "centre_lon_deg", "centre_alt_m"), "23/24/25"),
                              ("payload_target", ("target_lat_deg", "target_lon_deg", "target_alt_m"), "40/41/42")):
        m = _has(table, *names)
        if m.any():
            t, o = _series(table, m)
            setattr(log, attr, PositionSeries(t, c[names[0]][m][o], c[names[1]][m][o], c[names[2]][m][o], "amsl",
                                              source=f"{src}:tags {tags}", clock=table.clock))
    supplies = tuple(q for q in ("position", "attitude", "gimbal", "range", "field_of_view")
                     if getattr(log, q) is not None)
    log.streams.append(StreamInfo("ST 0601 UAS Local Set", "klv", table.n, int(table.t_ns.min()),
                                  int(table.t_ns.max()), supplies))
    return log


def _skipped_warning(path, n_ok: int, n_bad: int, n_cut: int, other_keys: int) -> list[str]:
    out = []
    if n_bad or n_cut:
        out.append(f"{Path(path).name}: skipped {n_bad + n_cut} KLV packet(s) of {n_ok + n_bad + n_cut} "
                   f"({n_bad} bad checksum or undecodable, {n_cut} cut off)")
    if other_keys:
        out.append(f"{Path(path).name}: {other_keys} KLV packet(s) of other sets (not ST 0601) ignored")
    return out


def _decode_all(chunks) -> tuple[list[dict], list, int, int, int]:
    """chunks: iterable of (bytes, time or None). Returns rows, their chunk's time, bad and cut counts, and the
    number of chunks holding only other sets (EG 0104 universal sets, ST 0903 VMTI ...)."""
    rows, times = [], []
    bad = cut = other = 0
    for data, t in chunks:
        if data.startswith(KEY_PREFIX) and not data.startswith(ST0601_KEY) and data.find(ST0601_KEY) < 0:
            other += 1
            continue
        got, n_bad, n_cut = scan_packets(data)
        bad += n_bad
        cut += n_cut
        rows += got
        times += [t] * len(got)
    return rows, times, bad, cut, other


def read_klv_dump(path) -> FlightLog:
    """A raw file of consecutive ST 0601 packets (`ffmpeg -i in.ts -map 0:d -f data out.klv`) -> FlightLog on the
    "unix" clock (tag 2)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise LogReadError(f"cannot read: {exc.strerror}", path=p) from None
    if not data:
        raise LogReadError("empty file", path=p)
    rows, _, bad, cut, _ = _decode_all([(data, None)])
    if not rows:
        if data.find(EG0104_KEY) >= 0:
            raise LogReadError("holds MISB EG 0104 universal sets only; ridgeloc reads ST 0601 local sets "
                               "(see docs/ingest.md)", path=p)
        raise LogReadError(f"no valid ST 0601 KLV packet ({bad} bad checksum or undecodable, {cut} cut off)", path=p)
    t_ns = [r["t_us"] * 1000 for r in rows]
    table = KlvTable(rows, t_ns, "unix", p.name)
    log = table_to_log(table, str(p), _skipped_warning(p, len(rows), bad, cut, 0))
    log.formats.append("klv")
    return log


def read_fmv(path, index=None) -> FlightLog:
    """An MPEG-TS (STANAG 4609) with a video stream and a KLV data stream -> FlightLog: frames from the video
    packets' pts, telemetry from the KLV packets, all on the "video" clock (0 = the first video frame), with a
    ClockLink video -> unix from each packet's tag 2. `index`: the file's demux_index(data_streams=True) if known."""
    from pipeline.ingest.video import demux_index

    p = Path(path)
    index = index if index is not None else demux_index(p, data_streams=True)
    if not index.data_packets:
        raise LogReadError("no KLV data stream (this video carries no MISB metadata; give telemetry files)", path=p)
    rows, times, bad, cut, other = _decode_all(index.data_packets)
    if not rows:
        raise LogReadError(f"no valid ST 0601 KLV packet in the data stream ({bad} bad checksum or undecodable, "
                           f"{cut} cut off)", path=p)
    t_us = np.array([r["t_us"] for r in rows], dtype=np.int64)
    have = np.array([t is not None for t in times])
    t_ns = np.zeros(len(rows), dtype=np.int64)
    warnings = _skipped_warning(p, len(rows), bad, cut, other)
    if have.all():
        t_ns[:] = [t for t in times]
    elif have.sum() >= 2:  # packets without a PTS: place them by tag 2, fitted to those with one
        a, b = np.polyfit(t_us[have] * 1e3, np.array([t for t in times if t is not None], dtype=np.float64), 1)
        t_ns[have] = [t for t in times if t is not None]
        t_ns[~have] = np.round(a * t_us[~have] * 1e3 + b).astype(np.int64)
        warnings.append(f"{p.name}: {int((~have).sum())} KLV packet(s) without a PTS placed by their time stamp")
    else:
        t_ns[:] = (t_us - t_us.min()) * 1000
        warnings.append(f"{p.name}: KLV packets carry no PTS; their time stamps are aligned with the first video "
                        "frame (set clock offsets if this is wrong)")
    table = KlvTable(rows, t_ns.tolist(), "video", p.name)
    log = table_to_log(table, str(p), warnings)
    log.frames = index.frames
    log.clock_links.append(ClockLink("video", "unix", table.t_ns.copy(), table.t_us * 1000))
    log.streams.append(StreamInfo(f"{p.name} video", "video", int(index.frames.t_ns.size),
                                  int(index.frames.t_ns[0]), int(index.frames.t_ns[-1]), ("frames",)))
    log.formats.append("fmv")
    return log
