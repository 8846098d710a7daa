"""ROS 1 bags and ROS 2 bags (sqlite3 / MCAP storage) through rosbags' AnyReader (no ROS installation).

Only the connections of the topics the mapping selects are read, and only their messages are deserialized.
A ROS 2 bag whose metadata.yaml QoS differs from its MCAP file's can make rosbags iterate zero messages
silently (FIELD_NOTES); counts are checked against the metadata and the MCAP files are then read directly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from pipeline.errors import LogReadError
from pipeline.ingest.mcap_records import linear_messages, mcap_errors, scan_channels
from pipeline.ingest.model import FlightLog, FrameSeries, StreamInfo
from pipeline.ingest.ros_messages import (
    RosAccumulator,
    decode_image,
    fill_log,
    normalize_type,
    resolve_topics,
    supplies_of,
)


def _typestore():
    return get_typestore(Stores.ROS2_HUMBLE)


def _open_reader(path: Path) -> AnyReader:
    try:
        reader = AnyReader([path], default_typestore=_typestore())
        reader.open()
    except Exception as exc:  # rosbags raises its own ReaderError/ValueError/KeyError variants
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if "index" in text.lower():
            text += " (a bag cut off while recording has no index; `rosbag reindex` repairs it)"
        raise LogReadError(f"cannot open bag: {text}", path=path) from None
    return reader


def _metadata_counts(path: Path) -> dict[str, int]:
    meta = path / "metadata.yaml"
    if not meta.is_file():
        return {}
    import yaml
    try:
        info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
        return {t["topic_metadata"]["name"]: int(t["message_count"]) for t in info["topics_with_message_count"]}
    except Exception:
        return {}


class _McapDirect:
    """Iterate the MCAP files of a ROS 2 bag folder with the mcap library (CDR decoded by mcap_ros2)."""

    def __init__(self, path: Path):
        import yaml
        info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        self.files = [path / f for f in info["relative_file_paths"]]

    def messages(self, topics):
        from mcap.reader import make_reader
        from mcap_ros2.decoder import DecoderFactory
        for f in self.files:
            with open(f, "rb") as fh:
                reader = make_reader(fh, decoder_factories=[DecoderFactory()])
                for schema, channel, message, decoded in reader.iter_decoded_messages(topics=list(topics)):
                    yield channel.topic, schema.name, message.log_time, decoded


def check_metadata(path: Path) -> None:
    """Refuses a ROS 2 bag folder whose metadata.yaml lacks, or mistypes, what the readers use (the libraries
    take its values on trust)."""
    import yaml

    meta = path / "metadata.yaml"
    try:
        info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
        files = info["relative_file_paths"]
        topics = info["topics_with_message_count"]
        ok = (isinstance(files, list) and files and all(isinstance(f, str) and f for f in files)
              and isinstance(topics, list) and all(
                  isinstance(t, dict) and isinstance(t.get("topic_metadata"), dict)
                  and all(isinstance(t["topic_metadata"].get(k), str) for k in ("name", "type"))
                  and isinstance(t.get("message_count"), int) for t in topics))
    except (OSError, UnicodeDecodeError, yaml.YAMLError, TypeError, KeyError) as exc:
        raise LogReadError(f"unreadable metadata.yaml ({type(exc).__name__}: {str(exc).splitlines()[0][:100]})",
                           path=meta) from None
    if not ok:
        raise LogReadError("metadata.yaml: relative_file_paths or topics_with_message_count (topic_metadata name, "
                           "type, message_count) missing or of the wrong type", path=meta)


def read_rosbag(path: str | Path, mapping: dict, scan_all: bool = False) -> FlightLog:
    """Read a ROS 1 .bag or a ROS 2 bag folder into a FlightLog on the UNIX clock (mappings/ros.yaml)."""
    path = Path(path)
    fmt = "ros2" if path.is_dir() else "ros1"
    if fmt == "ros2":
        check_metadata(path)
    warnings: list[str] = []
    try:
        reader = _open_reader(path)
    except LogReadError as exc:
        if fmt == "ros1":
            return _read_ros1_scan(path, mapping, scan_all, exc)
        return _read_ros2_mcap_direct(path, mapping, scan_all, exc)
    try:
        topic_types = {c.topic: c.msgtype for c in reader.connections}
        chosen = resolve_topics(mapping, topic_types, warnings, str(path))
        # frames name the full path: BagImages(path, topic) reopens it
        accs = {q: RosAccumulator(q, t, topic_types[t], mapping[q], mapping["stamp"],
                                  f"{path}:{t}" if q == "images" else f"{path.name}:{t}")
                for q, t in chosen.items()}
        by_topic: dict[str, list[RosAccumulator]] = {}
        for acc in accs.values():
            by_topic.setdefault(acc.topic, []).append(acc)
        stats = {c.topic: [0, None, None] for c in reader.connections}
        conns = list(reader.connections) if scan_all else [c for c in reader.connections if c.topic in by_topic]
        if conns:
            try:
                for conn, t_rec, raw in reader.messages(connections=conns):
                    st = stats[conn.topic]
                    st[0] += 1
                    st[1] = t_rec if st[1] is None else st[1]
                    st[2] = t_rec
                    if conn.topic in by_topic:
                        msg = reader.deserialize(raw, conn.msgtype)
                        for acc in by_topic[conn.topic]:
                            acc.add(msg, t_rec)
            except Exception as exc:
                read = sum(s[0] for s in stats.values())
                msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                if read == 0:
                    raise LogReadError(f"cannot read messages: {msg}", path=path) from None
                warnings.append(f"{path}: reading stopped after {read} messages: {msg} (truncated or corrupt)")
        meta_counts = _metadata_counts(path) if fmt == "ros2" else {}
        silent = sorted({c.topic for c in conns if stats[c.topic][0] == 0 and meta_counts.get(c.topic, 0) > 0})
        if silent:
            expected = sum(meta_counts[t] for t in silent)
            direct = all(str(f).endswith(".mcap") for f in _McapDirect(path).files)
            warnings.append(f"{path}: rosbags iterated 0 of {expected} messages that metadata.yaml lists on "
                            f"{', '.join(silent)} (QoS mismatch between metadata.yaml and the storage file?)"
                            + ("; read them from the MCAP file directly" if direct else ""))
            if direct:
                for topic, _schema, t_rec, msg in _McapDirect(path).messages(set(silent)):
                    st = stats[topic]
                    st[0] += 1
                    st[1] = t_rec if st[1] is None else st[1]
                    st[2] = t_rec
                    for acc in by_topic.get(topic, []):
                        acc.add(msg, t_rec)
        streams = []
        for c in reader.connections:
            n, t0, t1 = stats[c.topic]
            if c.topic not in {k.topic for k in conns}:
                n = meta_counts.get(c.topic, c.msgcount)
            streams.append(StreamInfo(c.topic, normalize_type(c.msgtype), int(n), t0, t1, supplies_of(c.msgtype)))
    finally:
        reader.close()
    log = FlightLog(path=str(path), streams=streams, warnings=warnings, formats=[fmt])
    fill_log(log, accs, warnings, path)
    return log


def _read_ros1_scan(path: Path, mapping: dict, scan_all: bool, open_error: LogReadError) -> FlightLog:
    """A ROS 1 bag rosbags cannot open (index missing: cut off while recording), read by a linear scan;
    raises the original error when the scan finds nothing either."""
    from pipeline.ingest.rosbag1_scan import UnindexedBag1

    try:
        bag = UnindexedBag1(path)
    except Exception:
        raise open_error from None
    if not bag.connections:
        raise open_error
    warnings: list[str] = []
    topic_types = {t: ty for t, ty, _ in bag.connections.values()}
    chosen = resolve_topics(mapping, topic_types, warnings, str(path))
    accs = {q: RosAccumulator(q, t, topic_types[t], mapping[q], mapping["stamp"],
                              f"{path}:{t}" if q == "images" else f"{path.name}:{t}") for q, t in chosen.items()}
    by_topic: dict[str, list[RosAccumulator]] = {}
    for acc in accs.values():
        by_topic.setdefault(acc.topic, []).append(acc)
    stats = {t: [0, None, None] for t in topic_types}
    n = 0
    for topic, msgtype, t_rec, raw in bag.messages(None if scan_all else set(by_topic)):
        n += 1
        st = stats[topic]
        st[0] += 1
        st[1] = t_rec if st[1] is None else min(st[1], t_rec)
        st[2] = t_rec if st[2] is None else max(st[2], t_rec)
        if topic in by_topic:
            try:
                msg = bag.deserialize(raw, msgtype)
            except Exception as exc:
                raise LogReadError(f"cannot decode {topic} ({msgtype}): message definition missing or broken "
                                   f"({exc})", path=path) from None
            for acc in by_topic[topic]:
                acc.add(msg, t_rec)
    if n == 0 and chosen:
        raise open_error
    t0 = min((s[1] for s in stats.values() if s[1] is not None), default=None)
    t1 = max((s[2] for s in stats.values() if s[2] is not None), default=None)
    span = (t1 - t0) / 1e9 if t0 is not None else 0.0
    why = str(open_error).split(": cannot open bag: ", 1)[-1].split(" (a bag cut off")[0]
    state = "file ends inside a record, " if not bag.complete else ""
    warnings.insert(0, f"{path}: rosbags cannot open it ({why}; {state}recording cut off?); read {n} messages "
                       f"covering {span:.1f} s by scanning the records")
    streams = [StreamInfo(t, ty, int(stats[t][0]), stats[t][1], stats[t][2], supplies_of(ty))
               for t, ty in topic_types.items()]
    log = FlightLog(path=str(path), streams=streams, warnings=warnings, formats=["ros1"])
    fill_log(log, accs, warnings, path)
    return log


def _read_ros2_mcap_direct(path: Path, mapping: dict, scan_all: bool, open_error: LogReadError) -> FlightLog:
    """A ROS 2 bag with MCAP storage that rosbags cannot open (e.g. cut off: no summary), read file by file with
    the plain-MCAP reader (linear scan, CDR channels by the ros mapping); else the original error."""
    from pipeline.ingest.mapping import mapping_for
    from pipeline.ingest.mcap_plain import read_mcap
    from pipeline.ingest.merge import merge_logs

    try:
        files = _McapDirect(path).files
    except Exception:
        raise open_error from None
    if not files or not all(f.suffix == ".mcap" and f.is_file() for f in files):
        raise open_error
    logs = [read_mcap(f, mapping_for("mcap"), mapping, scan_all=scan_all) for f in files]
    log = merge_logs(logs)
    why = str(open_error).split(": cannot open bag: ", 1)[-1]
    log.warnings.insert(0, f"{path}: rosbags cannot open it ({why}); read its MCAP file(s) directly")
    log.path, log.formats = str(path), ["ros2"]
    return log


class _RosbagsSource:
    """Image-topic access through rosbags (bags it can open)."""

    def __init__(self, path: Path):
        self.path = path
        reader = _open_reader(path)
        self.topic_types = {c.topic: c.msgtype for c in reader.connections}
        reader.close()

    def messages(self, topic: str):
        """(record time ns, decode()) per message of `topic`, in order; decode() deserializes that one only."""
        reader = _open_reader(self.path)
        try:
            msgtype = self.topic_types[topic]
            conns = [c for c in reader.connections if c.topic == topic]
            for _conn, t_rec, raw in reader.messages(connections=conns):
                yield t_rec, (lambda raw=raw: reader.deserialize(raw, msgtype))
        finally:
            reader.close()


class _Ros1ScanSource:
    """Image-topic access in a ROS 1 bag rosbags cannot open (no index), by scanning its records."""

    def __init__(self, path: Path):
        from pipeline.ingest.rosbag1_scan import UnindexedBag1

        self.bag = UnindexedBag1(path)
        self.topic_types = {t: ty for t, ty, _ in self.bag.connections.values()}

    def messages(self, topic: str):
        for _topic, msgtype, t_rec, raw in self.bag.messages({topic}):
            yield t_rec, (lambda raw=raw, msgtype=msgtype: self.bag.deserialize(raw, msgtype))


class _McapSource:
    """Image-topic access in MCAP files (a plain .mcap, or the files of a ROS 2 bag rosbags cannot open); CDR
    decoded by mcap_ros2; files without a summary are scanned linearly."""

    def __init__(self, files: list[Path]):
        self.files = files
        self.topic_types: dict[str, str] = {}
        for f in files:
            with open(f, "rb") as fh:
                channels, schemas = scan_channels(fh, f)
            for ch in channels.values():
                if ch.message_encoding == "cdr" and ch.schema_id in schemas:
                    self.topic_types[ch.topic] = normalize_type(schemas[ch.schema_id].name)

    def messages(self, topic: str):
        from mcap_ros2.decoder import DecoderFactory


        factory = DecoderFactory()
        for f in self.files:
            with open(f, "rb") as fh:
                decoders: dict[int, object] = {}
                try:
                    for schema, channel, message in linear_messages(fh, {topic}):
                        if channel.id not in decoders:
                            decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
                        dec = decoders[channel.id]
                        yield message.log_time, (lambda data=message.data, dec=dec: dec(data))
                except mcap_errors():
                    return  # file cut off: the images before the cut are all there is


def _image_source(path: Path):
    """The first way of reading `path` that works: rosbags, then a record scan (ROS 1) or the MCAP library."""
    if path.is_file() and path.suffix.lower() == ".mcap" and not (path.parent / "metadata.yaml").is_file():
        return _McapSource([path])
    try:
        return _RosbagsSource(path)
    except LogReadError as exc:
        try:
            if path.is_dir():
                files = _McapDirect(path).files
                if files and all(f.suffix == ".mcap" and f.is_file() for f in files):
                    return _McapSource(files)
            else:
                src = _Ros1ScanSource(path)
                if src.topic_types:
                    return src
        except Exception:
            pass
        raise exc from None


class BagImages:
    """The images of one topic of a bag (ROS 1 file, ROS 2 folder, or plain MCAP file with ROS 2 messages):
    `frames` (FrameSeries: header stamps on the UNIX clock, index = message number on the topic) and
    `read(indices)` decoding only those messages. `frames`: the FrameSeries `read_flight` already built for
    this bag's image topic (same source, image size known), which spares a second pass over the bag."""

    def __init__(self, path, topic: str | None = None, mapping: dict | None = None,
                 frames: FrameSeries | None = None):
        from pipeline.ingest.mapping import mapping_for

        self.path = Path(path)
        cfg = mapping_for("ros", mapping)
        if topic is not None:
            cfg["images"]["topic"] = topic
        self._source = _image_source(self.path)
        warnings: list[str] = []
        chosen = resolve_topics(cfg, self._source.topic_types, warnings, str(self.path))
        if "images" not in chosen:
            raise LogReadError(f"no image topic ({topic or cfg['images']['topic']}) in the bag", path=self.path)
        self.topic = chosen["images"]
        self.msgtype = self._source.topic_types[self.topic]
        if frames is not None and frames.source == f"{self.path}:{self.topic}" and frames.width_px > 0:
            self.frames = frames
            return
        acc = RosAccumulator("images", self.topic, self.msgtype, cfg["images"], cfg["stamp"],
                             f"{self.path}:{self.topic}")
        first = None
        for t_rec, decode in self._source.messages(self.topic):
            msg = decode()  # header stamp; pixels stay an undecoded byte array
            first = msg if first is None else first
            acc.add(msg, t_rec)
        frames = acc.series()
        if frames is None:
            raise LogReadError(f"image topic {self.topic} has no messages", path=self.path)
        if frames.width_px == 0 and first is not None:
            img = decode_image(first, self.msgtype)
            frames = FrameSeries(frames.t_ns, frames.index, frames.source, frames.clock, img.shape[1], img.shape[0])
        self.frames = frames

    def read(self, indices) -> dict[int, np.ndarray]:
        """Decode the messages with these indices (message number on the topic) -> {index: image}."""
        wanted = set(int(i) for i in indices)
        out: dict[int, np.ndarray] = {}
        if not wanted:
            return out
        it = self._source.messages(self.topic)
        try:
            for i, (_t, decode) in enumerate(it):
                if i in wanted:
                    out[i] = decode_image(decode(), self.msgtype)
                    if len(out) == len(wanted):
                        break
        finally:
            it.close()
        missing = sorted(wanted - set(out))
        if missing:
            raise LogReadError(f"image topic {self.topic} has no message {missing[0]}", path=self.path)
        return out
