"""Plain MCAP files through the mcap library: JSON channels by the `mcap` mapping (topic and field names per
quantity), ROS 2 (CDR) channels by the `ros` mapping, decoded with mcap_ros2. Only the selected channels are
read (`iter_messages(topics=...)`) and decoded."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipeline.errors import LogReadError
from pipeline.ingest.columns import Columns, sort_by_time
from pipeline.ingest.frames import ORIENTATION_FRAMES, quat_ned_frd_from_frame, quat_wxyz_from_order
from pipeline.ingest.mcap_records import first_line, linear_messages, mcap_errors, scan_channels
from pipeline.ingest.model import (
    ALT_DATUMS,
    AttitudeSeries,
    FlightLog,
    GimbalSeries,
    PositionSeries,
    RangeSeries,
    StreamInfo,
)
from pipeline.ingest.ros_messages import RosAccumulator, fill_log, normalize_type, resolve_topics, supplies_of

JSON_QUANTITIES = ("position", "attitude", "gimbal", "range")
# A message's `frame` field: <body>_<world> (ORIENTATION_FRAMES), optionally as body_/gimbal_/camera_<b>_to_<w>.
ATTITUDE_FRAMES = {f: f for f in ORIENTATION_FRAMES}
ATTITUDE_FRAMES.update({f"{who}_{f.replace('_', '_to_')}": f for f in ORIENTATION_FRAMES
                        for who in ("body", "gimbal", "camera")})


class _JsonAcc:
    def __init__(self, q: str, cfg: dict, source: str):
        self.q, self.cfg, self.source = q, cfg, source
        self.f = cfg["fields"]
        self.n = self.bad = 0
        self.datums: set[str] = set()
        self.frames: set[str] = set()
        if q == "position":
            self.cols = Columns(t="q", lat="d", lon="d", alt="d")
        elif q in ("attitude", "gimbal"):
            self.cols = Columns(t="q", w="d", x="d", y="d", z="d", veh="b")
        else:
            self.cols = Columns(t="q", r="d", v="b")

    def add(self, d: dict, log_time: int) -> None:
        f = self.f
        self.n += 1
        t = int(d.get(f["t_ns"], log_time)) if f.get("t_ns") else log_time
        try:
            if self.q == "position":
                self.datums.add(str(d.get(f["alt_datum"], self.cfg["default_datum"])))
                self.cols.add(t=t, lat=float(d[f["lat_deg"]]), lon=float(d[f["lon_deg"]]), alt=float(d[f["alt_m"]]))
            elif self.q in ("attitude", "gimbal"):
                q = d[f["q_wxyz"]]
                self.frames.add(str(d.get(f["frame"], "body_frd_to_ned")))
                veh = bool(d.get(f["yaw_in_vehicle_frame"], False)) if "yaw_in_vehicle_frame" in f else False
                self.cols.add(t=t, w=float(q[0]), x=float(q[1]), y=float(q[2]), z=float(q[3]), veh=veh)
            else:
                r = d[f["range_m"]]
                r = np.nan if r is None else float(r)
                self.cols.add(t=t, r=r, v=bool(d.get(f["valid"], True)) and bool(np.isfinite(r)) and r > 0)
        except (KeyError, TypeError, ValueError, IndexError):
            self.bad += 1

    def series(self, path: Path, warnings: list[str]):
        if self.bad:
            warnings.append(f"{path}: {self.bad} of {self.n} {self.q} messages lack the mapped fields; skipped")
        if len(self.cols) == 0:
            return None
        a = self.cols.arrays()
        self.cols = None  # the buffers now live only as long as the views that still need them
        if self.q == "position":
            if len(self.datums) != 1 or next(iter(self.datums)) not in ALT_DATUMS:
                raise LogReadError(f"{self.source}: altitude datum {sorted(self.datums)} (expected one of "
                                   f"{', '.join(ALT_DATUMS)})", path=path)
            t, lat, lon, alt = sort_by_time(a["t"], a["lat"], a["lon"], a["alt"])
            return PositionSeries(t, lat, lon, alt, next(iter(self.datums)), source=self.source, clock="unix")
        if self.q in ("attitude", "gimbal"):
            kinds = {ATTITUDE_FRAMES.get(fr) for fr in self.frames}
            if len(kinds) != 1 or None in kinds:
                raise LogReadError(f"{self.source}: unknown or mixed orientation frame {sorted(self.frames)} "
                                   f"(known: {', '.join(ATTITUDE_FRAMES)})", path=path)
            order = self.cfg.get("quat_order", "wxyz")
            try:
                raw = quat_wxyz_from_order(np.column_stack([a["w"], a["x"], a["y"], a["z"]]), order)
            except ValueError as exc:
                raise LogReadError(f"mcap mapping {self.q}.quat_order: {exc}", path=path) from None
            rot = quat_ned_frd_from_frame(raw, next(iter(kinds)))
            t, q, veh = sort_by_time(a["t"], rot, a["veh"].astype(bool))
            if self.q == "attitude":
                return AttitudeSeries(t, q, source=self.source, clock="unix")
            return GimbalSeries(t, q, veh, source=self.source, clock="unix")
        t, r, v = sort_by_time(a["t"], a["r"], a["v"].astype(bool))
        return RangeSeries(t, r, v, source=self.source, clock="unix")


def read_mcap(path: str | Path, mapping: dict, ros_mapping: dict, scan_all: bool = False) -> FlightLog:
    """Read a plain .mcap file into a FlightLog on the UNIX clock."""
    from mcap.reader import make_reader

    path = Path(path)
    warnings: list[str] = []
    try:
        fh = open(path, "rb")
    except OSError as exc:
        raise LogReadError(f"cannot open: {exc.strerror}", path=path) from None
    with fh:
        try:
            reader = make_reader(fh)
            summary = reader.get_summary()
        except mcap_errors() as exc:
            summary = None
            warnings.append(f"{path}: no MCAP summary ({first_line(exc)}); scanning the file")
        if summary is None:
            fh.seek(0)
            channels, schemas = scan_channels(fh, path)
            counts = {}
        else:
            channels, schemas = summary.channels, summary.schemas
            counts = summary.statistics.channel_message_counts if summary.statistics else {}
        topic_chan = {ch.topic: ch for ch in channels.values()}

        def type_of(ch):
            s = schemas.get(ch.schema_id)
            return s.name if s is not None else ""

        json_topics = {t for t, ch in topic_chan.items() if ch.message_encoding == "json"}
        cdr_topics = {t: normalize_type(type_of(ch)) for t, ch in topic_chan.items() if ch.message_encoding == "cdr"}
        json_accs = {}
        for q in JSON_QUANTITIES:
            topic = mapping[q]["topic"]
            if topic in json_topics:
                json_accs[topic] = _JsonAcc(q, mapping[q], f"{path.name}:{topic}")
        chosen = resolve_topics(ros_mapping, cdr_topics, warnings, str(path)) if cdr_topics else {}
        chosen = {q: t for q, t in chosen.items() if not (q in JSON_QUANTITIES and any(
            a.q == q for a in json_accs.values()))}
        ros_accs = {q: RosAccumulator(q, t, cdr_topics[t], ros_mapping[q], ros_mapping["stamp"],
                                      f"{path}:{t}" if q == "images" else f"{path.name}:{t}")
                    for q, t in chosen.items()}
        ros_by_topic: dict[str, list] = {}
        for acc in ros_accs.values():
            ros_by_topic.setdefault(acc.topic, []).append(acc)
        needed = set(json_accs) | set(ros_by_topic)
        topics = list(topic_chan) if scan_all else sorted(needed)
        stats = {t: [0, None, None] for t in topic_chan}
        decoders: dict[int, object] = {}
        fh.seek(0)
        if topics:
            try:
                it = make_reader(fh).iter_messages(topics=topics) if summary is not None \
                    else linear_messages(fh, set(topics))
                for schema, channel, message in it:
                    st = stats[channel.topic]
                    st[0] += 1
                    st[1] = message.log_time if st[1] is None else min(st[1], message.log_time)
                    st[2] = message.log_time if st[2] is None else max(st[2], message.log_time)
                    if channel.topic in json_accs:
                        try:
                            d = json.loads(message.data)
                        except ValueError:
                            json_accs[channel.topic].bad += 1
                            json_accs[channel.topic].n += 1
                            continue
                        json_accs[channel.topic].add(d, message.log_time)
                    elif channel.topic in ros_by_topic:
                        dec = decoders.get(channel.id)
                        if dec is None:
                            from mcap_ros2.decoder import DecoderFactory
                            dec = decoders[channel.id] = DecoderFactory().decoder_for(channel.message_encoding,
                                                                                       schema)
                        msg = dec(message.data)
                        for acc in ros_by_topic[channel.topic]:
                            acc.add(msg, message.log_time)
            except mcap_errors() as exc:
                read = sum(s[0] for s in stats.values())
                if read == 0:
                    raise LogReadError(f"cannot read MCAP messages: {first_line(exc)}", path=path) from None
                warnings.append(f"{path}: reading stopped after {read} messages: {first_line(exc)} "
                                "(truncated or corrupt)")
    streams = []
    for t, ch in topic_chan.items():
        n, t0, t1 = stats[t]
        if t not in topics:
            n = counts.get(ch.id, 0)
        if ch.message_encoding == "json":
            sup = tuple(a.q for a in json_accs.values() if a.source.endswith(":" + t))
        else:
            sup = supplies_of(type_of(ch))
        streams.append(StreamInfo(t, type_of(ch) or ch.message_encoding, int(n), t0, t1, sup))
    log = FlightLog(path=str(path), streams=streams, warnings=warnings, formats=["mcap"])
    for acc in json_accs.values():
        setattr(log, acc.q, acc.series(path, warnings))
    fill_log(log, ros_accs, warnings, path)
    return log
