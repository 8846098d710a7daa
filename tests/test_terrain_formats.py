"""The DEMs people download (docs/terrain.md, "Formats"): DTED, SRTM .hgt, Copernicus GLO-30 GeoTIFFs with or
without their EGM2008 vertical CRS, USGS 3DEP (NAD83 + NAVD88), each read with the vertical datum its file states
or the one the user states: a level terrain at 500 m above mean sea level must come out at 500 m + the EGM2008
undulation N (WGS84 ellipsoidal), and at 500 m where the heights are ellipsoidal."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from rasterio.crs import CRS
from rasterio.shutil import copy as raster_copy
from rasterio.transform import from_origin

from pipeline.geometry.geoid import geoid_undulation_m
from pipeline.terrain import Dem

LAT, LON, H = 46.5, 7.5, 500.0


def _tile(path, crs, n=121, driver="GTiff", dtype="int16"):
    """A level 1 x 1 degree tile of posts every 1/(n-1) degree at H m, centred on whole degrees (pixel is area)."""
    step = 1.0 / (n - 1)
    with rasterio.open(path, "w", driver=driver, width=n, height=n, count=1, dtype=dtype,
                       crs=CRS.from_user_input(crs), transform=from_origin(7 - step / 2, 47 + step / 2, step, step)
                       ) as ds:
        ds.write(np.full((1, n, n), H, dtype=dtype))
    return path


@pytest.mark.parametrize("name, crs, datum, match", [
    ("copernicus.tif", "EPSG:4326", "orthometric", "assumed"),  # GLO-30 as distributed: no vertical CRS
    ("copernicus_egm2008.tif", "EPSG:4326+3855", "orthometric", "EGM2008 height"),
    ("srtm_egm96.tif", "EPSG:4326+5773", "orthometric", "EGM96 height"),
    ("3dep.tif", "EPSG:4269+5703", "orthometric", "NAVD88 height"),  # NAD83 + NAVD88, as USGS 3DEP
    ("3dep_nad83_only.tif", "EPSG:4269", "orthometric", "assumed"),
    ("lidar_ellipsoidal.tif", "EPSG:4979", "ellipsoidal", "ellipsoidal heights"),
])
def test_geotiffs_vertical_datum_read_from_the_file(tmp_path, name, crs, datum, match):
    dem = Dem.open(_tile(tmp_path / name, crs))
    assert dem.vertical.kind == datum and match in dem.vertical.source
    n = geoid_undulation_m(LAT, LON) if datum == "orthometric" else 0.0
    assert dem.height_wgs84_m(LAT, LON) == pytest.approx(H + n, abs=1e-6)


def test_dted_is_read_as_mean_sea_level_from_its_header(tmp_path):
    src = _tile(tmp_path / "src.tif", "EPSG:4326")
    raster_copy(src, tmp_path / "n46e007.dt0", driver="DTED")  # DTED level 0: 121 x 121 posts, 30 arc-seconds
    dem = Dem.open(tmp_path / "n46e007.dt0")
    assert dem.vertical.kind == "orthometric" and "DTED header" in dem.vertical.source
    assert dem.height_wgs84_m(LAT, LON) == pytest.approx(H + geoid_undulation_m(LAT, LON), abs=1e-6)
    assert dem.post_m[1] == pytest.approx(30.0 / 3600 * 111_200, rel=0.01)  # 30" of latitude


def test_srtm_hgt_tiles_are_read(tmp_path):
    src = _tile(tmp_path / "src.tif", "EPSG:4326", n=1201)  # SRTM3: 3 arc-seconds
    raster_copy(src, tmp_path / "N46E007.hgt", driver="SRTMHGT")
    dem = Dem.open(tmp_path / "N46E007.hgt")
    assert dem.vertical.kind == "orthometric"
    assert dem.height_wgs84_m(LAT, LON) == pytest.approx(H + geoid_undulation_m(LAT, LON), abs=1e-6)


def test_locate_states_the_dems_datum(tmp_path, capsys):
    """`ridgeloc locate --dem-datum ellipsoidal` on a file without a vertical CRS: the ground is N metres lower
    for the orthometric reading than for the stated ellipsoidal one, so the same ray meets it further on."""
    import json

    from pipeline.cli import main as cli_main
    from support.maker_photos import write_maker_photo

    dem = _tile(tmp_path / "flat.tif", "EPSG:4326")
    photo = write_maker_photo(tmp_path / "p.jpg", "parrot", yaw=0.0, pitch=-45.0, lat=LAT, lon=LON, alt=700.0)
    heights = {}
    for datum in (None, "ellipsoidal"):
        extra = ["--dem-datum", datum] if datum else []
        cli_main(["locate", str(photo), "--dem", str(dem), "--json", *extra])
        heights[datum] = json.loads(capsys.readouterr().out)["estimates"]["dem"]["h_m"]
    n = geoid_undulation_m(LAT, LON)
    assert heights["ellipsoidal"] == pytest.approx(H, abs=0.01)
    assert heights[None] == pytest.approx(H + n, abs=0.01)
    assert cli_main(["locate", str(photo), "--dem-datum", "ellipsoidal"]) != 0
    assert "--dem-datum is the DEM's vertical datum: give the DEM with --dem" in capsys.readouterr().err
