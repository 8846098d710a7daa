"""Small synthetic drone photos carrying each maker's pose tags as the real ones in ../shared/photos/makers write
them (tests of the readers and the fuzz targets' seeds): `write_maker_photo(path, maker, ...)`.

Makers: "skydio" (drone-skydio structs as attributes, as skydio-catilina.jpg), "skydio-resource" (the same
structs as child elements of rdf:parseType="Resource", Skydio's newer form), "parrot" (drone-parrot: Anafi),
"parrot-disco" (Camera: under the URI `Camera/`, as parrot-1.jpg), "autel-pix4d" (Pix4D's Camera: URI, Autel's
older firmware), "autel-dji" (Autel's newer firmware: DJI's namespace URI under the prefix drone:), "teal"
(exif:Camera*/Platform* rationals and the field of view, as teal2_img_ir_00015.jpg).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

MAKES = {"skydio": ("Skydio", "2"), "skydio-resource": ("Skydio", "X2"), "parrot": ("Parrot", "ANAFI"),
         "parrot-disco": ("PARROT", "Disco"), "autel-pix4d": ("Autel Robotics", "XT705"),
         "autel-dji": ("Autel Robotics", "XT705"), "teal": ("Teledyne FLIR", "Boson 640")}


def _rational(v: float) -> str:
    return f"{round(v * 1_000_000)}/1000000"


def maker_xmp(maker: str, yaw: float, pitch: float, roll: float, lat: float, lon: float, alt: float,
              platform=(0.0, 0.0, 0.0)) -> bytes:
    """An XMP packet of `maker` stating the camera's (yaw, pitch, roll) in the maker's own convention."""
    rdf = "http://www.w3.org/1999/02/22-rdf-syntax-ns#"
    if maker == "skydio":
        body = (f'<rdf:Description rdf:about="" xmlns:drone-skydio="https://www.skydio.com/drone-skydio/1.0/" '
                f'drone-skydio:Latitude="{lat}" drone-skydio:Longitude="{lon}" drone-skydio:AbsoluteAltitude="{alt}">'
                f'<drone-skydio:VehicleOrientationNED drone-skydio:Roll="1.5" drone-skydio:Pitch="-1.4" '
                f'drone-skydio:Yaw="{yaw - 0.6}"/>'
                f'<drone-skydio:CameraOrientationNED drone-skydio:Roll="{roll}" drone-skydio:Pitch="{pitch}" '
                f'drone-skydio:Yaw="{yaw}"/>'
                '<drone-skydio:CalibratedFocalLength drone-skydio:X="2378.5" drone-skydio:Y="2376.9"/>'
                '<drone-skydio:CalibratedOpticalCenter drone-skydio:X="2029.2" drone-skydio:Y="1520.3"/>'
                '</rdf:Description>')
    elif maker == "skydio-resource":
        def struct(name, **fields):
            inner = "".join(f"<drone-skydio:{k}>{v}</drone-skydio:{k}>" for k, v in fields.items())
            return f'<drone-skydio:{name} rdf:parseType="Resource">{inner}</drone-skydio:{name}>'
        body = ('<rdf:Description rdf:about="" xmlns:drone-skydio="https://www.skydio.com/drone-skydio/1.0/">'
                f"<drone-skydio:Latitude>{lat}</drone-skydio:Latitude><drone-skydio:Longitude>{lon}"
                f"</drone-skydio:Longitude><drone-skydio:AbsoluteAltitude>{alt}</drone-skydio:AbsoluteAltitude>"
                + struct("VehicleOrientationNED", Roll=0.5, Pitch=-2.0, Yaw=yaw + 1.0)
                + struct("CameraOrientationNED", Roll=roll, Pitch=pitch, Yaw=yaw) + "</rdf:Description>")
    elif maker == "parrot":
        body = ('<rdf:Description rdf:about="" xmlns:drone-parrot="http://www.parrot.com/drone-parrot/1.0/">'
                f"<drone-parrot:CameraYawDegree>{yaw}</drone-parrot:CameraYawDegree>"
                f"<drone-parrot:CameraPitchDegree>{pitch}</drone-parrot:CameraPitchDegree>"
                f"<drone-parrot:CameraRollDegree>{roll}</drone-parrot:CameraRollDegree>"
                f"<drone-parrot:DroneYawDegree>{yaw}</drone-parrot:DroneYawDegree>"
                "<drone-parrot:DronePitchDegree>-2.0</drone-parrot:DronePitchDegree>"
                "<drone-parrot:DroneRollDegree>0.5</drone-parrot:DroneRollDegree></rdf:Description>")
    elif maker in ("parrot-disco", "autel-pix4d"):
        uri = "Camera/" if maker == "parrot-disco" else "http://pix4d.com/camera/1.0/"
        about = "Autel Robotics Meta Data" if maker == "autel-pix4d" else ""
        body = (f'<rdf:Description rdf:about="{about}" xmlns:Camera="{uri}" Camera:Yaw="{yaw}" '
                f'Camera:Pitch="{pitch}" Camera:Roll="{roll}" Camera:AboveGroundAltitude="1.000"/>')
    elif maker == "autel-dji":
        body = ('<rdf:Description rdf:about="DJI Meta Data" xmlns:drone="http://www.dji.com/drone-dji/1.0/" '
                f'drone:AbsoluteAltitude="{alt:+.2f}" drone:GpsLatitude="{lat}" drone:GpsLongtitude="{lon}" '
                f'drone:GimbalYawDegree="{yaw}" drone:GimbalPitchDegree="{pitch}" drone:GimbalRollDegree="{roll}" '
                f'drone:FlightYawDegree="{yaw}" drone:FlightPitchDegree="0" drone:FlightRollDegree="0" '
                'drone:RelativeAltitude="+80.00"/>')
    elif maker == "teal":
        py, pp, pr = platform
        body = ('<rdf:Description rdf:about="" xmlns:exif="http://ns.adobe.com/exif/1.0/" '
                'xmlns:tiff="http://ns.adobe.com/tiff/1.0/">'
                f"<exif:CameraPitch>{_rational(pitch)}</exif:CameraPitch>"
                f"<exif:CameraRoll>{_rational(roll)}</exif:CameraRoll>"
                f"<exif:CameraYaw>{_rational(yaw)}</exif:CameraYaw>"
                f"<exif:PlatformPitch>{_rational(pp)}</exif:PlatformPitch>"
                f"<exif:PlatformRoll>{_rational(pr)}</exif:PlatformRoll>"
                f"<exif:PlatformYaw>{_rational(py)}</exif:PlatformYaw>"
                "<exif:CameraHorizontalFOV>31534363/1000000</exif:CameraHorizontalFOV>"
                "<exif:CameraVerticalFOV>25456987/1000000</exif:CameraVerticalFOV>"
                "<tiff:Make>Teledyne FLIR</tiff:Make><tiff:Model>Boson 640</tiff:Model></rdf:Description>")
    else:
        raise ValueError(f"unknown maker {maker!r}")
    return (f'<?xpacket begin="\ufeff" id="W5M0MpCehiHzreSzNTczkc9d"?><x:xmpmeta xmlns:x="adobe:ns:meta/">'
            f'<rdf:RDF xmlns:rdf="{rdf}">{body}</rdf:RDF></x:xmpmeta><?xpacket end="w"?>').encode()


def _dms(value: float) -> tuple[float, float, float]:
    v = abs(value)
    d = int(v)
    m = int((v - d) * 60)
    return float(d), float(m), round((v - d - m / 60) * 3600, 6)


def write_maker_photo(path, maker: str, yaw: float = 30.0, pitch: float = -40.0, roll: float = 0.0,
                      lat: float = 46.5, lon: float = 7.5, alt: float = 900.0, size=(64, 48), platform=(0.0, 0.0, 0.0),
                      exif_extra: dict | None = None, software: str | None = None, model: str | None = None) -> Path:
    """A JPEG of `size` (w, h) with EXIF Make/Model/GPS (altitude `alt`) and `maker`'s XMP pose; `model` replaces
    the maker's usual model (one the camera database does not hold: no distortion, the 35 mm focal length)."""
    from PIL import Image

    w, h = size
    img = Image.fromarray(np.random.default_rng(1).integers(60, 200, (h, w), dtype=np.uint8))
    exif = Image.Exif()
    exif[271], exif[272] = MAKES[maker]
    if model is not None:
        exif[272] = model
    if software:
        exif[305] = software
    ex = exif.get_ifd(0x8769)
    ex[36867] = "2024:07:31 19:17:50"
    ex[37386] = 4.7
    ex[41989] = 24
    for k, v in (exif_extra or {}).items():
        ex[k] = v
    gps = exif.get_ifd(0x8825)
    gps[1], gps[2] = ("N" if lat >= 0 else "S"), _dms(lat)
    gps[3], gps[4] = ("E" if lon >= 0 else "W"), _dms(lon)
    gps[5], gps[6] = b"\x00", round(abs(alt), 3)
    path = Path(path)
    img.save(path, "JPEG", quality=70, exif=exif,
             xmp=maker_xmp(maker, yaw, pitch, roll, lat, lon, alt, platform=platform))
    return path
