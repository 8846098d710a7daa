"""The pose tags of each drone maker's photos, read into one convention (docs/ingest.md, "Drone photos: makers").

Every reader returns a `MakerPose` whose `gimbal_ypr_deg` is DJI's convention whatever the maker wrote: the ZYX
(yaw, pitch, roll) Euler angles of the camera's FRD frame (x along the optical axis, y to the image's right, z to
its bottom) in the local NED frame, yaw from true north, pitch -90 straight down. A maker whose angles mean something
else (Pix4D's Camera: tags, pitch 0 at nadir; Teal's camera angles relative to the aircraft) is turned into that
frame here, through the rotation, never by adding angles.

Readers, tried in this order (`read_maker_pose`):
- Skydio: `drone-skydio:CameraOrientationNED` (earth-referenced, ZYX of the camera FRD frame in NED; its
  quaternion `CameraOrientationQuatNED` is checked against it), `Latitude/Longitude/AbsoluteAltitude` (AMSL),
  `CalibratedFocalLength`, `CalibratedOpticalCenter` (pixels of the full sensor).
- DJI's `drone-dji:` namespace (DJI, Hasselblad-branded DJI cameras, and Autel's newer firmware, which writes the
  same namespace URI under the prefix `drone:`): `Gimbal*/Flight*Degree`, `AbsoluteAltitude`, `RelativeAltitude`.
- Parrot (Anafi family): `drone-parrot:CameraYaw/Pitch/RollDegree` (earth-referenced, DJI's convention),
  `DroneYaw/Pitch/RollDegree`; altitude from EXIF GPSAltitude (AMSL; ellipsoidal on the Anafi Ai).
- Pix4D's `Camera:Yaw/Pitch/Roll` (Autel's older firmware under Pix4D's URI; Parrot's Disco and Bebop under the
  URI `Camera/`): pitch 0 looks straight down, 90 forward; yaw 0 puts the image's top to the north at nadir.
- Teal / Teledyne FLIR: `exif:CameraYaw/Pitch/Roll` relative to the aircraft, `exif:PlatformYaw/Pitch/Roll`
  the aircraft's (ZYX, NED), written as rationals ("-86831/1600"); `exif:CameraHorizontalFOV/VerticalFOV`.
"""

from __future__ import annotations

import math
import warnings as warnings_module
from dataclasses import dataclass, field

import numpy as np

NS_DJI = "http://www.dji.com/drone-dji/1.0/"
NS_SKYDIO = "https://www.skydio.com/drone-skydio/1.0/"
NS_PARROT = "http://www.parrot.com/drone-parrot/1.0/"
NS_PIX4D = "http://pix4d.com/camera/1.0/"
NS_PARROT_CAMERA = "Camera/"  # the URI Parrot's Disco/Bebop firmware declares for Pix4D's Camera: tags
NS_EXIF_XMP = "http://ns.adobe.com/exif/1.0/"  # Teal writes its pose here, beside the standard exif: properties
NS_RDF = "http://www.w3.org/1999/02/22-rdf-syntax-ns#"

#: what a photo with no readable pose was searched for (the one-line refusal lists it)
POSE_TAGS_LOOKED_FOR = ("drone-dji:Gimbal*Degree, DJI MakerNote CameraYaw/Pitch/Roll, "
                        "drone-skydio:CameraOrientationNED, drone-parrot:Camera*Degree, Camera:Yaw/Pitch/Roll "
                        "(Pix4D), exif:CameraYaw/Pitch/Roll (Teal)")


@dataclass(frozen=True)
class Calibration:
    """A camera's stated intrinsics: fx, fy (px), principal point (cx, cy) (px, None: the image centre) in the
    pixels of a frame `ref_size_px` (w, h) (None: the camera's own frame, EXIF PixelX/YDimension), distortion
    (OpenCV k1 k2 p1 p2 k3, None: not stated), and the tags they came from."""

    fx_px: float
    fy_px: float
    cx_px: float | None
    cy_px: float | None
    ref_size_px: tuple[int, int] | None
    dist: tuple[float, ...] | None
    source: str


@dataclass
class MakerPose:
    """One photo's pose as its maker's tags state it, in DJI's convention (module docstring). NaN where the tags
    say nothing (the caller falls back to EXIF GPS). alt_datum: "amsl" or "ellipsoid", the maker's documented or
    verified datum (docs/ingest.md)."""

    maker: str
    gimbal_ypr_deg: tuple[float, float, float]
    flight_ypr_deg: tuple[float, float, float] | None
    attitude_source: str
    alt_datum: str
    lat_deg: float = math.nan
    lon_deg: float = math.nan
    alt_m: float = math.nan
    alt_source: str = ""
    relative_alt_m: float = math.nan
    relative_alt_source: str = ""
    calibration: Calibration | None = None
    fov_deg: tuple[float, float] | None = None  # (horizontal, vertical; NaN: not stated) of the stored image
    thermal: bool = False
    notes: list[str] = field(default_factory=list)


def number(value) -> float:
    """A tag's number: "12.5", "+12.5", a rational "-86831/1600", NaN when none of these or not finite."""
    text = str(value if value is not None else "").strip()
    try:
        if "/" in text:
            num, den = text.split("/", 1)
            v = float(num) / float(den)
        else:
            v = float(text)
    except (ValueError, ZeroDivisionError, OverflowError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def _finite(values) -> bool:
    return all(math.isfinite(v) for v in values)


def _ypr_from_rotation(R) -> tuple[float, float, float]:
    """(yaw, pitch, roll) degrees, ZYX, of a rotation (scipy Rotation) FRD -> NED; at pitch +-90 the yaw carries
    the whole heading (roll 0), which is the same rotation."""
    with warnings_module.catch_warnings():
        warnings_module.simplefilter("ignore")  # scipy's gimbal-lock notice: the angles still give the rotation
        yaw, pitch, roll = R.as_euler("ZYX", degrees=True)
    return float(yaw), float(pitch), float(roll)


def _rotation_ypr(yaw_deg, pitch_deg, roll_deg):
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("ZYX", [yaw_deg, pitch_deg, roll_deg], degrees=True)


def gimbal_from_pix4d(yaw_deg: float, pitch_deg: float, roll_deg: float) -> tuple[float, float, float]:
    """DJI-convention gimbal (yaw, pitch, roll) of Pix4D's camera angles: Pix4D's camera frame (x to the image's
    right, y to its bottom, lens down) at zero angles is the body's (right wing, tail, down), rotated by
    Rz(yaw) Ry(pitch) Rx(roll); the camera FRD frame is Pix4D's frame turned by Ry(-90) (pitch 0: nadir)."""
    from scipy.spatial.transform import Rotation

    R = _rotation_ypr(yaw_deg, pitch_deg, roll_deg) * Rotation.from_euler("y", -90.0, degrees=True)
    return _ypr_from_rotation(R)


def gimbal_from_body_relative(camera_ypr_deg, platform_ypr_deg) -> tuple[float, float, float]:
    """Earth-referenced gimbal (yaw, pitch, roll) of a camera whose ZYX angles are relative to the aircraft body,
    itself at ZYX `platform_ypr_deg` in NED: R_ned_from_camera = R_ned_from_body R_body_from_camera."""
    R = _rotation_ypr(*platform_ypr_deg) * _rotation_ypr(*camera_ypr_deg)
    return _ypr_from_rotation(R)


# ---- readers --------------------------------------------------------------------------------------------------

YPR = ("Yaw", "Pitch", "Roll")


def _in(xmp: dict, ns: str) -> dict[str, str]:
    """The properties of one namespace, by local name."""
    return {name: v for (n, name), v in xmp.items() if n == ns}


def _angles(tags: dict, pattern: str = "{}") -> tuple[float, float, float]:
    """(yaw, pitch, roll) of the tags named pattern.format("Yaw"), ... (NaN where absent or not a number)."""
    return tuple(number(tags.get(pattern.format(a))) for a in YPR)


def _dji(xmp: dict, make: str, model: str) -> MakerPose | None:
    dji = _in(xmp, NS_DJI)
    gimbal = _angles(dji, "Gimbal{}Degree")
    if not _finite(gimbal):
        return None
    body = _angles(dji, "Flight{}Degree")
    autel = make.strip().lower().startswith("autel")
    pose = MakerPose(maker="Autel" if autel else "DJI", gimbal_ypr_deg=gimbal,
                     flight_ypr_deg=body if _finite(body) else None,
                     attitude_source="drone-dji XMP Gimbal*/Flight*Degree (earth-referenced)",
                     alt_datum="ellipsoid" if autel else "amsl",
                     lat_deg=number(dji.get("GpsLatitude", dji.get("Latitude"))),
                     lon_deg=number(dji.get("GpsLongitude", dji.get("GpsLongtitude", dji.get("Longitude")))))
    abs_alt = number(dji.get("AbsoluteAltitude"))
    if math.isfinite(abs_alt):
        pose.alt_m, pose.alt_source = abs_alt, "drone-dji:AbsoluteAltitude"
    rel = number(dji.get("RelativeAltitude"))
    if math.isfinite(rel):
        pose.relative_alt_m, pose.relative_alt_source = rel, "drone-dji:RelativeAltitude (above the take-off point)"
    source = dji.get("ImageSource", "").lower()
    pose.thermal = "infrared" in source or "thermal" in source
    return pose


def _children(el) -> dict[str, str]:
    """Local name -> text of a struct element's fields: its attributes, its simple children, or the attributes
    and children of an rdf:Description inside it (rdf:parseType="Resource" and the nested form)."""
    out: dict[str, str] = {}
    for key, value in el.attrib.items():
        if key.startswith("{") and not key.startswith("{" + NS_RDF):
            out.setdefault(key.split("}", 1)[1], value)
    for child in el:
        tag = child.tag if isinstance(child.tag, str) else ""
        if not tag.startswith("{"):
            continue
        ns, name = tag[1:].split("}", 1)
        if ns == NS_RDF and name == "Description":
            out.update({k: v for k, v in _children(child).items() if k not in out})
        elif len(child) == 0 and child.text and child.text.strip():
            out.setdefault(name, child.text.strip())
    return out


def _struct(root, ns: str, name: str) -> dict[str, str]:
    """The fields of the first element {ns}name in the XMP tree (empty when there is none)."""
    if root is None:
        return {}
    el = root.find(f".//{{{ns}}}{name}")
    return _children(el) if el is not None else {}


def _skydio(xmp: dict, root) -> MakerPose | None:
    cam = _struct(root, NS_SKYDIO, "CameraOrientationNED")
    gimbal = _angles(cam)
    if not _finite(gimbal):
        return None
    body = _angles(_struct(root, NS_SKYDIO, "VehicleOrientationNED"))
    sk = _in(xmp, NS_SKYDIO)
    pose = MakerPose(maker="Skydio", gimbal_ypr_deg=gimbal, flight_ypr_deg=body if _finite(body) else None,
                     attitude_source="drone-skydio:CameraOrientationNED/VehicleOrientationNED (earth-referenced)",
                     alt_datum="amsl", lat_deg=number(sk.get("Latitude")), lon_deg=number(sk.get("Longitude")))
    abs_alt = number(sk.get("AbsoluteAltitude"))
    if math.isfinite(abs_alt):
        pose.alt_m, pose.alt_source = abs_alt, "drone-skydio:AbsoluteAltitude"
    quat = _struct(root, NS_SKYDIO, "CameraOrientationQuatNED")
    q = tuple(number(quat.get(k)) for k in ("X", "Y", "Z", "W"))
    if _finite(q) and np.linalg.norm(q) > 0.5:
        # the quaternion rotates the camera's FLU frame into NED: its x axis is the optical axis
        from scipy.spatial.transform import Rotation

        axis_q = Rotation.from_quat(q).as_matrix()[:, 0]
        axis_e = _rotation_ypr(*gimbal).as_matrix()[:, 0]
        angle = math.degrees(math.acos(float(np.clip(np.dot(axis_q, axis_e), -1.0, 1.0))))
        if angle > 1.0:
            pose.notes.append(f"drone-skydio:CameraOrientationQuatNED and CameraOrientationNED disagree on the "
                              f"optical axis by {angle:.1f} deg: the Euler angles are used")
    focal = _struct(root, NS_SKYDIO, "CalibratedFocalLength")
    centre = _struct(root, NS_SKYDIO, "CalibratedOpticalCenter")
    fx, fy = number(focal.get("X")), number(focal.get("Y"))
    if fx > 0 and fy > 0:
        cx, cy = number(centre.get("X")), number(centre.get("Y"))
        ok = math.isfinite(cx) and math.isfinite(cy)
        pose.calibration = Calibration(fx, fy, cx if ok else None, cy if ok else None, None, None,
                                       "drone-skydio:CalibratedFocalLength/CalibratedOpticalCenter")
    if "DewarpData" in sk:
        pose.notes.append("drone-skydio:DewarpData (three numbers, a lens model Skydio does not document) is not "
                          "applied: the camera database's distortion is, where it has the model")
    return pose


def _parrot(xmp: dict, model: str) -> MakerPose | None:
    pa = _in(xmp, NS_PARROT)
    gimbal = _angles(pa, "Camera{}Degree")
    if not _finite(gimbal):
        return None
    body = _angles(pa, "Drone{}Degree")
    anafi_ai = "anafiai" in model.replace(" ", "").lower()
    return MakerPose(maker="Parrot", gimbal_ypr_deg=gimbal, flight_ypr_deg=body if _finite(body) else None,
                     attitude_source="drone-parrot:Camera*/Drone*Degree (earth-referenced)",
                     alt_datum="ellipsoid" if anafi_ai else "amsl")


def _pix4d(xmp: dict, make: str) -> MakerPose | None:
    for ns in (NS_PIX4D, NS_PARROT_CAMERA):
        ypr = _angles(_in(xmp, ns))
        if _finite(ypr):
            break
    else:
        return None
    m = make.strip().lower()
    maker = "Autel" if m.startswith("autel") else "Parrot" if m.startswith("parrot") else make.strip() or "unknown"
    pose = MakerPose(maker=maker, gimbal_ypr_deg=gimbal_from_pix4d(*ypr), flight_ypr_deg=None,
                     attitude_source=f"Camera:Yaw/Pitch/Roll {ypr[0]:g} {ypr[1]:g} {ypr[2]:g} (Pix4D convention: "
                                     "pitch 0 at nadir, 90 forward; earth-referenced)",
                     alt_datum="ellipsoid" if maker == "Autel" else "amsl")
    if maker == "Parrot":
        pose.notes.append("Parrot Camera: tags read with Pix4D's convention; on the one such photo checked (a "
                          "Disco) its picture and altitude did not confirm them (docs/ingest.md)")
    return pose


def _teal(xmp: dict, make: str, model: str) -> MakerPose | None:
    ex = _in(xmp, NS_EXIF_XMP)
    cam = _angles(ex, "Camera{}")
    if not _finite(cam):
        return None
    plat = _angles(ex, "Platform{}")
    if _finite(plat):
        gimbal = gimbal_from_body_relative(cam, plat)
        source = "exif:Camera* relative to exif:Platform* (ZYX, composed)"
        flight = plat
    else:
        gimbal, flight = cam, None
        source = "exif:CameraYaw/Pitch/Roll (no exif:Platform* angles: taken as earth-referenced)"
    pose = MakerPose(maker="Teal" if "flir" in make.lower() or "teal" in make.lower() else make.strip() or "Teal",
                     gimbal_ypr_deg=gimbal, flight_ypr_deg=flight, attitude_source=source, alt_datum="amsl")
    h, v = number(ex.get("CameraHorizontalFOV")), number(ex.get("CameraVerticalFOV"))
    if 0 < h < 180:
        pose.fov_deg = (h, v if 0 < v < 180 else math.nan)
    pose.thermal = "boson" in model.lower()
    return pose


def read_maker_pose(xmp: dict, root, make: str, model: str) -> MakerPose | None:
    """The pose of the first maker reader that finds its tags (module docstring), None when none does.
    `xmp`: {(namespace, local name): text} of every simple property; `root`: the parsed XMP tree (or None)."""
    for reader in (lambda: _skydio(xmp, root), lambda: _dji(xmp, make, model), lambda: _parrot(xmp, model),
                   lambda: _pix4d(xmp, make), lambda: _teal(xmp, make, model)):
        pose = reader()
        if pose is not None:
            return pose
    return None
