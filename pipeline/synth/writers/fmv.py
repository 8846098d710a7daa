"""STANAG 4609 full-motion video: H.264 frames and MISB ST 0601 KLV packets in one MPEG-TS, written with PyAV.

One KLV packet per video frame, with that frame's PTS (synchronous carriage as FMV encoders do), encoded by the
`stanag4609` library (tag 2 first, checksum tag 1 last). The telemetry is interpolated to the frame times from
the noisy logged series: position (tags 13/14, 75 ellipsoid height and 15 true altitude MSL), platform heading/
pitch/roll (5/6/7, or 90/91 for pitch and roll beyond 6/7's +-20/+-50 deg), the sensor's azimuth/elevation/roll
relative to the platform (18/19/20), the field of view of the frame's zoom (16/17) and, on frames where the laser
fired, its range as the slant range (21) and the frame centre (23/24/25) where the optical axis reaches at that
range (pymap3d's aer2geodetic from the logged attitude; elevation MSL), as a payload computes it.
`sensor_angles="earth"` writes a deliberate convention error: tags 18/19/20 earth-referenced (azimuth from true
north, elevation from the horizon) instead of relative to the platform, the frame centre still the true one.
"""

from __future__ import annotations

from collections.abc import Iterable
from fractions import Fraction
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

TS_TIME_BASE = Fraction(1, 90000)
UAS_LS_VERSION = 19


def _interp_rot(t_src: np.ndarray, q_wxyz: np.ndarray, t: np.ndarray) -> Rotation:
    rots = Rotation.from_quat(q_wxyz, scalar_first=True)
    tt = np.clip(t, t_src[0], t_src[-1])
    return Slerp((t_src - t_src[0]).astype(float), rots)((tt - t_src[0]).astype(float))


def klv_packets(tel, t_ns: np.ndarray, camera: tuple[int, int, float, float], zoom: np.ndarray,
                geoid_separation_m: float, sensor_angles: str = "platform") -> list[bytes]:
    """ST 0601 packets at telemetry times t_ns (n,) (UNIX ns): camera (width, height, fx, fy) px at zoom 1,
    zoom (n,) factors. The gimbal series must be earth-referenced. sensor_angles: "platform" (the standard) or
    "earth" (a deliberate convention error, see the module docstring)."""
    import pymap3d
    from stanag4609 import st0601

    t_ns = np.asarray(t_ns, dtype=np.int64)
    lla = np.column_stack([np.interp(t_ns, tel.gps_t_ns, tel.gps_lla[:, i]) for i in range(3)])
    R_body = _interp_rot(tel.att_t_ns, tel.att_quat_wxyz, t_ns)
    R_gim = _interp_rot(tel.gimbal_t_ns, tel.gimbal_quat_wxyz, t_ns)
    hpr = R_body.as_euler("ZYX", degrees=True)
    aer = (R_body.inv() * R_gim if sensor_angles == "platform" else R_gim).as_euler("ZYX", degrees=True)
    axis_ned = R_gim.apply([1.0, 0.0, 0.0])
    axis_az = np.degrees(np.arctan2(axis_ned[:, 1], axis_ned[:, 0]))
    axis_el = np.degrees(np.arcsin(np.clip(-axis_ned[:, 2], -1.0, 1.0)))
    w, h, fx, fy = camera
    hfov = np.degrees(2 * np.arctan(w / (2 * fx * zoom)))
    vfov = np.degrees(2 * np.arctan(h / (2 * fy * zoom)))
    shots = {int(t): float(r) for t, r in zip(tel.laser_t_ns, tel.laser_range_m, strict=True)}
    out = []
    for i, t in enumerate(t_ns.tolist()):
        values = {2: t // 1000, 65: UAS_LS_VERSION,
                  5: float(hpr[i, 0] % 360.0),
                  13: float(lla[i, 0]), 14: float(lla[i, 1]), 15: float(lla[i, 2] - geoid_separation_m),
                  16: float(hfov[i]), 17: float(vfov[i]),
                  18: float(aer[i, 0] % 360.0), 19: float(aer[i, 1]), 20: float(aer[i, 2] % 360.0),
                  75: float(lla[i, 2])}
        # pitch and roll in tags 6/7 where they fit (+-20, +-50 deg), else in the full-range tags 90/91
        values[6 if abs(hpr[i, 1]) <= 20 else 90] = float(hpr[i, 1])
        values[7 if abs(hpr[i, 2]) <= 50 else 91] = float(hpr[i, 2])
        r = shots.get(t)
        if r is not None and np.isfinite(r) and 0 <= r <= 5_000_000:
            values[21] = r
            c_lat, c_lon, c_h = pymap3d.aer2geodetic(axis_az[i], axis_el[i], r, *lla[i])
            values.update({23: float(c_lat), 24: float(c_lon), 25: float(c_h - geoid_separation_m)})
        out.append(st0601.encode_uas_local_set(values))
    return out


def write_fmv(path: Path, frames: Iterable[np.ndarray], pts_ns: np.ndarray, klv: list[tuple[int, bytes]], fps: int,
              size_px: tuple[int, int], preset: str = "medium", crf: int = 23, gop: int | None = None) -> int:
    """Write BGR uint8 frames (h, w, 3) at video times pts_ns (n,) as H.264 and the KLV packets [(pts_ns, bytes)]
    as a KLV data stream, into an MPEG-TS at `path`; returns the frame count."""
    import av

    def ticks(t_ns: int) -> int:
        return round(Fraction(int(t_ns), 10**9) / TS_TIME_BASE)

    pts_ns = np.asarray(pts_ns, dtype=np.int64)
    klv = sorted(klv, key=lambda p: p[0])
    n = k = 0
    with av.open(str(path), "w", format="mpegts") as out:
        vs = out.add_stream("libx264", rate=fps)
        vs.width, vs.height = size_px
        vs.pix_fmt = "yuv420p"
        vs.time_base = TS_TIME_BASE
        vs.codec_context.time_base = TS_TIME_BASE
        vs.options = {"preset": preset, "crf": str(crf), "g": str(gop or 2 * fps)}
        ds = out.add_data_stream(codec_name="klv")
        ds.time_base = TS_TIME_BASE

        def mux_klv_until(limit_ns: int | None) -> None:
            nonlocal k
            while k < len(klv) and (limit_ns is None or klv[k][0] <= limit_ns):
                pkt = av.Packet(klv[k][1])
                pkt.stream = ds
                pkt.pts = pkt.dts = ticks(klv[k][0])
                pkt.time_base = TS_TIME_BASE
                out.mux(pkt)
                k += 1

        for img in frames:
            if n >= len(pts_ns):
                raise RuntimeError(f"more frames than the {len(pts_ns)} timestamps")
            mux_klv_until(int(pts_ns[n]))
            frame = av.VideoFrame.from_ndarray(img, format="bgr24")
            frame.pts = ticks(int(pts_ns[n]))
            frame.time_base = TS_TIME_BASE
            out.mux(vs.encode(frame))
            n += 1
        out.mux(vs.encode(None))
        mux_klv_until(None)
    if n != len(pts_ns):
        raise RuntimeError(f"wrote {n} frames but have {len(pts_ns)} timestamps")
    return n
