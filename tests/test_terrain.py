"""pipeline.terrain: a GeoTIFF DEM as WGS84 heights, rays cast onto it, the `dem` method.

The truths are independent of the ray caster: hits on the analytic terrain (pipeline.synth.dem.Hills, or a
surface that a bilinear grid represents exactly) found by dense sampling and bisection along the ray.
"""

import re

import numpy as np
import pytest
import rasterio
from rasterio.crs import CRS
from rasterio.transform import from_origin
from rasterio.warp import transform as crs_transform

from pipeline.errors import GeometryError, InputError, ObservationError
from pipeline.geometry.frames import ecef_from_lla, enu_from_lla, lla_from_enu
from pipeline.solve.observations import Observations
from pipeline.synth.dem import Hills, bilinear_error_bound_m, incidence_sin, ray_truth_ecef, write_dem
from pipeline.terrain import Dem, locate_dem

LAT0, LON0 = 46.5, 7.5
POST_M = 30.0
HILLS = Hills(LAT0, LON0, base_m=600.0)


def random_rays(n: int, seed: int, spread_deg: float = 0.008):
    """n camera positions 150-500 m above the hills' base near the centre and directions 15-75 deg down."""
    rng = np.random.default_rng(seed)
    origins = np.column_stack([LAT0 + rng.uniform(-spread_deg, spread_deg, n),
                               LON0 + rng.uniform(-spread_deg, spread_deg, n),
                               HILLS.base_m + 150 + rng.uniform(0, 350, n)])
    az = rng.uniform(0, 2 * np.pi, n)
    el = np.radians(rng.uniform(-75, -15, n))
    dirs = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    return origins, dirs


def truth_hits_ecef(origins, dirs, height_fn):
    truth = ray_truth_ecef(origins, dirs, height_fn)
    assert np.isfinite(truth).all(), "a test ray does not meet the analytic terrain"
    return truth


def hits_ecef(dem, origins, dirs):
    """The rays' hits (ECEF), all at once, and the first three one by one through `intersect` (the same)."""
    lla, reasons = dem.intersect_many(origins, dirs)
    assert reasons == [None] * len(origins)
    for i in range(3):
        assert np.array_equal(dem.intersect(origins[i], dirs[i], label=f"ray {i}"), lla[i])
    return ecef_from_lla(lla[:, 0], lla[:, 1], lla[:, 2])


# ---- accuracy --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("crs, stated", [
    ("EPSG:4326", None),  # geographic, no vertical CRS: orthometric assumed (the SRTM/Copernicus case)
    ("EPSG:32632+5773", None),  # UTM 32N + EGM96 height
    ("EPSG:4979", None),  # geographic 3-D: ellipsoidal heights
    ("EPSG:32632", "ellipsoidal"),  # UTM, the caller states ellipsoidal heights
], ids=["geographic-orthometric", "utm-egm96", "geographic-ellipsoidal", "utm-stated-ellipsoidal"])
def test_dem_hits_match_the_analytic_terrain_within_a_fifth_of_a_post(tmp_path, crs, stated):
    path = write_dem(tmp_path / "dem.tif", HILLS, extent_m=6000.0, post_m=POST_M, crs=crs, vertical_datum=stated)
    dem = Dem.open(path, vertical_datum=stated)
    origins, dirs = random_rays(60, seed=sum(map(ord, crs)))
    truth = truth_hits_ecef(origins, dirs, HILLS.h_wgs84_m)
    err = np.linalg.norm(hits_ecef(dem, origins, dirs) - truth, axis=1)
    # A ray meeting a slope at a grazing angle a turns the DEM's height error dh (bilinear between posts of the
    # terrain) into dh / sin(a) along the ground: beyond 0.2 post for a < ~2 deg whatever the ray caster does.
    sin_a = incidence_sin(truth, dirs, HILLS.h_wgs84_m)
    steep = sin_a > np.sin(np.radians(2.0))
    assert steep.sum() >= 50
    assert err[steep].max() < 0.2 * POST_M, f"max {err[steep].max():.2f} m, median {np.median(err):.2f} m"
    assert (err * sin_a).max() < bilinear_error_bound_m(HILLS, POST_M)  # every ray: no more than the DEM's error


def test_a_dem_read_without_its_geoid_would_miss(tmp_path):
    """The datum matters: the same orthometric file read as ellipsoidal is off by ~N / tan(elevation)."""
    path = write_dem(tmp_path / "dem.tif", HILLS, extent_m=6000.0, crs="EPSG:4326")
    origins, dirs = random_rays(10, seed=3)
    truth = truth_hits_ecef(origins, dirs, HILLS.h_wgs84_m)
    wrong = np.linalg.norm(hits_ecef(Dem.open(path, vertical_datum="ellipsoidal"), origins, dirs) - truth, axis=1)
    assert np.median(wrong) > 20.0  # the geoid is ~50 m above the ellipsoid here


def test_exact_on_a_surface_the_bilinear_grid_represents(tmp_path):
    """h = a + b x + c y + d x y in the grid's own coordinates (lon, lat) is the bilinear surface itself: the
    intersection must then be exact (the in-cell solve, not interpolation error, is what is measured)."""
    def saddle(lat, lon):
        x, y = np.asarray(lon) - LON0, np.asarray(lat) - LAT0
        return 600.0 + 900.0 * x - 400.0 * y + 2.0e5 * x * y

    dlat = POST_M / 111_320.0
    dlon = dlat / np.cos(np.radians(LAT0))
    n = 201
    lon = LON0 + dlon * (np.arange(n) - (n - 1) / 2)
    lat = LAT0 - dlat * (np.arange(n) - (n - 1) / 2)
    H = saddle(lat[:, None], lon[None, :])
    path = tmp_path / "saddle.tif"
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float64",
                       crs=CRS.from_epsg(4979), transform=from_origin(lon[0] - dlon / 2, lat[0] + dlat / 2, dlon,
                                                                      dlat)) as ds:
        ds.write(H[None])
    dem = Dem.open(path)
    assert dem.vertical.kind == "ellipsoidal"
    origins, dirs = random_rays(40, seed=11)
    truth = truth_hits_ecef(origins, dirs, saddle)
    err = np.linalg.norm(hits_ecef(dem, origins, dirs) - truth, axis=1)
    assert err.max() < 1e-3, err.max()


def test_utm_post_spacing_matches_the_transverse_mercator_scale(tmp_path):
    """rasterio/PROJ against a closed form: a UTM grid of 30 m posts at 1.5 deg from the central meridian spans
    30 / k metres on the ground, k = 0.9996 (1 + (dlon cos lat)^2 / 2) to first order."""
    dem = Dem.open(write_dem(tmp_path / "utm.tif", HILLS, extent_m=2000.0, post_m=POST_M, crs="EPSG:32632"))
    k = 0.9996 * (1 + (np.radians(LON0 - 9.0) * np.cos(np.radians(LAT0))) ** 2 / 2)
    assert dem.post_m == pytest.approx((POST_M / k, POST_M / k), rel=2e-5)
    (x,), (y,) = crs_transform("EPSG:4326", "EPSG:32632", [9.0], [0.0])
    assert (x, y) == pytest.approx((500_000.0, 0.0), abs=1e-6)


def test_heights_are_nan_outside_and_bilinear_inside(tmp_path):
    dem = Dem.open(write_dem(tmp_path / "dem.tif", HILLS, extent_m=2000.0, crs="EPSG:4979"))
    lat = LAT0 + np.linspace(-0.005, 0.005, 7)
    assert np.abs(dem.height_wgs84_m(lat, LON0) - HILLS.h_wgs84_m(lat, LON0)).max() < 0.5
    assert np.isnan(dem.height_wgs84_m([LAT0 + 0.05, np.nan, 91.0], [LON0, LON0, LON0])).all()


def test_a_geographic_dem_across_the_antimeridian(tmp_path):
    hills = Hills(-16.5, 180.0, base_m=300.0)
    dem = Dem.open(write_dem(tmp_path / "fiji.tif", hills, extent_m=2000.0, crs="EPSG:4979"))
    assert dem.bounds_deg[3] > 180.0  # the file's longitudes run past 180
    lat, lon = np.full(4, -16.5), np.array([179.995, 180.005, -179.995, 180.0])
    assert np.abs(dem.height_wgs84_m(lat, lon) - hills.h_wgs84_m(lat, lon)).max() < 0.5


# ---- the datum and refusals --------------------------------------------------------------------------------

@pytest.mark.parametrize("crs, kind, source", [
    ("EPSG:4326", "orthometric", "assumed"),
    ("EPSG:4326+3855", "orthometric", "EGM2008"),
    ("EPSG:32632+5773", "orthometric", "EGM96"),
    ("EPSG:4979", "ellipsoidal", "3-D"),
])
def test_vertical_datum_from_the_crs(tmp_path, crs, kind, source):
    dem = Dem.open(write_dem(tmp_path / "dem.tif", HILLS, extent_m=600.0, crs=crs))
    assert dem.vertical.kind == kind and source in dem.vertical.source


def _tiny(path, crs=None, shape=(3, 4), values=None, **kw):
    values = np.ones(shape, np.float32) if values is None else values
    with rasterio.open(path, "w", driver="GTiff", width=shape[1], height=shape[0], count=1, dtype="float32",
                       transform=from_origin(9, 47, 0.01, 0.01), **({"crs": CRS.from_user_input(crs)} if crs else {}),
                       **kw) as ds:
        ds.write(values[None])
    return path


@pytest.mark.parametrize("make, match", [
    (lambda p: p, "file not found"),
    (lambda p: (p.mkdir(), p)[1], "is a directory"),
    (lambda p: (p.write_bytes(b"II*\x00garbage" * 10), p)[1], "not a readable GeoTIFF DEM"),
    (lambda p: _tiny(p), "has no coordinate reference system"),
    (lambda p: _tiny(p, 'LOCAL_CS["site grid",UNIT["metre",1]]'), "unknown CRS 'site grid'"),
    (lambda p: _tiny(p, "EPSG:4326+5783"), "unknown vertical datum 'DHHN92 height'"),
    (lambda p: _tiny(p, "EPSG:4326", shape=(1, 5)), "at least 2 x 2"),
    (lambda p: _tiny(p, "EPSG:4326", values=np.full((3, 4), -9999, np.float32), nodata=-9999),
     "no height data"),
], ids=["missing", "directory", "garbage", "no-crs", "local-crs", "dhhn92", "one-row", "all-nodata"])
def test_unusable_dems_are_refused_in_one_line_naming_the_file(tmp_path, make, match):
    path = make(tmp_path / "bad.tif")
    with pytest.raises(InputError, match=match) as exc:
        Dem.open(path)
    assert "\n" not in str(exc.value) and str(path) in str(exc.value)


def test_a_plain_image_given_as_the_dem_is_refused_without_rasterio_s_warning(tmp_path):
    import warnings

    from PIL import Image

    path = tmp_path / "photo.png"
    Image.new("L", (8, 6)).save(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(InputError, match="has no coordinate reference system"):
            Dem.open(path)
    assert [str(w.message) for w in caught] == []


def test_a_stated_vertical_datum_overrides_an_unknown_one(tmp_path):
    path = _tiny(tmp_path / "dhhn.tif", "EPSG:4326+5783")
    assert Dem.open(path, vertical_datum="orthometric").vertical.source == "stated by the user"
    with pytest.raises(InputError, match="vertical datum must be one of"):
        Dem.open(path, vertical_datum="navd88")


# ---- rays that miss ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def hills_dem(tmp_path_factory):
    return Dem.open(write_dem(tmp_path_factory.mktemp("dem") / "hills.tif", HILLS, extent_m=4000.0, crs="EPSG:32632"))


@pytest.mark.parametrize("origin, direction, match", [
    ((LAT0, LON0, 900.0), (0, 1, 0.01), "points above the terrain"),
    ((LAT0, LON0, 900.0), (0, 1, -0.01), "leaves the DEM's data at"),
    ((LAT0, LON0, 500.0), (0, 1, -0.5), "starts below the DEM surface"),
    ((LAT0 + 0.1, LON0, 600.0), (0, 1, 0.0), "never crosses the DEM's area"),
    ((LAT0 - 0.05, LON0, 800.0), (0, 1, -0.1), "meets the ground outside the DEM: it drops below"),
])
def test_a_ray_that_misses_is_one_line_naming_photo_pixel_and_dem(hills_dem, origin, direction, match):
    with pytest.raises(GeometryError, match=match) as exc:
        hills_dem.intersect(origin, direction, label="DJI_0042.JPG pixel (2000.0, 1500.0)")
    msg = str(exc.value)
    assert isinstance(exc.value, InputError) and "\n" not in msg
    assert msg.startswith("DJI_0042.JPG pixel (2000.0, 1500.0): ") and str(hills_dem.path) in msg


def test_a_miss_names_its_heights_datum_and_where_a_dem_of_another_site_is(hills_dem):
    """The camera's height in a miss is WGS84 ellipsoidal (the photo states AMSL: they differ by the geoid), and a
    camera away from the DEM hears where the DEM is: a DEM of another site is the usual cause."""
    with pytest.raises(GeometryError, match=r"500\.0 m WGS84 ellipsoidal height, [0-9.]+ m under the ground"):
        hills_dem.intersect((LAT0, LON0, 500.0), (0, 1, -0.5))
    with pytest.raises(GeometryError) as exc:
        hills_dem.intersect((LAT0 + 0.1, LON0, 600.0), (0, 1, 0.0))
    lat0, lat1, _, _ = hills_dem.bounds_deg
    d_m = (LAT0 + 0.1 - lat1) * 111_000  # north of the DEM by about this
    got = re.search(r"the DEM covers lat ([0-9.]+)\.\.([0-9.]+), lon [0-9.]+\.\.[0-9.]+, about (\d+) m from the camera",
                    str(exc.value))
    assert got and float(got[1]) == pytest.approx(lat0, abs=1e-4) and float(got[2]) == pytest.approx(lat1, abs=1e-4)
    assert abs(int(got[3]) - d_m) < 100
    with pytest.raises(GeometryError) as exc:  # over the DEM: nothing to say about where it is
        hills_dem.intersect((LAT0, LON0, 900.0), (0, 1, 0.01))
    assert "the DEM covers" not in str(exc.value)


def test_a_nodata_hole_on_the_way_stops_the_ray(tmp_path):
    dem = Dem.open(write_dem(tmp_path / "dem.tif", HILLS, extent_m=4000.0, crs="EPSG:4979"))
    lat, lon, _ = dem.intersect((LAT0, LON0, 900.0), (0, 1, -0.3))
    n_hit = enu_from_lla(lat, lon, 0.0, (LAT0, LON0, 0.0))[1]
    rows = dem.heights_m.shape[0]
    dem.heights_m[(rows - 1) // 2 - int(0.6 * n_hit / POST_M), :] = np.nan  # a row of posts before the hit
    with pytest.raises(GeometryError, match="leaves the DEM's data"):
        dem.intersect((LAT0, LON0, 900.0), (0, 1, -0.3))


# ---- the dem method ----------------------------------------------------------------------------------------

def _camera(C, G, f_px=1000.0, c_px=(500.0, 400.0)):
    """P (3, 4) of a camera at C looking at G (world ENU); G projects to the principal point."""
    z = (G - C) / np.linalg.norm(G - C)
    x = np.cross(z, [0, 0, 1.0])
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    K = np.array([[f_px, 0, c_px[0]], [0, f_px, c_px[1]], [0, 0, 1.0]])
    return K @ np.hstack([R, -(R @ C)[:, None]])


def test_locate_dem_takes_the_median_of_the_views_and_lists_the_misses(hills_dem):
    origin = (LAT0, LON0, 600.0)
    g_lla = (LAT0 + 0.004, LON0 + 0.002)
    G = enu_from_lla(*g_lla, float(hills_dem.height_wgs84_m(*g_lla)), origin)
    Cs = np.array([[100.0, -200.0, 400.0], [-300.0, 50.0, 500.0], [400.0, 300.0, 450.0]])
    P = np.stack([_camera(C, G) for C in Cs])
    pixel = np.array([[500.0, 400.0], [500.0, 400.0], [500.0, -4000.0]])  # the third looks at the sky
    obs = Observations(P=P, pixel=pixel, platform_m=Cs, range_m=np.full(3, np.nan))
    est = locate_dem(obs, hills_dem, origin, labels=["a.jpg", "b.jpg", "c.jpg"])
    assert est.method == "dem" and est.converged
    assert np.linalg.norm(est.position_m - G) < 0.01  # the ground point of the bilinear DEM itself
    assert est.extras["n_points"] == 2 and est.extras["points_m"][2] is None
    assert est.extras["missed"][0].startswith("c.jpg pixel (500.0, -4000.0): the ray never meets the ground")
    with pytest.raises(GeometryError, match=r"^dem: c.jpg pixel \(500.0, -4000.0\): .* \(DEM .*hills.tif\)$"):
        locate_dem(obs.subset(np.array([2])), hills_dem, origin, labels=["c.jpg"])
    with pytest.raises(GeometryError, match=r"^dem: c.jpg pixel \(510.0, -3990.0\): "):  # as the user gave it
        locate_dem(obs.subset(np.array([2])), hills_dem, origin, labels=["c.jpg"], pixels_shown=[[510.0, -3990.0]])
    with pytest.raises(ObservationError, match="no view has a target pixel"):
        locate_dem(Observations(P=P[:1], pixel=[[np.nan, np.nan]], platform_m=Cs[:1], range_m=[np.nan]),
                   hills_dem, origin)


def test_local_terrain_gives_up_and_slopes_in_the_enu_frame(hills_dem):
    origin = (LAT0, LON0, 650.0)
    terrain = hills_dem.local(*origin)
    rng = np.random.default_rng(5)
    e, n = rng.uniform(-1200, 1200, 50), rng.uniform(-1200, 1200, 50)
    up, de, dn = terrain(e, n)
    lla = lla_from_enu(np.stack([e, n, up], axis=-1), origin)  # the point found is on the DEM surface
    assert np.abs(lla[:, 2] - hills_dem.height_wgs84_m(lla[:, 0], lla[:, 1])).max() < 1e-3
    assert np.abs(lla[:, 2] - HILLS.h_wgs84_m(lla[:, 0], lla[:, 1])).max() < 0.5  # and near the analytic one
    # slopes against a central difference of the analytic terrain over 2 posts (the bilinear slope is a
    # cell's average, so they agree to the curvature over a cell)
    h = 30.0
    def analytic_up(ee, nn):
        u = np.zeros_like(ee)
        for _ in range(4):
            p = lla_from_enu(np.stack([ee, nn, u], axis=-1), origin)
            u = u + HILLS.h_wgs84_m(p[:, 0], p[:, 1]) - p[:, 2]
        return u
    de_ref = (analytic_up(e + h, n) - analytic_up(e - h, n)) / (2 * h)
    dn_ref = (analytic_up(e, n + h) - analytic_up(e, n - h)) / (2 * h)
    assert np.abs(de - de_ref).max() < 0.05 and np.abs(dn - dn_ref).max() < 0.05
    assert np.isnan(terrain(np.array([5000.0]), np.array([0.0]))[0]).all()
