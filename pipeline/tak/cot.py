"""Cursor on Target (MITRE CoT event schema 2.0) events of located targets.

An event is

    <event version="2.0" uid="ridgeloc-<uuid>" type="a-u-G" how="m-f" time=... start=... stale=...>
      <point lat=... lon=... hae=... ce=... le=.../>
      <detail>
        <contact callsign="<target>"/>
        <remarks>method, MGRS, CE90/LE90, 95 % ellipse, heights, flight</remarks>
        <precisionlocation geopointsrc="CALC" altsrc="CALC"/>
        <ridgeloc .../>   the same numbers, machine-readable
      </detail>
    </event>

- `hae` is the height above the WGS84 ellipsoid (m), as the schema defines it.
- `ce`/`le` are CE90 and LE90 (m): the radius of the horizontal circle holding 90 % of the error and 1.645 sigma
  of the height. The schema's text reads "circular 1-sigma"; ATAK stores and shows both fields as 90 % values
  (its GeoPoint's ce90/le90), and a 90 % reading of a smaller 1-sigma number would understate the error
  2.1 times. Unknown is 9999999 (the schema's and TAK's convention). docs/outputs.md, "For TAK users".
- `how` "m-f": machine-generated, fused ("corroborated from multiple sources" in the schema: the answer fuses
  many views, laser ranges and the platform's navigation).
- `type` defaults to "a-u-G" (an atom of unknown affiliation on the ground: ATAK's yellow "unknown" marker);
  any CoT type can be given (e.g. "a-h-G" hostile, "a-n-G" neutral, "b-m-p-s-m" a spot marker).
- `time` = `start` = when the event is written (or sent), `stale` = start + the stale time (default 24 h).
"""

from __future__ import annotations

import math
import re
import uuid
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone

from pipeline.errors import InputError
from pipeline.tak import DEFAULT_STALE_S, DEFAULT_TYPE

HOW = "m-f"
#: the schema's (and TAK's) value of an unknown hae, ce or le
UNKNOWN = 9999999.0
#: ATAK's source names for a calculated point and altitude (GeoPointMetaData.CALCULATED)
CALCULATED = "CALC"
XML_DECLARATION = '<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n'
#: the namespace of ridgeloc's target uids (uuid5 of a flight's and target's key, `target_uid`)
UID_NAMESPACE = uuid.UUID("6f1d7c1e-3b0a-5e55-9d6a-2f4c1a7b0c39")
#: a CoT type as the schema's pattern allows it: dash-separated words, an optional ";" qualifier
#: a .cot file larger than this is refused unread (an event of ridgeloc's is about 1 KB)
MAX_EVENT_BYTES = 1 << 20
_TYPE_RE = re.compile(r"\w+(-\w+)*(;[^;]*)?")
_DURATION_RE = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([smhd]?)\s*")
_UNIT_S = {"": 1.0, "s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}


@dataclass(frozen=True)
class CotTarget:
    """What one event says about a located target: WGS84 position (deg, deg, m above the ellipsoid), CE90 and
    LE90 (m; None when unknown), the callsign shown on the map, the remarks text and machine-readable
    attributes (name -> text) for the <ridgeloc> detail."""

    uid: str
    callsign: str
    lat_deg: float
    lon_deg: float
    hae_m: float
    ce90_m: float | None
    le90_m: float | None
    remarks: str = ""
    attributes: Mapping[str, str] = field(default_factory=dict)


def target_uid(key: str) -> str:
    """The event uid of a target: "ridgeloc-" and the uuid5 of `key` (the flight's identity and the target's
    name), so the same flight and target always give the same uid and a re-send updates the marker."""
    return f"ridgeloc-{uuid.uuid5(UID_NAMESPACE, key)}"


def check_type(cot_type: str) -> str:
    """`cot_type` if it is a CoT type (e.g. "a-u-G"); InputError otherwise."""
    if not isinstance(cot_type, str) or not _TYPE_RE.fullmatch(cot_type):
        raise InputError(f"not a CoT type: {cot_type!r} (dash-separated letters, e.g. {DEFAULT_TYPE} for an "
                         "unknown ground point, a-h-G hostile, a-n-G neutral)")
    return cot_type


def parse_duration_s(text: str | float) -> float:
    """Seconds of a duration given as a number of seconds or with a unit: "90", "90s", "30m", "24h", "7d";
    InputError unless it is > 0 and finite."""
    if isinstance(text, int | float):
        seconds = float(text)
    else:
        m = _DURATION_RE.fullmatch(str(text))
        if m is None:
            raise InputError(f"not a duration: {text!r} (a number of seconds, or with a unit: 90s, 30m, 24h, 7d)")
        seconds = float(m.group(1)) * _UNIT_S[m.group(2)]
    if not (seconds > 0 and math.isfinite(seconds)):
        raise InputError(f"a stale time must be more than 0 s, got {text!r}")
    return seconds


def cot_time(t: datetime) -> str:
    """A CoT time stamp (UTC, milliseconds, "Z")."""
    return t.astimezone(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


def parse_cot_time(text: str) -> datetime:
    """A CoT time stamp (xs:dateTime in UTC, any fraction of a second) as an aware datetime."""
    m = re.fullmatch(r"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d)(?:\.(\d+))?Z", text or "")
    if m is None:
        raise ValueError(f"not a CoT time: {text!r}")
    t = datetime.strptime(m.group(1), "%Y-%m-%dT%H:%M:%S").replace(tzinfo=timezone.utc)
    return t + timedelta(microseconds=round(float("0." + (m.group(2) or "0")) * 1e6))


def _number(x: float | None, decimals: int) -> str:
    return f"{UNKNOWN:.1f}" if x is None or not math.isfinite(x) else f"{x:.{decimals}f}"


def event_element(target: CotTarget, now: datetime, cot_type: str = DEFAULT_TYPE,
                  stale_s: float = DEFAULT_STALE_S) -> ET.Element:
    """The <event> element of a target, valid from `now` (aware datetime) for `stale_s` seconds."""
    event = ET.Element("event", {
        "version": "2.0", "uid": target.uid, "type": check_type(cot_type), "how": HOW,
        "time": cot_time(now), "start": cot_time(now), "stale": cot_time(now + timedelta(seconds=stale_s))})
    ET.SubElement(event, "point", {
        "lat": f"{target.lat_deg:.8f}", "lon": f"{target.lon_deg:.8f}", "hae": _number(target.hae_m, 3),
        "ce": _number(target.ce90_m, 2), "le": _number(target.le90_m, 2)})
    detail = ET.SubElement(event, "detail")
    ET.SubElement(detail, "contact", {"callsign": target.callsign})
    if target.remarks:
        ET.SubElement(detail, "remarks").text = target.remarks
    ET.SubElement(detail, "precisionlocation", {"geopointsrc": CALCULATED, "altsrc": CALCULATED})
    if target.attributes:
        ET.SubElement(detail, "ridgeloc", {k: str(v) for k, v in target.attributes.items()})
    return event


def to_bytes(event: ET.Element) -> bytes:
    """An event as the bytes of a .cot file and of a message: XML declaration, the event on one line."""
    return (XML_DECLARATION + ET.tostring(event, encoding="unicode")).encode("utf-8")


def event_xml(target: CotTarget, now: datetime, cot_type: str = DEFAULT_TYPE,
              stale_s: float = DEFAULT_STALE_S) -> bytes:
    """`to_bytes(event_element(...))`."""
    return to_bytes(event_element(target, now, cot_type, stale_s))


def read_event(data: bytes, source: str) -> ET.Element:
    """A CoT event from XML bytes (a .cot file): InputError naming `source` unless it is an <event> with a uid,
    time stamps and a <point>."""
    from defusedxml import ElementTree as SafeET

    try:
        root = SafeET.fromstring(data)
    except Exception as exc:  # defusedxml's and expat's parse errors, entity expansion refused
        raise InputError(f"not a CoT event: {str(exc).splitlines()[0]}", source) from None
    if root.tag != "event" or not root.get("uid") or root.find("point") is None:
        raise InputError("not a CoT event: no <event> with a uid and a <point>", source)
    try:
        for key in ("time", "start", "stale"):
            parse_cot_time(root.get(key))
        point = {k: float(root.find("point").get(k, "nan")) for k in ("lat", "lon", "hae", "ce", "le")}
    except ValueError as exc:
        raise InputError(f"not a CoT event: {exc}", source) from None
    bad = [k for k, v in point.items() if not math.isfinite(v)]
    if bad or abs(point["lat"]) > 90 or abs(point["lon"]) > 180:
        raise InputError(f"not a CoT event: its point's {', '.join(bad) or 'lat/lon'} is missing, not a finite "
                         "number or out of range", source)
    return root


def read_event_file(path) -> ET.Element:
    """`read_event` of a .cot file (at most MAX_EVENT_BYTES)."""
    from pathlib import Path

    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_EVENT_BYTES:
            raise InputError(f"not a CoT event: {size} bytes (an event is at most {MAX_EVENT_BYTES})", path)
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror or exc}", path) from None
    return read_event(data, str(path))


def restamp(event: ET.Element, now: datetime, stale_s: float | None = None) -> ET.Element:
    """The event valid from `now`: time = start = now, stale = now + `stale_s` (default: the validity the event
    was written with, stale - start). The element is changed in place and returned."""
    if stale_s is None:
        stale_s = (parse_cot_time(event.get("stale")) - parse_cot_time(event.get("start"))).total_seconds()
        stale_s = stale_s if stale_s > 0 else DEFAULT_STALE_S
    event.set("time", cot_time(now))
    event.set("start", cot_time(now))
    event.set("stale", cot_time(now + timedelta(seconds=stale_s)))
    return event


def ping_event(now: datetime) -> bytes:
    """TAK's ping (type t-x-c-t), sent first on a stream: TAK Server answers it, FreeTAKServer takes the first
    event of a connection as the client's own and greets it; no device shows it."""
    event = ET.Element("event", {"version": "2.0", "uid": "ridgeloc-ping", "type": "t-x-c-t", "how": "m-g",
                                 "time": cot_time(now), "start": cot_time(now),
                                 "stale": cot_time(now + timedelta(seconds=20))})
    ET.SubElement(event, "point", {"lat": "0.0", "lon": "0.0", "hae": "0.0", "ce": f"{UNKNOWN:.1f}",
                                   "le": f"{UNKNOWN:.1f}"})
    ET.SubElement(event, "detail")
    return to_bytes(event)
