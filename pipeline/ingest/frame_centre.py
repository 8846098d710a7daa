"""The payload's own frame centre as a second opinion on the conventions ridgeloc applies to KLV metadata.

Per packet that has the sensor position, its angles, a slant range and a frame centre (ST 0601 tags 13-25, EG 0104
items): ridgeloc's line of sight through the principal point (the optical axis of the sensor attitude the reader
builds, `klv.table_sensor_rotation`), followed for the logged slant range from the logged sensor position,
should land on the logged frame centre. The distance is 3-D where the frame centre has an elevation, horizontal
where it has none (most EG 0104 files). A few metres is the sensor's rounding and its own terrain model; hundreds
are a convention error, and the same distance under each alternative reading of the angles and heights
(`ALTERNATIVES`) names the one that explains it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pymap3d
from scipy.spatial.transform import Rotation

from pipeline.geometry.frames import R_ecef_from_ned, ecef_from_lla
from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.geometry.grid_north import utm_convergence_deg
from pipeline.ingest.klv import KlvTable, _platform_rotation, sensor_position, sensor_rotation, table_sensor_rotation

CONSISTENT_M = 30.0  # median at or below: the conventions agree with the payload's
LARGE_M = 100.0  # median above: a convention error, not rounding or terrain


def _rel(c, m, order="ZYX", signs=(1, 1, 1)) -> Rotation:
    roll = np.nan_to_num(c["sensor_roll_deg"][m], nan=0.0)
    az, el = c["sensor_az_deg"][m], c["sensor_el_deg"][m]
    angles = {"Z": signs[0] * az, "Y": signs[1] * el, "X": signs[2] * roll}
    return Rotation.from_euler(order, np.radians(np.column_stack([angles[a] for a in order])))


def _platform_rpy(c, m) -> Rotation:
    return Rotation.from_euler("XYZ", np.radians(np.column_stack(
        [c["roll_deg"][m], c["pitch_deg"][m], c["heading_deg"][m]])))


def _heading_only(c, m) -> Rotation:
    roll = np.nan_to_num(c["sensor_roll_deg"][m], nan=0.0)
    return Rotation.from_euler("ZYX", np.radians(np.column_stack(
        [c["heading_deg"][m] + c["sensor_az_deg"][m], c["sensor_el_deg"][m], roll])))


# name -> sensor attitude (NED from sensor FRD) of the rows in m, from the table's columns c
ALTERNATIVES = {
    "sensor angles relative to the platform (ST 0601: platform ZYX, then sensor ZYX)":
        lambda c, m: sensor_rotation(c, m, "platform"),
    "sensor angles earth-referenced (azimuth from true north, elevation from the horizontal)":
        lambda c, m: sensor_rotation(c, m, "earth"),
    "sensor azimuth relative to the heading only, elevation from the horizontal":
        _heading_only,
    "platform angles in roll-pitch-yaw order (XYZ) instead of yaw-pitch-roll":
        lambda c, m: _platform_rpy(c, m) * _rel(c, m),
    "sensor elevation applied before azimuth (YZX)":
        lambda c, m: _platform_rotation(c, m) * _rel(c, m, "YZX"),
    "relative angles composed before the platform's (sensor * platform)":
        lambda c, m: _rel(c, m) * _platform_rotation(c, m),
    "sensor elevation with the opposite sign (positive down)":
        lambda c, m: _platform_rotation(c, m) * _rel(c, m, signs=(1, -1, 1)),
    "sensor azimuth counter-clockwise":
        lambda c, m: _platform_rotation(c, m) * _rel(c, m, signs=(-1, 1, 1)),
}
GRID_NORTH = "azimuths from UTM grid north, not true north (meridian convergence of the sensor's UTM zone)"
TRUE_NORTH = "azimuths from true north, not UTM grid north (as the standards say)"
# what the flight config sets to read the angles as the alternative that explains the miss
SWITCH = {GRID_NORTH: "mapping: {klv: {azimuth_north: grid}}", TRUE_NORTH: "mapping: {klv: {azimuth_north: true}}"}
HEIGHT_ALTERNATIVES = ("sensor altitude on the other datum (MSL <-> ellipsoid)",
                       "frame-centre elevation above the ellipsoid, not MSL")


@dataclass
class FrameCentreCheck:
    """Distances (m) between ridgeloc's line of sight at the slant range and the logged frame centre."""

    n: int
    median_m: float
    p95_m: float
    horizontal_only: bool  # the frame centre has no elevation: horizontal distances
    median_horizontal_m: float
    median_vertical_m: float | None  # signed, line of sight minus frame centre (None: no elevation)
    convention: str  # how ridgeloc read the angles (the sets' conventions)
    verdict: str
    alternatives: dict[str, float] = field(default_factory=dict)  # name -> median (m)
    explained_by: str | None = None

    def to_dict(self) -> dict:
        return {"n": self.n, "median_m": round(self.median_m, 2), "p95_m": round(self.p95_m, 2),
                "horizontal_only": self.horizontal_only, "median_horizontal_m": round(self.median_horizontal_m, 2),
                "median_vertical_m": None if self.median_vertical_m is None else round(self.median_vertical_m, 2),
                "convention": self.convention, "verdict": self.verdict, "explained_by": self.explained_by,
                "alternatives": {k: round(v, 2) for k, v in self.alternatives.items()}}

    def line(self) -> str:
        what = "horizontal" if self.horizontal_only else "3-D"
        out = (f"frame centre: {self.n} packets, {what} distance from ridgeloc's line of sight at the slant range "
               f"median {self.median_m:.1f} m, p95 {self.p95_m:.1f} m: {self.verdict}")
        if self.explained_by:
            out += f"; explained by: {self.explained_by} (median {self.alternatives[self.explained_by]:.1f} m)"
            if self.explained_by in SWITCH:
                out += f"; to read them so, set `{SWITCH[self.explained_by]}` in the flight config"
        return out


def _distances(lat, lon, h_ell, R: Rotation, range_m, c_lat, c_lon, c_h_ell) -> tuple[np.ndarray, np.ndarray]:
    """(horizontal, vertical) m of the line-of-sight end points from the frame centres, all (n,); vertical NaN
    where the centre has no height."""
    axis_ned = R.apply([1.0, 0.0, 0.0])
    end = ecef_from_lla(lat, lon, h_ell) + range_m[:, None] * np.einsum("nij,nj->ni", R_ecef_from_ned(lat, lon),
                                                                          axis_ned)
    ref_h = np.where(np.isfinite(c_h_ell), c_h_ell, 0.0)
    e, n, u = pymap3d.ecef2enu(end[:, 0], end[:, 1], end[:, 2], c_lat, c_lon, ref_h)
    return np.hypot(e, n), np.where(np.isfinite(c_h_ell), u, np.nan)


def _summary(horiz: np.ndarray, vert: np.ndarray) -> tuple[np.ndarray, bool]:
    has_v = np.isfinite(vert)
    if has_v.any():
        return np.hypot(horiz[has_v], vert[has_v]), False
    return horiz, True


def _conventions(table: KlvTable, m: np.ndarray) -> str:
    from pipeline.ingest.klv import SENSOR_CONVENTION

    eg = table.is_eg0104[m]
    out = ", ".join(f"{s}: {SENSOR_CONVENTION[s]}" for s, has in (("st0601", (~eg).any()), ("eg0104", eg.any()))
                    if has)
    return out + (", azimuths from UTM grid north" if table.azimuth_north == "grid" else "")


def check_frame_centre(table: KlvTable, max_packets: int | None = None) -> FrameCentreCheck | None:
    """The frame-centre check of decoded KLV packets, or None where no packet has everything it needs. Cost
    linear in the packets, times the (fixed) number of alternatives; `max_packets`: at most this many of them,
    evenly spaced (medians need no more)."""
    c = table.cols
    pos, alt, datum, _ = sensor_position(table)
    m = (pos & np.isfinite(c["sensor_az_deg"]) & np.isfinite(c["sensor_el_deg"]) & np.isfinite(c["slant_range_m"])
         & (np.nan_to_num(c["slant_range_m"]) > 0) & np.isfinite(c["centre_lat_deg"])
         & np.isfinite(c["centre_lon_deg"]))
    platform = np.isfinite(c["heading_deg"]) & np.isfinite(c["pitch_deg"]) & np.isfinite(c["roll_deg"])
    m &= platform | table.is_eg0104
    if not m.any():
        return None
    if max_packets is not None and m.sum() > max_packets:
        keep = np.flatnonzero(m)[np.linspace(0, m.sum() - 1, max_packets).round().astype(int)]
        m = np.zeros_like(m)
        m[keep] = True
    lat, lon = c["lat_deg"][m], c["lon_deg"][m]
    c_lat, c_lon = c["centre_lat_deg"][m], c["centre_lon_deg"][m]
    n_sensor, n_centre = geoid_undulation_m(lat, lon), geoid_undulation_m(c_lat, c_lon)  # EGM2008, cached area
    h_read = alt[m] + (n_sensor if datum == "amsl" else 0.0)  # the reader's datum, as ellipsoid height
    h_other = alt[m] + (0.0 if datum == "amsl" else -n_sensor)  # the other datum
    c_h = c["centre_alt_m"][m] + n_centre  # ST 0601 tag 25 and EG 0104: MSL
    rng = c["slant_range_m"][m]

    R = table_sensor_rotation(table, m)
    horiz, vert = _distances(lat, lon, h_read, R, rng, c_lat, c_lon, c_h)
    d, horizontal_only = _summary(horiz, vert)
    med = float(np.median(d))
    alternatives: dict[str, float] = {}
    full = m & platform
    for name, rot in ALTERNATIVES.items():
        if not full[m].all():
            if "earth-referenced" not in name:
                continue  # the platform's angles are missing in some packets: only the earth reading applies
        h2, v2 = _distances(lat, lon, h_read, rot(c, m), rng, c_lat, c_lon, c_h)
        alternatives[name] = float(np.median(_summary(h2, v2)[0]))
    R_true = table_sensor_rotation(table, m, north="true")  # the azimuths as logged, from true north
    if table.azimuth_north == "grid":
        h2, v2 = _distances(lat, lon, h_read, R_true, rng, c_lat, c_lon, c_h)
        alternatives[TRUE_NORTH] = float(np.median(_summary(h2, v2)[0]))
    else:
        grid = Rotation.from_euler("Z", np.radians(utm_convergence_deg(lat, lon))[:, None])
        h2, v2 = _distances(lat, lon, h_read, grid * R_true, rng, c_lat, c_lon, c_h)
        alternatives[GRID_NORTH] = float(np.median(_summary(h2, v2)[0]))
    if not horizontal_only:
        h2, v2 = _distances(lat, lon, h_other, R, rng, c_lat, c_lon, c_h)
        alternatives[HEIGHT_ALTERNATIVES[0]] = float(np.median(_summary(h2, v2)[0]))
        h2, v2 = _distances(lat, lon, h_read, R, rng, c_lat, c_lon, c["centre_alt_m"][m])
        alternatives[HEIGHT_ALTERNATIVES[1]] = float(np.median(_summary(h2, v2)[0]))
    explained = None
    if med <= CONSISTENT_M:
        verdict = "consistent (sensor rounding and terrain)"
    else:
        verdict = ("a convention error" if med > LARGE_M else "suspect: more than rounding") + \
            " in how the angles or heights are read"
        best = min(alternatives, key=alternatives.get, default=None)
        if best is not None and alternatives[best] < min(med / 2, max(CONSISTENT_M, med / 10)):
            explained = best
    return FrameCentreCheck(
        n=int(d.size), median_m=med, p95_m=float(np.percentile(d, 95)), horizontal_only=horizontal_only,
        median_horizontal_m=float(np.median(horiz)),
        median_vertical_m=None if horizontal_only else float(np.nanmedian(vert)),
        convention=_conventions(table, m), verdict=verdict, alternatives=alternatives, explained_by=explained)


def check_file(path, index=None, mapping: dict | None = None) -> FrameCentreCheck | None:
    """`check_frame_centre` of a full-motion video's KLV stream or a raw KLV dump (ST 0601 or EG 0104); `mapping`
    the `klv` reading options (`azimuth_north`)."""
    from pipeline.ingest.klv import read_klv_table

    table, _ = read_klv_table(path, index, mapping)
    return check_frame_centre(table)


def frame_centre_checks(log) -> list[tuple[str, FrameCentreCheck]]:
    """(file, check) for every KLV stream a flight's read log holds (`FlightLog.klv_tables`: raw KLV dumps and
    full-motion videos, decoded once by the reader) that has frame centres."""
    out = []
    for path, table in log.klv_tables.items():
        r = check_frame_centre(table)
        if r is not None:
            out.append((path, r))
    return out


def frame_centre_document(checks: list[tuple[str, FrameCentreCheck]]) -> dict | None:
    """The `frame_centre` entry of `ridgeloc check --json`: the first KLV file's check (n, median_m, p95_m, ...)
    with its "file", and "others" for any further KLV files; None without any."""
    if not checks:
        return None
    docs = [{"file": f, **r.to_dict()} for f, r in checks]
    return {**docs[0], "others": docs[1:]} if len(docs) > 1 else docs[0]


#: packets the azimuth_north "auto" decision looks at, at most (a 10-minute clip has 18,000)
AUTO_NORTH_PACKETS = 1000


def auto_north(table: KlvTable) -> tuple[str, str | None]:
    """`mapping: {klv: {azimuth_north: auto}}` (a full-motion video run alone, `ridgeloc run clip.ts`): for a table
    read from true north, "grid" where its frame-centre check finds the miss explained by a grid-north reading
    (`GRID_NORTH`, the rule `ridgeloc check` and `ridgeloc init` apply), else "true"; and a note saying which and
    why (None where the table has no frame centres to judge by)."""
    c = check_frame_centre(table, AUTO_NORTH_PACKETS)
    if c is None:
        return "true", None
    name = Path(table.source).name
    if c.explained_by == GRID_NORTH:
        return "grid", (f"{name}: azimuths read from UTM grid north (klv.azimuth_north: auto): the payload's frame "
                        f"centres lie {c.alternatives[GRID_NORTH]:.1f} m (median) from the line of sight read so, "
                        f"{c.median_m:.1f} m from it read from true north")
    return "true", None
