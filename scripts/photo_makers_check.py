"""The makers' photos against an independent implementation (docs/ingest.md, "Drone photos: makers, verified"):
`ridgeloc locate PHOTO --dem DEM --pixel (image centre)` on each photo of ../shared/photos/makers, beside
OpenAthena's published answers for the same photos and pixel (its iOS tests, below), and the same ray cast onto the
DEM read the way OpenAthena reads it (the GeoTIFF's tie point taken as the first post, half a post west and north
of where GDAL and ridgeloc put it), to tell the pose conventions apart from the terrain model's registration.

    python scripts/photo_makers_check.py [--folder ../shared/photos/makers]

OpenAthena's expectations: Theta-Limited/OpenAthenaIOS, OpenAthenaIOSTests/TestCalculations.swift at commit
122fa9f2734828467d3dc2935b9b4f1c54855319 (testSkydio: the image centre, targetXprop = targetYprop = 0.5; testTeal2:
the centre of teal2_img_eo_00015.jpg, the visible-light photo taken with this thermal one, whose pose tags are the
same; testParrot: parrot-1's centre throws).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: photo -> (DEM, OpenAthena's published (lat, lon) of the image centre, or None where it refuses)
OPENATHENA = {
    "skydio-catilina.jpg": ("skydio-catilina-dem.tiff", (32.517076053635684, -110.92166815563021)),
    "teal2_img_ir_00015.jpg": ("teal2.tiff", (40.71041728495734, -111.89443435609874)),
    "parrot-1.jpg": ("parrot-1-dem.tiff", None),
}


def corner_registered_copy(dem_path: Path, out: Path) -> Path:
    """The DEM with its posts moved half a post west and north: the tie point read as the first post's centre."""
    import rasterio
    from rasterio.transform import Affine

    with rasterio.open(dem_path) as ds:
        profile, heights, t = ds.profile, ds.read(1), ds.transform
    profile["transform"] = Affine(t.a, t.b, t.c - t.a / 2, t.d, t.e, t.f - t.e / 2)
    with rasterio.open(out, "w", **profile) as ds:
        ds.write(heights, 1)
    return out


def centre_answer(photo_path: Path, dem_path: Path) -> tuple[np.ndarray | None, str, np.ndarray, np.ndarray]:
    """(lat, lon, h of the `dem` answer at the image centre or None, the refusal, camera ENU, ray ENU) in the ENU
    frame at the camera."""
    from pipeline.ingest.photo import read_photo_checked
    from pipeline.locate import locate_photos
    from pipeline.terrain import Dem

    photo = read_photo_checked(photo_path)
    centre = [[(photo.width_px - 1) / 2.0, (photo.height_px - 1) / 2.0]]
    loc = locate_photos([photo], centre, dem=Dem.open(dem_path), methods=["dem"])
    axis = loc.views.R_enu0_from_optical[0] @ np.linalg.solve(loc.views.K[0], [*loc.obs.pixel[0], 1.0])
    if "dem" not in loc.estimates:
        return None, loc.unsolved["dem"][1], loc.views.camera_m[0], axis
    return loc.views.lla(loc.estimates["dem"].position_m), "", loc.views.camera_m[0], axis / np.linalg.norm(axis)


def compare(ours_lla, theirs_latlon, camera_m, ray) -> tuple[float, float, float]:
    """(horizontal distance, along the ray's horizontal direction, across it) of ours - theirs, metres."""
    from pipeline.geometry.frames import enu_from_lla

    e = enu_from_lla(theirs_latlon[0], theirs_latlon[1], ours_lla[2], (ours_lla[0], ours_lla[1], ours_lla[2]))
    d = -np.asarray(e[:2])  # ours minus theirs, east-north
    along = ray[:2] / np.linalg.norm(ray[:2])
    return float(np.hypot(*d)), float(d @ along), float(d @ np.array([-along[1], along[0]]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folder", default="../shared/photos/makers")
    folder = Path(ap.parse_args().folder)
    if not folder.is_dir():
        print(f"{folder}: no such folder", file=sys.stderr)
        return 1
    print("photo                   ridgeloc dem answer (lat lon h)          OpenAthena (lat lon)        "
          "|d| m  along  across | DEM as OpenAthena reads it: |d| m")
    with tempfile.TemporaryDirectory() as tmp:
        for name, (dem, theirs) in OPENATHENA.items():
            ours, refusal, cam, ray = centre_answer(folder / name, folder / dem)
            if ours is None or theirs is None:
                print(f"{name:23s} {'refused: ' + refusal if ours is None else ours}  |  OpenAthena: "
                      f"{'refuses' if theirs is None else theirs}")
                continue
            dist, along, across = compare(ours, theirs, cam, ray)
            shifted, _, _, _ = centre_answer(folder / name, corner_registered_copy(folder / dem, Path(tmp) / dem))
            d2 = compare(shifted, theirs, cam, ray)[0] if shifted is not None else float("nan")
            print(f"{name:23s} {ours[0]:.7f} {ours[1]:.7f} {ours[2]:7.1f}  {theirs[0]:.7f} {theirs[1]:.7f}  "
                  f"{dist:5.2f} {along:6.2f} {across:6.2f} | {d2:5.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
