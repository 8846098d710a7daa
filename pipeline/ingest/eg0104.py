"""MISB EG 0104 "Predator UAV Basic Universal Metadata Set": one packet -> the columns `klv.KlvTable` holds.

The set (16-byte key 06 0E 2B 34 02 01 01 01 0E 01 01 02 01 01 00 00, BER length) is a run of universal items:
each a 16-byte SMPTE key from the SMPTE RP 210 dictionary, a BER length and the value, with no local tags and no
checksum. No maintained Python library reads it correctly (docs/ingest.md: klvdata 0.0.3 has no EG 0104 set,
klv-parser 0.0.6 parses its items as 1-byte local tags and returns garbage, stanag4609 0.4.0 has none), so the key
table below is written from EG 0104.5 (MISB, "Predator UAV Basic Universal Metadata Set", table 1), with the
names and meanings of ST 0601's mapping of its local tags to these universal keys.

Keys match on every byte but the eighth (the registry version byte, which SMPTE 336 says to ignore: real files
carry 01, 02, 03, 07 or 0A there for the same item). Values: floating point big-endian IEEE 754 (4 or 8 bytes),
the time stamp an unsigned 64-bit count of microseconds since 1970 (UTC, no leap seconds), text items ASCII.
Units: degrees (latitude/longitude WGS84; angles), metres (altitudes above mean sea level, slant range, width).
Items with an unknown key, a length the type cannot have, a non-finite or out-of-range value, or running past the
end of the packet are skipped and counted; a packet whose structure breaks keeps the items before the break.
"""

from __future__ import annotations

import math
import struct

from pipeline.ingest.ber import ber_length

SET_KEY = bytes.fromhex("060E2B34020101010E01010201010000")
_UL_PREFIX = bytes.fromhex("060E2B34010101")  # bytes 1-7 of every item key (byte 8, the version, ignored)

# key bytes 9-16 -> (column, kind, (low, high) valid range). Names after EG 0104.5 / RP 210.
ITEMS: dict[bytes, tuple[str, str, tuple[float, float] | None]] = {
    bytes.fromhex(k): v for k, v in {
        "0702010101050000": ("t_us", "uint64", None),  # User Defined Time Stamp (UNIX us)
        "0701020102040200": ("lat_deg", "float", (-90, 90)),  # Device (sensor) Latitude
        "0701020102040000": ("lat_deg", "float", (-90, 90)),  # the same, older dictionary entry
        "0701020102060200": ("lon_deg", "float", (-180, 360)),  # Device (sensor) Longitude
        "0701020102060000": ("lon_deg", "float", (-180, 360)),
        "0701020102020000": ("alt_msl_m", "float", (-1000, 100000)),  # Device Altitude, m above MSL
        "0701100106000000": ("heading_deg", "float", (-360, 360)),  # Platform Heading Angle
        "0701100105000000": ("pitch_deg", "float", (-180, 180)),  # Platform Pitch Angle
        "0701100104000000": ("roll_deg", "float", (-180, 180)),  # Platform Roll Angle
        "0701100102000000": ("sensor_az_deg", "float", (-360, 360)),  # Angle to North: sensor relative azimuth
        "0701100103000000": ("sensor_el_deg", "float", (-180, 180)),  # Obliquity Angle: sensor relative elevation
        "0701100101000000": ("sensor_roll_deg", "float", (-360, 360)),  # Sensor Roll Angle
        "0420020101080000": ("hfov_deg", "float", (0, 180)),  # Field of View (horizontal)
        "04200201010A0100": ("vfov_deg", "float", (0, 180)),  # Field of View (vertical)
        "0701080101000000": ("slant_range_m", "float", (0, 5e6)),  # Slant Range
        "0701090201000000": ("target_width_m", "float", (0, 1e5)),  # Target Width
        "0701020103020000": ("centre_lat_deg", "float", (-90, 90)),  # Frame Center Latitude
        "0701020103040000": ("centre_lon_deg", "float", (-180, 360)),  # Frame Center Longitude
        "0701020103160000": ("centre_alt_m", "float", (-1000, 100000)),  # Frame Center Elevation, m MSL
        **{f"07010201030{7 + i:X}0100": (f"corner{i + 1}_lat_deg", "float", (-90, 90)) for i in range(4)},
        **{f"07010201030{0xB + i:X}0100": (f"corner{i + 1}_lon_deg", "float", (-180, 360)) for i in range(4)},
        # text items: known, kept out of the numbers
        "0105050000000000": ("episode", "text", None),
        "0101200100000000": ("device_designation", "text", None),
        "0420010201010000": ("image_source_device", "text", None),
        "0701010100000000": ("image_coordinate_system", "text", None),
        "0702010201010000": ("start_date_time", "text", None),
        "0702010207010000": ("event_start_date_time", "text", None),
    }.items()}
COLUMNS = tuple(dict.fromkeys(name for name, kind, _ in ITEMS.values() if kind == "float"))


def decode_set(value: bytes) -> tuple[dict, int, int]:
    """The value of one EG 0104 set (after its key and length) -> (row, unknown items, damaged items).

    row: {column: float} for the numeric items present (the time stamp as int "t_us"), text items as str. Linear
    in len(value)."""
    row: dict = {}
    unknown = damaged = 0
    pos, n = 0, len(value)
    while pos < n:
        if pos + 16 > n:
            return row, unknown, damaged + 1
        key = value[pos:pos + 16]
        ln = ber_length(value, pos + 16)
        if ln is None or ln[1] + ln[0] > n:
            return row, unknown, damaged + 1  # the structure breaks here: nothing after it can be trusted
        length, start = ln
        raw = value[start:start + length]
        pos = start + length
        item = ITEMS.get(key[8:]) if key[:7] == _UL_PREFIX else None
        if item is None:
            unknown += 1
            continue
        name, kind, bounds = item
        if kind == "text":
            row[name] = raw.decode("ascii", errors="replace").rstrip("\x00")
            continue
        if kind == "uint64":
            if length != 8:
                damaged += 1
                continue
            row[name] = int.from_bytes(raw, "big")
            continue
        if length not in (4, 8):
            damaged += 1
            continue
        v = struct.unpack(">f" if length == 4 else ">d", raw)[0]
        if not math.isfinite(v) or not bounds[0] <= v <= bounds[1]:
            damaged += 1
            continue
        row[name] = v
    return row, unknown, damaged
