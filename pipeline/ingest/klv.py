"""MISB ST 0601 UAS Datalink Local Set and EG 0104 Universal Set (STANAG 4609 FMV metadata) -> the model.

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
EG 0104 sets (`eg0104.py` holds their key table; no checksum) fill the same columns, their sensor angles
earth-referenced (SENSOR_CONVENTION). A stream may hold both; each row keeps its set (`KlvTable.is_eg0104`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import LogReadError
from pipeline.ingest import eg0104
from pipeline.ingest.ber import ber_length
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
KEY_PREFIX = ST0601_KEY[:4]
MAX_T_US = (2**63 - 1) // 1000  # time stamps past 2262 do not fit int64 nanoseconds: not a packet
MAX_PACKET_BYTES = 65536  # far above any ST 0601 packet; a longer BER length is garbage, not a packet
# ST 0601 tag -> column name of the decoded table
TAGS = {5: "heading_deg", 6: "pitch_deg", 7: "roll_deg", 13: "lat_deg", 14: "lon_deg", 15: "alt_msl_m",
        75: "alt_hae_m", 16: "hfov_deg", 17: "vfov_deg", 18: "sensor_az_deg", 19: "sensor_el_deg",
        20: "sensor_roll_deg", 21: "slant_range_m", 23: "centre_lat_deg", 24: "centre_lon_deg",
        25: "centre_alt_m", 40: "target_lat_deg", 41: "target_lon_deg", 42: "target_alt_m",
        90: "pitch_full_deg", 91: "roll_full_deg"}
TAG_OF = {name: tag for tag, name in TAGS.items()}
COLUMNS = tuple(dict.fromkeys((*TAGS.values(), *eg0104.COLUMNS)))  # every column of a KlvTable


def _checksum_ok(packet: bytes) -> bool:
    """ST 0601's checksum (tag 1, the packet's last 2 bytes): the 16-bit sum of the bytes before it read as
    big-endian words. Checked here with numpy before the library decodes, so damaged or hostile bytes cost a
    vectorised sum, not a decode."""
    if len(packet) < 20 or packet[-4:-2] != b"\x01\x02":
        return False
    body = np.frombuffer(packet, dtype=np.uint8, count=len(packet) - 2).astype(np.uint32)
    s = int(body[0::2].sum()) * 256 + int(body[1::2].sum())
    return (s & 0xFFFF) == int.from_bytes(packet[-2:], "big")


def scan_packets(data: bytes, key: bytes = ST0601_KEY, decode=None) -> tuple[list[dict], int, int]:
    """Decode consecutive KLV packets with Universal Key `key` in `data` -> (rows of `decode`, bad, cut off).

    `decode(packet) -> row | None` defaults to `decode_checked` (ST 0601); EG 0104 sets use `decode_eg0104`.
    A packet is taken when its BER length fits (at most MAX_PACKET_BYTES) and `decode` accepts it (ST 0601: its
    checksum holds and the library decodes it); then scanning goes on after it. Anything else (a false key
    match, a bad checksum, a packet running past the end) is skipped by resuming just past its key, so one damaged
    packet costs only itself. Work is linear in len(data) times at most MAX_PACKET_BYTES / 16 per key occurrence."""
    decode = decode or decode_checked
    rows: list[dict] = []
    bad = cut = 0
    pos, n = 0, len(data)
    while True:
        k = data.find(key, pos)
        if k < 0:
            return rows, bad, cut
        pos = k + 16
        ln = ber_length(data, pos)
        if ln is None:
            bad += 1
            continue
        length, start = ln
        if start > n:
            cut += 1
            continue
        if length > MAX_PACKET_BYTES:
            bad += 1
            continue
        if start + length > n:
            cut += 1
            continue
        packet = data[k:start + length]
        row = decode(packet)
        if row is None:
            bad += 1
            continue
        rows.append(row)
        pos = start + length


def _st0601():
    from stanag4609 import st0601  # imported on first use: the package import takes ~0.6 s

    return st0601


def decode_checked(packet: bytes) -> dict | None:
    """An ST 0601 packet -> its row when the checksum holds and it decodes, else None."""
    return decode_packet(packet) if _checksum_ok(packet) else None


def decode_eg0104(packet: bytes) -> dict | None:
    """An EG 0104 universal set (key, BER length, items) -> row as `decode_packet` gives, plus "_unknown" and
    "_damaged" item counts and "set" = "eg0104"; None without a valid time stamp (nothing to place it by)."""
    ln = ber_length(packet, 16)
    if ln is None:
        return None
    row, unknown, damaged = eg0104.decode_set(packet[ln[1]:])
    if not 0 <= row.get("t_us", -1) <= MAX_T_US:
        return None
    out: dict = {k: v for k, v in row.items() if not isinstance(v, str)}
    for name in ("lon_deg", "centre_lon_deg", *(f"corner{i}_lon_deg" for i in range(1, 5))):
        if name in out and out[name] > 180:  # some writers give 0..360
            out[name] -= 360.0
    out.update(_unknown=unknown, _damaged=damaged, set="eg0104")
    return out


def _klv_packet(packet: bytes):
    """One whole KLV packet (16-byte key, minimal BER length, value) -> the library's `KLVPacket`; raises the
    library's errors when the length is malformed or does not end the packet.

    Built here rather than by `decode_uas_local_set(bytes)`: its one-packet parser is a streaming parser over a
    bytearray that it shrinks after reading a length through a memoryview of it. Where something holds the frame
    that read the length (a sampling profiler, as every Dask worker runs, keeps other threads' frames and with
    them their locals), the shrink raises "BufferError: Existing exports of data: object cannot be re-sized"
    (tests/test_batch_dask_cluster.py). Immutable bytes have no such failure."""
    from stanag4609.errors import DecodeError
    from stanag4609.klv import KLVPacket, decode_ber_length

    packet = bytes(packet)
    length, used = decode_ber_length(packet, 16, canonical=True, max_value=MAX_PACKET_BYTES)
    if 16 + used + length != len(packet):
        raise DecodeError("the BER length does not end the packet")
    return KLVPacket(packet[:16], packet[16 + used:], packet[16:16 + used], 0)


def decode_packet(packet: bytes) -> dict[str, float] | None:
    """One ST 0601 packet -> {"t_us": int, column: value (NaN for reserved/out-of-range values)}, or None when
    the packet fails its checksum or does not decode (the library's checks: structure, tag 2 first, lengths)."""
    st = _st0601()
    from stanag4609.errors import Stanag4609Error

    try:
        ls = st.decode_uas_local_set(_klv_packet(packet), verify_checksum=True, require_version=False,
                                     field_decoding=st.FieldDecodingMode.PRESERVE)
    except (Stanag4609Error, ValueError, TypeError, OverflowError):
        return None
    t_us = ls.misp_timestamp_microseconds
    if t_us is None or not 0 <= t_us <= MAX_T_US:
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
    column per name in TAGS (NaN where a packet lacks the tag). Counts of skipped packets by reason. `azimuth_north`
    "grid": the azimuths were logged from UTM grid north (mapping `klv.azimuth_north`), turned to true north by
    the meridian convergence wherever the table's attitudes are built."""

    def __init__(self, rows: list[dict], t_ns: list[int], clock: str, source: str, azimuth_north: str = "true"):
        self.n = len(rows)
        self.azimuth_north = azimuth_north  # "true" or "grid": where the azimuths are measured from (mapping)
        self.t_us = np.array([r["t_us"] for r in rows], dtype=np.int64)
        self.t_ns = np.array(t_ns, dtype=np.int64)
        self.cols = {name: np.array([r.get(name, math.nan) for r in rows], dtype=np.float64) for name in COLUMNS}
        self.is_eg0104 = np.array([r.get("set") == "eg0104" for r in rows], dtype=bool)
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


# How each set's sensor angles give the sensor's attitude (NED from sensor FRD, x = optical axis):
# "platform": ST 0601's definition, platform ZYX (heading, pitch, roll) then sensor ZYX (azimuth, elevation, roll)
#   relative to the platform;
# "earth": the angles are earth-referenced, ZYX (azimuth from true north, elevation from the local horizontal,
#   roll) in the local NED frame, without the platform attitude. EG 0104's "Angle to North" and "Obliquity Angle"
#   items, as the KWIVER Fort A.P. Hill clips write them (docs/ingest.md gives the frame-centre evidence).
SENSOR_CONVENTION = {"st0601": "platform", "eg0104": "earth"}


def sensor_rotation(c: dict[str, np.ndarray], mask: np.ndarray, convention: str) -> Rotation:
    """The sensor's attitude (NED from sensor FRD) of the rows in `mask` under `convention` ("platform" or
    "earth", see SENSOR_CONVENTION); a missing sensor roll counts as 0."""
    roll = np.nan_to_num(c["sensor_roll_deg"][mask], nan=0.0)
    rel = Rotation.from_euler("ZYX", np.radians(np.column_stack(
        [c["sensor_az_deg"][mask], c["sensor_el_deg"][mask], roll])))
    if convention == "earth":
        return rel
    return _platform_rotation(c, mask) * rel


def grid_to_true(table: KlvTable, mask: np.ndarray) -> Rotation:
    """The rotation (about the local down axis) turning NED-from-x attitudes whose azimuths were logged from UTM
    grid north into true-north ones, for the rows in `mask`: by each row's meridian convergence at the sensor
    position (identity where the table's azimuths are true or a row has no position)."""
    n = int(mask.sum())
    if table.azimuth_north != "grid":
        return Rotation.identity(n)
    from pipeline.geometry.grid_north import utm_convergence_deg

    gamma = np.nan_to_num(utm_convergence_deg(table.cols["lat_deg"][mask], table.cols["lon_deg"][mask]), nan=0.0)
    return Rotation.from_euler("Z", np.radians(gamma)[:, None])


def platform_rotation(table: KlvTable, mask: np.ndarray) -> Rotation:
    """The platform's attitude (NED from body FRD) of the rows in `mask`, true north."""
    return grid_to_true(table, mask) * _platform_rotation(table.cols, mask)


def table_sensor_rotation(table: KlvTable, mask: np.ndarray, north: str | None = None) -> Rotation:
    """`sensor_rotation` of the rows in `mask`, each under its own set's convention (SENSOR_CONVENTION), turned to
    true north when the table's azimuths are grid ones (`north` "true": as logged, without that turn)."""
    eg = table.is_eg0104[mask]
    q = np.empty((int(mask.sum()), 4))
    for conv, rows in ((SENSOR_CONVENTION["eg0104"], eg), (SENSOR_CONVENTION["st0601"], ~eg)):
        if rows.any():
            sub = mask.copy()
            sub[mask] = rows
            q[rows] = sensor_rotation(table.cols, sub, conv).as_quat()
    rot = Rotation.from_quat(q)
    return rot if north == "true" else grid_to_true(table, mask) * rot


def sensor_position(table: KlvTable) -> tuple[np.ndarray, np.ndarray, str, str]:
    """(rows with a sensor position (n,) bool, altitude of every row (n,) m, its datum "ellipsoid" or "amsl",
    the tags it came from): ST 0601 tag 75 (ellipsoid) where more rows have it than tag 15 / EG 0104 altitude
    (MSL)."""
    hae = _has(table, "lat_deg", "lon_deg", "alt_hae_m")
    msl = _has(table, "lat_deg", "lon_deg", "alt_msl_m")
    if hae.sum() >= msl.sum() and hae.any():
        return hae, table.cols["alt_hae_m"], "ellipsoid", "75"
    return msl, table.cols["alt_msl_m"], "amsl", "15"


def _items(table: KlvTable, st0601: str, eg: str) -> str:
    """Where a series came from: the ST 0601 tags, the EG 0104 items, or both."""
    names = ([st0601] if (~table.is_eg0104).any() else []) + ([f"EG 0104 {eg}"] if table.is_eg0104.any() else [])
    return " + ".join(names)


def table_to_log(table: KlvTable, path: str, warnings: list[str]) -> FlightLog:
    """The model's series from decoded ST 0601 / EG 0104 packets (see the module docstring for the mapping)."""
    c, src = table.cols, table.source
    for short, full in (("pitch_deg", "pitch_full_deg"), ("roll_deg", "roll_full_deg")):
        c[short] = np.where(np.isfinite(c[full]), c[full], c[short])  # 90/91 cover what 6/7 cannot (+-20/50 deg)
    log = FlightLog(path=path, warnings=warnings)
    if table.n == 0:
        return log

    m, alt_all, datum, alt_tag = sensor_position(table)
    if m.any():
        t, o = _series(table, m)
        log.position = PositionSeries(t, c["lat_deg"][m][o], c["lon_deg"][m][o], alt_all[m][o], datum,
                                      source=f"{src}:{_items(table, f'tags 13/14/{alt_tag}', 'sensor position')}",
                                      clock=table.clock)
    att = _has(table, "heading_deg", "pitch_deg", "roll_deg")
    if att.any():
        t, o = _series(table, att)
        log.attitude = AttitudeSeries(t, quat_wxyz_from_rotation(platform_rotation(table, att))[o], clock=table.clock,
                                      source=f"{src}:{_items(table, 'tags 5/6/7', 'platform angles')}")
    gim = _has(table, "sensor_az_deg", "sensor_el_deg") & (att | table.is_eg0104)
    if gim.any():
        t, o = _series(table, gim)
        q = quat_wxyz_from_rotation(table_sensor_rotation(table, gim))[o]
        grid = ", azimuths from UTM grid north" if table.azimuth_north == "grid" else ""
        log.gimbal = GimbalSeries(t, q, np.zeros(t.size, bool), clock=table.clock, source=f"{src}:" + _items(
            table, "tags 18/19/20 on 5/6/7", "sensor angles (earth-referenced)") + grid)
    rng = _has(table, "slant_range_m")
    if rng.any():
        t, o = _series(table, rng)
        r = c["slant_range_m"][rng][o]
        log.range = RangeSeries(t, r, r > 0, source=f"{src}:{_items(table, 'tag 21', 'slant range')}",
                                clock=table.clock)
    fov = np.isfinite(c["hfov_deg"]) | np.isfinite(c["vfov_deg"])
    if fov.any():
        t, o = _series(table, fov)
        log.field_of_view = FieldOfViewSeries(t, c["hfov_deg"][fov][o], c["vfov_deg"][fov][o], clock=table.clock,
                                              source=f"{src}:{_items(table, 'tags 16/17', 'fields of view')}")
    for attr, names, tags in (("frame_centre", ("centre_lat_deg", "centre_lon_deg", "centre_alt_m"), "23/24/25"),
                              ("payload_target", ("target_lat_deg", "target_lon_deg", "target_alt_m"), "40/41/42")):
        m = _has(table, *names[:2])  # EG 0104 has no frame-centre elevation in many files: NaN there
        if m.any():
            t, o = _series(table, m)
            what = _items(table, f"tags {tags}", attr.replace("_", " "))
            setattr(log, attr, PositionSeries(t, c[names[0]][m][o], c[names[1]][m][o], c[names[2]][m][o], "amsl",
                                              source=f"{src}:{what}", clock=table.clock))
    supplies = tuple(q for q in ("position", "attitude", "gimbal", "range", "field_of_view")
                     if getattr(log, q) is not None)
    name = " + ".join(n for n, has in (("ST 0601 UAS Local Set", (~table.is_eg0104).any()),
                                        ("EG 0104 Universal Set", table.is_eg0104.any())) if has)
    log.streams.append(StreamInfo(name, "klv", table.n, int(table.t_ns.min()),
                                  int(table.t_ns.max()), supplies))
    return log


def _skipped_warning(path, n_ok: int, n_bad: int, n_cut: int, other_keys: int, unknown: int = 0,
                     damaged: int = 0) -> list[str]:
    out = []
    if n_bad or n_cut:
        out.append(f"{Path(path).name}: skipped {n_bad + n_cut} KLV packet(s) of {n_ok + n_bad + n_cut} "
                   f"({n_bad} bad checksum or undecodable, {n_cut} cut off)")
    if unknown or damaged:
        out.append(f"{Path(path).name}: EG 0104 items skipped: {unknown} with an unknown key, {damaged} damaged "
                   "(wrong length, out of range or cut off)")
    if other_keys:
        out.append(f"{Path(path).name}: {other_keys} KLV packet(s) of other sets (not ST 0601 or EG 0104) ignored")
    return out


def _decode_all(chunks) -> tuple[list[dict], list, int, int, int, int, int]:
    """chunks: iterable of (bytes, time or None). Returns rows (ST 0601 and EG 0104), their chunk's time, bad and
    cut packet counts, the number of chunks holding only other sets (ST 0903 VMTI ...), and the unknown and
    damaged EG 0104 item counts."""
    rows, times = [], []
    bad = cut = other = unknown = damaged = 0
    for data, t in chunks:
        got: list[dict] = []
        for key, decode in ((ST0601_KEY, decode_checked), (eg0104.SET_KEY, decode_eg0104)):
            if data.find(key) < 0:
                continue
            part, n_bad, n_cut = scan_packets(data, key, decode)
            bad += n_bad
            cut += n_cut
            got += part
        if not got and data.startswith(KEY_PREFIX) and data.find(ST0601_KEY) < 0 and data.find(eg0104.SET_KEY) < 0:
            other += 1
            continue
        for r in got:
            unknown += r.pop("_unknown", 0)
            damaged += r.pop("_damaged", 0)
        rows += got
        times += [t] * len(got)
    return rows, times, bad, cut, other, unknown, damaged


def _north(mapping: dict | None) -> str:
    """The mapping's `azimuth_north` ("true", "grid" or "auto"; YAML's bare `true` counts as "true")."""
    value = (mapping or {}).get("azimuth_north", True)
    north = "true" if value is True or value == "true" else value
    if north not in ("true", "grid", "auto"):
        from pipeline.errors import ConfigError

        raise ConfigError(f"mapping.klv.azimuth_north: expected true, grid or auto, got {value!r}")
    return north


def _resolve_north(table: KlvTable, warnings: list[str], north_of) -> None:
    """azimuth_north "auto": the table's reading as `north_of(table) -> ("true" | "grid", note or None)` decides
    (the frame-centre check, `pipeline.ingest.frame_centre.auto_north`), its note added to the warnings; "true"
    without a `north_of`."""
    if table.azimuth_north != "auto":
        return
    table.azimuth_north = "true"
    if north_of is not None:
        table.azimuth_north, note = north_of(table)
        if note:
            warnings.append(note)


def _dump_table(p: Path, mapping: dict | None = None) -> tuple[KlvTable, list[str]]:
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise LogReadError(f"cannot read: {exc.strerror}", path=p) from None
    if not data:
        raise LogReadError("empty file", path=p)
    rows, _, bad, cut, _, unknown, damaged = _decode_all([(data, None)])
    if not rows:
        raise LogReadError(f"no valid ST 0601 or EG 0104 KLV packet ({bad} bad checksum or undecodable, {cut} cut "
                           "off)", path=p)
    t_ns = [r["t_us"] * 1000 for r in rows]
    return (KlvTable(rows, t_ns, "unix", p.name, _north(mapping)),
            _skipped_warning(p, len(rows), bad, cut, 0, unknown, damaged))


def _fmv_table(p: Path, index, mapping: dict | None = None) -> tuple[KlvTable, list[str]]:
    if not index.data_packets:
        raise LogReadError("no KLV data stream (this video carries no MISB metadata; give telemetry files)", path=p)
    rows, times, bad, cut, other, unknown, damaged = _decode_all(index.data_packets)
    if not rows:
        raise LogReadError(f"no valid ST 0601 or EG 0104 KLV packet in the data stream ({bad} bad checksum or "
                           f"undecodable, {cut} cut off)", path=p)
    t_us = np.array([r["t_us"] for r in rows], dtype=np.int64)
    have = np.array([t is not None for t in times])
    t_ns = np.zeros(len(rows), dtype=np.int64)
    warnings = _skipped_warning(p, len(rows), bad, cut, other, unknown, damaged)
    if have.all():
        t_ns[:] = [t for t in times]
    elif have.sum() >= 2:  # packets without a PTS: place them by their time stamp, fitted to those with one
        a, b = np.polyfit(t_us[have] * 1e3, np.array([t for t in times if t is not None], dtype=np.float64), 1)
        t_ns[have] = [t for t in times if t is not None]
        t_ns[~have] = np.round(a * t_us[~have] * 1e3 + b).astype(np.int64)
        warnings.append(f"{p.name}: {int((~have).sum())} KLV packet(s) without a PTS placed by their time stamp")
    else:
        t_ns[:] = (t_us - t_us.min()) * 1000
        warnings.append(f"{p.name}: KLV packets carry no PTS; their time stamps are aligned with the first video "
                        "frame (set clock offsets if this is wrong)")
    return KlvTable(rows, t_ns.tolist(), "video", p.name, _north(mapping)), warnings


def read_klv_table(path, index=None, mapping: dict | None = None) -> tuple[KlvTable, list[str]]:
    """The decoded packets of a raw KLV dump (times on the "unix" clock) or of a video's KLV data stream (the
    "video" clock) and the reader's warnings; `index`: the video's demux_index(data_streams=True) if known."""
    from pipeline.ingest.video import VIDEO_SUFFIXES, demux_index

    p = Path(path)
    if index is None and p.suffix.lower() not in VIDEO_SUFFIXES:  # a raw dump (dispatch's rule: videos by suffix)
        return _dump_table(p, mapping)
    if index is None:
        index = demux_index(p, data_streams=True)
    return _fmv_table(p, index, mapping)


def read_klv_dump(path, mapping: dict | None = None, north_of=None) -> FlightLog:
    """A raw file of consecutive ST 0601 packets or EG 0104 sets (`ffmpeg -i in.ts -map 0:d -f data out.klv`) ->
    FlightLog on the "unix" clock (tag 2 / the EG 0104 time stamp). `north_of`: what decides azimuth_north "auto"
    (`_resolve_north`)."""
    p = Path(path)
    table, warnings = _dump_table(p, mapping)
    _resolve_north(table, warnings, north_of)
    log = table_to_log(table, str(p), warnings)
    log.formats.append("klv")
    log.klv_tables[str(p)] = table
    return log


def read_fmv(path, index=None, mapping: dict | None = None, north_of=None) -> FlightLog:
    """An MPEG-TS (STANAG 4609) with a video stream and a KLV data stream -> FlightLog: frames from the video
    packets' pts, telemetry from the KLV packets, all on the "video" clock (0 = the first video frame), with a
    ClockLink video -> unix from each packet's time stamp. `index`: the file's demux_index(data_streams=True) if
    known; `north_of`: what decides azimuth_north "auto" (`_resolve_north`)."""
    from pipeline.ingest.video import demux_index

    p = Path(path)
    index = index if index is not None else demux_index(p, data_streams=True)
    table, warnings = _fmv_table(p, index, mapping)
    warnings = [*index.warnings, *warnings]
    _resolve_north(table, warnings, north_of)
    log = table_to_log(table, str(p), warnings)
    log.frames = index.frames
    log.clock_links.append(ClockLink("video", "unix", table.t_ns.copy(), table.t_us * 1000))
    log.streams.append(StreamInfo(f"{p.name} video", "video", int(index.frames.t_ns.size),
                                  int(index.frames.t_ns[0]), int(index.frames.t_ns[-1]), ("frames",)))
    log.formats.append("fmv")
    log.klv_tables[str(p)] = table
    log.video_indexes[str(p)] = dataclasses.replace(index, data_packets=[])
    return log
