"""`dem` on one synthetic drone photo (pipeline.synth.photos, read back through the photo reader and its pose
chain) against the ray-terrain truth: the ray the photo's own tags define, through its pixel, intersected with
the analytic terrain the DEM was sampled from (done-when of issue 22: within 0.2 of a DEM post)."""

import numpy as np
import pymap3d
import pytest

from pipeline.synth.dem import Hills, bilinear_error_bound_m, incidence_sin, ray_truth_ecef, write_dem
from pipeline.terrain import Dem

POST_M = 30.0
HILLS = Hills(46.5, 7.5, base_m=600.0)


@pytest.fixture(scope="module")
def dem(tmp_path_factory):
    return Dem.open(write_dem(tmp_path_factory.mktemp("dem") / "dem.tif", HILLS, extent_m=4000.0, post_m=POST_M,
                              crs="EPSG:32632"))


@pytest.mark.parametrize("seed", range(8))
def test_dem_on_one_photo_matches_the_ray_terrain_truth(tmp_path, dem, seed):
    from pipeline.ingest.photo import read_photo_checked
    from pipeline.locate import locate_photos
    from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight

    flight = simulate_photo_flight(PhotoFlightSpec(seed=seed, n_photos=1, hills=HILLS))
    (path,) = write_photo_flight(flight, tmp_path)
    loc = locate_photos([read_photo_checked(path)], dem=dem, methods=["dem"])
    est = loc.estimates["dem"]
    origin = loc.views.origin_lla
    # the truth, by plain linear algebra and pymap3d: the ray of the photo's camera matrix through its pixel
    M, p4 = loc.obs.P[0, :, :3], loc.obs.P[0, :, 3]
    C = -np.linalg.solve(M, p4)
    d = np.linalg.solve(M, [*loc.obs.pixel[0], 1.0]) * np.sign(np.linalg.det(M))
    c_lla = np.array(pymap3d.enu2geodetic(*C, *origin))
    d_ecef = np.array(pymap3d.enu2uvw(*d, origin[0], origin[1]))
    d_enu = np.array(pymap3d.uvw2enu(*d_ecef, c_lla[0], c_lla[1]))
    truth = ray_truth_ecef(c_lla[None], d_enu[None], HILLS.h_wgs84_m, t_max_m=3000.0, step_m=0.25)[0]
    hit = np.array(pymap3d.enu2ecef(*est.position_m, *origin))
    err = np.linalg.norm(hit - truth)
    sin_a = incidence_sin(truth[None], d_enu[None], HILLS.h_wgs84_m)[0]
    if sin_a > np.sin(np.radians(2)):  # (a grazing ray's error is the DEM's own / sin(incidence): test_terrain.py)
        assert err < 0.2 * POST_M, err
    assert err * sin_a < bilinear_error_bound_m(HILLS, POST_M)
