"""Intrinsics of a drone photo, in order of precedence (docs/ingest.md, "Drone photos"):

1. The maker's calibrated tags (pipeline.ingest.photo_makers.Calibration): DJI's `drone-dji:CalibratedFocalLength`
   (px), `CalibratedOpticalCenterX/Y` (px), the distortion from `drone-dji:DewarpData`
   ("date;fx,fy,cx,cy,k1,k2,p1,p2,k3", cx/cy offsets from the image centre in px), else from the camera database,
   else none (DewarpData alone gives K too); Skydio's `CalibratedFocalLength` and `CalibratedOpticalCenter` (in the
   full sensor's pixels). Scaled to the stored image when it was resized after capture; a principal point is kept
   as its offset from the frame's centre when the frames differ (a centred crop, as a 16:9 photo of a 4:3 sensor).
   A stated field of view (Teal's `exif:CameraHorizontalFOV/VerticalFOV`) comes next: fx = w / (2 tan(hfov / 2)).
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
    if isinstance(value, str):
        value = value.strip().rstrip("dD")  # some entries keep Java's double suffix: "7.68d/640.0d"
        if "/" in value:
            num, den = value.split("/", 1)
            return float(Fraction(num.strip().rstrip("dD"))) / float(Fraction(den.strip()))
    return float(value)


def database_entry(make: str, model: str, thermal: bool = False) -> dict | None:
    """The entry for an EXIF make and model (key: make lower-case + model upper-case, e.g. djiFC300S), visible-light
    or thermal (`isThermal`)."""
    return camera_database().get((make.strip().lower() + model.strip().upper(), bool(thermal)))


def parse_dewarp(text: str) -> tuple[float, ...] | None:
    """(fx, fy, dcx, dcy, k1, k2, p1, p2, k3) of a DewarpData value, or None when it is not nine finite numbers."""
    body = text.split(";", 1)[1] if ";" in text else text
    try:
        values = tuple(float(v) for v in body.split(","))
    except ValueError:
        return None
    return values if len(values) == 9 and np.isfinite(values).all() else None


def dji_calibration(dji: dict, camera_size_px: tuple[int, int], warnings: list[str]):
    """The calibrated intrinsics of drone-dji tags (`dji`: values by name) in the camera's frame `camera_size_px`
    (w, h): CalibratedFocalLength + CalibratedOpticalCenterX/Y with DewarpData's distortion, or DewarpData alone
    (its cx, cy offsets from the frame's centre). None without them."""
    from pipeline.ingest.photo_makers import Calibration

    dewarp = parse_dewarp(dji["DewarpData"]) if "DewarpData" in dji else None
    if "DewarpData" in dji and dewarp is None:
        warnings.append("drone-dji:DewarpData is not nine numbers: ignored")
    f = _finite(dji.get("CalibratedFocalLength"))
    if f is not None and f > 0:
        cx, cy = _finite(dji.get("CalibratedOpticalCenterX")), _finite(dji.get("CalibratedOpticalCenterY"))
        return Calibration(f, f, cx, cy, camera_size_px, None if dewarp is None else tuple(dewarp[4:]),
                           "drone-dji Calibrated*" + (" + DewarpData" if dewarp is not None else ""))
    if dewarp is not None and dewarp[0] > 0 and dewarp[1] > 0:
        w, h = camera_size_px
        return Calibration(dewarp[0], dewarp[1], w / 2.0 + dewarp[2], h / 2.0 + dewarp[3], camera_size_px,
                           tuple(dewarp[4:]), "drone-dji DewarpData")
    return None


#: a stated principal point further than this fraction of the frame from its centre is not in that frame's pixels
PRINCIPAL_POINT_MAX_OFFSET = 0.1


def photo_intrinsics(width_px: int, height_px: int, make: str, model: str, calibration=None, fov_deg=None,
                     focal_mm: float | None = None, focal_35mm: float | None = None, warnings: list[str] | None = None,
                     camera_size_px: tuple[int, int] | None = None, thermal: bool = False) -> PhotoIntrinsics | None:
    """Intrinsics of the stored image (width_px x height_px) from, in order: the maker's calibrated tags
    (`calibration`, photo_makers.Calibration, scaled from its frame to the image), the stated field of view
    `fov_deg` (h, v), the database entry of make + model (thermal or visible) with EXIF FocalLength, the 35 mm
    focal length. `camera_size_px`: the camera's frame (EXIF PixelX/YDimension) when the image was resized after
    capture. None when nothing applies. Appends notes to `warnings`."""
    warnings = [] if warnings is None else warnings
    cx0, cy0 = (width_px - 1) / 2.0, (height_px - 1) / 2.0
    entry = database_entry(make, model, thermal)
    db_dist = None
    if entry is not None:
        if entry.get("lensType", "perspective") == "perspective":
            db_dist = tuple(float(entry.get(k, 0.0)) for k in ("radialR1", "radialR2", "tangentialT1",
                                                                "tangentialT2", "radialR3"))
        else:
            warnings.append(f"camera database entry {entry['makeModel']} is a {entry.get('lensType')} lens: "
                            "its distortion is not applied")
    c = calibration
    if c is not None and c.fx_px > 0 and c.fy_px > 0:
        ref_w, ref_h = c.ref_size_px or camera_size_px or (width_px, height_px)
        s = width_px / ref_w
        if c.cx_px is None or c.cy_px is None:
            cx, cy = cx0, cy0
        elif (ref_w, ref_h) == (width_px, height_px):
            cx, cy = c.cx_px, c.cy_px
        elif (abs(c.cx_px - ref_w / 2.0) > PRINCIPAL_POINT_MAX_OFFSET * ref_w
              or abs(c.cy_px - ref_h / 2.0) > PRINCIPAL_POINT_MAX_OFFSET * ref_h):
            warnings.append(f"{c.source}: the principal point ({c.cx_px:g}, {c.cy_px:g}) is not near the centre of "
                            f"a {ref_w}x{ref_h} frame: the image centre is used")
            cx, cy = cx0, cy0
        else:  # an offset from the centre, kept through a centred crop and scaled with the image
            cx, cy = cx0 + (c.cx_px - (ref_w - 1) / 2.0) * s, cy0 + (c.cy_px - (ref_h - 1) / 2.0) * s
        source = c.source + (f" (scaled by {s:.4g} from {ref_w}x{ref_h} px)" if s != 1.0 else "")
        if c.dist is not None:
            dist = c.dist
        elif db_dist is not None:
            dist, source = db_dist, f"{source} + database {entry['makeModel']}"
        else:
            dist, source = (0.0,) * 5, f"{source} (no distortion stated)"
        return PhotoIntrinsics(c.fx_px * s, c.fy_px * s, cx, cy, tuple(float(d) for d in dist), source)
    if fov_deg is not None and 0 < fov_deg[0] < 180:
        fx = width_px / (2.0 * np.tan(np.radians(fov_deg[0]) / 2.0))
        fy = height_px / (2.0 * np.tan(np.radians(fov_deg[1]) / 2.0)) if 0 < fov_deg[1] < 180 else fx
        return PhotoIntrinsics(float(fx), float(fy), cx0, cy0, (0.0,) * 5,
                               "stated field of view (exif:CameraHorizontalFOV/VerticalFOV; no distortion)")
    if entry is not None:
        try:
            fm = focal_mm if focal_mm else (_number(entry["focalLength"]) if "focalLength" in entry else None)
            pitch_w, pitch_h = _number(entry["ccdWidthMMPerPixel"]), _number(entry["ccdHeightMMPerPixel"])
            full_w = float(entry["widthPixels"])
        except (KeyError, ValueError, ZeroDivisionError):
            fm = None
        if fm and pitch_w > 0 and pitch_h > 0 and full_w > 0:
            scale = width_px / full_w  # a downscaled image has proportionally larger pixels
            return PhotoIntrinsics(fm / pitch_w * scale, fm / pitch_h * scale, cx0, cy0, db_dist or (0.0,) * 5,
                                   f"database {entry['makeModel']}{' (thermal)' if thermal else ''} + EXIF FocalLength")
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
