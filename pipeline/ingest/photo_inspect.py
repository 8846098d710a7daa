"""`ridgeloc inspect PHOTO...`: what each drone photo states (pose, intrinsics, laser, RTK), as text or a dict."""

from __future__ import annotations

import math
from datetime import datetime, timezone
from pathlib import Path

from pipeline.ingest.photo import PHOTO_SUFFIXES, Photo


def is_photo_input(path) -> bool:
    """A .jpg/.jpeg file, or a folder of photos: one holding a .jpg/.jpeg and no log, bag or video (a flight folder
    whose only JPEG is, say, a target template stays a flight folder)."""
    from pipeline.errors import RidgelocError
    from pipeline.ingest.dispatch import detect_format

    p = Path(path)
    if not p.is_dir():
        return p.suffix.lower() in PHOTO_SUFFIXES
    children = [c for c in p.iterdir() if c.is_file()]
    if not any(c.suffix.lower() in PHOTO_SUFFIXES for c in children) or (p / "metadata.yaml").is_file():
        return False
    for c in children:
        if c.suffix.lower() in PHOTO_SUFFIXES:
            continue
        try:
            detect_format(c)
        except RidgelocError:
            continue
        return False
    return True


def _time_text(p: Photo) -> str:
    if p.t_ns is None:
        return "no time (EXIF DateTimeOriginal and GPSDateStamp/GPSTimeStamp missing)"
    t = datetime.fromtimestamp(p.t_ns / 1e9, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]
    gps = "" if p.gps_t_ns is None else ", GPS time stamp " + datetime.fromtimestamp(
        p.gps_t_ns / 1e9, tz=timezone.utc).strftime("%H:%M:%S")
    if p.time_zone == "unknown":
        return f"{t} camera local time (time zone unknown: no EXIF OffsetTimeOriginal, no GPS time stamp)"
    if p.time_zone.startswith(("UTC", "+", "-")) and "(" in p.time_zone:
        return f"{t} UTC (time zone {p.time_zone}{gps})"
    return f"{t} UTC (OffsetTimeOriginal {p.time_zone}{gps})"


def _num(v: float, fmt: str = ".2f") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def format_photo(p: Photo) -> str:
    rel = (f"{p.relative_alt_m:.2f} m above the take-off point ({p.relative_alt_source.split(' (')[0]}), take-off "
           f"ground {p.takeoff_ground_m:.2f} m {p.alt_datum}" if math.isfinite(p.relative_alt_m)
           else "no height above the take-off point")
    lines = [f"{p.path}  [photo {p.make} {p.model} {p.width_px}x{p.height_px}]",
             f"  time: {_time_text(p)}",
             f"  position: {p.lat_deg:.7f} {p.lon_deg:.7f}, altitude {p.alt_m:.2f} m {p.alt_datum} ({p.alt_source}; "
             + ("" if p.alt_source.startswith("EXIF GPSAltitude") else f"EXIF GPSAltitude {_num(p.gps_alt_m)} m; ")
             + f"{rel})"]
    g, f = p.gimbal_ypr_deg, p.flight_ypr_deg
    # yaws from north in [0, 360), whichever range the tags use, so the aircraft's and the gimbal's compare
    body = "aircraft -" if f is None else f"aircraft {f[0] % 360:.2f} {f[1]:.2f} {f[2]:.2f}"
    lines.append(f"  attitude (yaw 0-360 from north, pitch, roll deg, NED): gimbal {g[0] % 360:.2f} {g[1]:.2f} "
                 f"{g[2]:.2f}; {body} ({p.maker} tags: {p.attitude_source})")
    k = p.intrinsics
    if k is None:
        lines.append("  intrinsics: none (no calibrated tags, database entry or 35 mm focal length)")
    else:
        lines.append(f"  intrinsics: fx {k.fx_px:.1f} fy {k.fy_px:.1f} cx {k.cx_px:.1f} cy {k.cy_px:.1f} px, "
                     f"k1 k2 p1 p2 k3 {' '.join(f'{d:.4g}' for d in k.dist)} ({k.source})")
    if p.lrf_status or not math.isnan(p.lrf_range_m):
        lines.append(f"  laser: {_num(p.lrf_range_m, '.3f')} m, LRFStatus {p.lrf_status or '-'} "
                     f"({'valid' if p.lrf_valid else 'not used'})")
    else:
        lines.append("  laser: none")
    if p.dji_target_lla is not None:
        t = p.dji_target_lla
        lines.append(f"  dji target (LRFTargetLat/Lon/AbsAlt): {t[0]:.7f} {t[1]:.7f} {t[2]:.2f} m {p.alt_datum}")
    if p.rtk_flag is not None:
        std = "-" if p.rtk_std_m is None else " ".join(f"{v:.3f}" for v in p.rtk_std_m)
        lines.append(f"  rtk: RtkFlag {p.rtk_flag}, RtkStdLon/Lat/Hgt {std} m")
    lines += [f"  warning: {w}" for w in p.warnings]
    return "\n".join(lines)


def photo_as_dict(p: Photo) -> dict:
    def clean(v):
        return None if isinstance(v, float) and math.isnan(v) else v

    k = p.intrinsics
    return {"path": p.path, "format": "photo", "make": p.make, "model": p.model, "width_px": p.width_px,
            "height_px": p.height_px, "t_ns": p.t_ns, "time_zone": p.time_zone, "gps_t_ns": p.gps_t_ns,
            "lat_deg": p.lat_deg, "lon_deg": p.lon_deg, "alt_m": p.alt_m, "alt_datum": p.alt_datum,
            "alt_source": p.alt_source, "maker": p.maker,
            "relative_alt_m": clean(p.relative_alt_m), "relative_alt_source": p.relative_alt_source,
            "takeoff_ground_m": clean(p.takeoff_ground_m), "gps_alt_m": clean(p.gps_alt_m),
            "resaved_by": p.resaved_by, "exif_orientation": p.orientation,
            "gimbal_ypr_deg": list(p.gimbal_ypr_deg),
            "flight_ypr_deg": None if p.flight_ypr_deg is None else list(p.flight_ypr_deg),
            "attitude_source": p.attitude_source,
            "intrinsics": None if k is None else {"fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px,
                                                  "cy_px": k.cy_px, "dist": list(k.dist), "source": k.source},
            "lrf_range_m": clean(p.lrf_range_m), "lrf_status": p.lrf_status, "lrf_valid": p.lrf_valid,
            "dji_target_lla": None if p.dji_target_lla is None else list(p.dji_target_lla),
            "rtk_flag": p.rtk_flag, "rtk_std_m": None if p.rtk_std_m is None else list(p.rtk_std_m),
            "warnings": list(p.warnings)}
