"""Intrinsics of a drone photo, in order of precedence (docs/ingest.md, "Drone photos"):

1. DJI's calibrated tags: `drone-dji:CalibratedFocalLength` (px), `CalibratedOpticalCenterX/Y` (px); the
   distortion from `drone-dji:DewarpData` ("date;fx,fy,cx,cy,k1,k2,p1,p2,k3", cx/cy offsets from the image
   centre in px), else from the camera database, else none. Without the calibrated tags, DewarpData alone gives
   K too.
2. The camera database droneModels.json (OpenAthena's, Apache 2.0, shipped in photo_data/): EXIF FocalLength (mm)
   over the pixel pitch (mm/px) of the EXIF make + model, scaled by image width / the database's full width;
   principal point at the image centre; OpenCV k1 k2 p1 p2 k3 = radialR1 R2 tangentialT1 T2 radialR3
   (perspective lenses only; a fisheye entry gives no distortion and a warning).
3. EXIF FocalLengthIn35mmFilm: fx = fy = f35 * image diagonal (px) / 43.27 mm (the CIPA definition: the
   equivalent focal length of the same diagonal field of view); principal point at the centre; no distortion.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from fractions import Fraction
from importlib import resources

import numpy as np

FULL_FRAME_DIAGONAL_MM = float(np.hypot(36.0, 24.0))  # 43.27 mm


@dataclass(frozen=True)
class PhotoIntrinsics:
    """fx, fy, cx, cy in px (pixel centres at integers), dist OpenCV (k1, k2, p1, p2, k3), and where they came from."""

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    dist: tuple[float, float, float, float, float]
    source: str

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])


@functools.cache
def camera_database() -> dict[tuple[str, bool], dict]:
    """droneModels.json entries keyed by (makeModel, isThermal)."""
    text = resources.files("pipeline.ingest").joinpath("photo_data", "droneModels.json").read_text()
    return {(e["makeModel"], bool(e.get("isThermal", False))): e for e in json.loads(text)["droneCCDParams"]}


def _number(value) -> float:
    """A database number, written as a float or a fraction string ("6.3175/4000.0")."""
    if isinstance(value, str) and "/" in value:
        num, den = value.split("/", 1)
        return float(Fraction(num.strip())) / float(Fraction(den.strip()))
    return float(value)


def database_entry(make: str, model: str) -> dict | None:
    """The visible-light entry for an EXIF make and model (key: make lower-case + model upper-case, e.g. djiFC300S)."""
    return camera_database().get((make.strip().lower() + model.strip().upper(), False))


def parse_dewarp(text: str) -> tuple[float, ...] | None:
    """(fx, fy, dcx, dcy, k1, k2, p1, p2, k3) of a DewarpData value, or None when it is not nine finite numbers."""
    body = text.split(";", 1)[1] if ";" in text else text
    try:
        values = tuple(float(v) for v in body.split(","))
    except ValueError:
        return None
    return values if len(values) == 9 and np.isfinite(values).all() else None


def photo_intrinsics(width_px: int, height_px: int, make: str, model: str, dji: dict, focal_mm: float | None,
                     focal_35mm: float | None, warnings: list[str]) -> PhotoIntrinsics | None:
    """Intrinsics from the tags (`dji`: drone-dji XMP values by name), the database, or the 35 mm focal length;
    None when none applies. Appends notes to `warnings`."""
    cx0, cy0 = (width_px - 1) / 2.0, (height_px - 1) / 2.0
    entry = database_entry(make, model)
    db_dist = None
    if entry is not None:
        if entry.get("lensType", "perspective") == "perspective":
            db_dist = tuple(float(entry.get(k, 0.0)) for k in ("radialR1", "radialR2", "tangentialT1",
                                                                "tangentialT2", "radialR3"))
        else:
            warnings.append(f"camera database entry {entry['makeModel']} is a {entry.get('lensType')} lens: "
                            "its distortion is not applied")
    dewarp = parse_dewarp(dji["DewarpData"]) if "DewarpData" in dji else None
    if "DewarpData" in dji and dewarp is None:
        warnings.append("drone-dji:DewarpData is not nine numbers: ignored")
    f = _finite(dji.get("CalibratedFocalLength"))
    cx, cy = _finite(dji.get("CalibratedOpticalCenterX")), _finite(dji.get("CalibratedOpticalCenterY"))
    if f is not None and f > 0:
        cxv = cx if cx is not None else cx0
        cyv = cy if cy is not None else cy0
        if dewarp is not None:
            return PhotoIntrinsics(f, f, cxv, cyv, tuple(dewarp[4:]), "drone-dji Calibrated* + DewarpData")
        if db_dist is not None:
            return PhotoIntrinsics(f, f, cxv, cyv, db_dist, f"drone-dji Calibrated* + database {make}{model}")
        return PhotoIntrinsics(f, f, cxv, cyv, (0.0,) * 5, "drone-dji Calibrated* (no distortion stated)")
    if dewarp is not None and dewarp[0] > 0 and dewarp[1] > 0:
        return PhotoIntrinsics(dewarp[0], dewarp[1], width_px / 2.0 + dewarp[2], height_px / 2.0 + dewarp[3],
                               tuple(dewarp[4:]), "drone-dji DewarpData")
    if entry is not None:
        fm = focal_mm if focal_mm else (_number(entry["focalLength"]) if "focalLength" in entry else None)
        pitch_w, pitch_h = _number(entry["ccdWidthMMPerPixel"]), _number(entry["ccdHeightMMPerPixel"])
        full_w = float(entry["widthPixels"])
        if fm and pitch_w > 0 and pitch_h > 0 and full_w > 0:
            scale = width_px / full_w  # a downscaled image has proportionally larger pixels
            return PhotoIntrinsics(fm / pitch_w * scale, fm / pitch_h * scale, cx0, cy0, db_dist or (0.0,) * 5,
                                   f"database {entry['makeModel']} + EXIF FocalLength")
    if focal_35mm and focal_35mm > 0:
        f = focal_35mm * float(np.hypot(width_px, height_px)) / FULL_FRAME_DIAGONAL_MM
        return PhotoIntrinsics(f, f, cx0, cy0, (0.0,) * 5, "EXIF FocalLengthIn35mmFilm (no distortion)")
    return None


def _finite(value) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) else None
