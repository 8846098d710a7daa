"""The real Skydio X2 lines of sight of ../shared/real_rays (scripts/real_rays.py; docs/locate.md, "Real lines of
sight"): the adapter reproduces OpenAthena's own numbers from the CSV's pose and pixel, and each point's photos,
fused by locate's MLE under the default photo error model, hold the figures docs/locate.md states."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDER = ROOT.parent / "shared" / "real_rays"  # ../shared from the repo root
pytestmark = pytest.mark.skipif(not (FOLDER / "openathena_rays.csv").is_file(), reason="../shared/real_rays is absent")


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("real_rays", ROOT / "scripts" / "real_rays.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["real_rays"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    yield module
    del sys.modules["real_rays"]


@pytest.fixture(scope="module")
def data(script):
    rr = script.read_real_rays(FOLDER)
    return rr, script.camera_yaw_deg(rr)


@pytest.fixture(scope="module")
def fused(script, data):
    rr, yaw = data
    return [script.fuse(rr, rr.rows_of(k), yaw) for k in range(len(rr.names))]


def test_the_adapter_reproduces_openathenas_angles(script, data):
    rr, yaw = data
    assert (len(rr.point), len(rr.names), len(np.unique(rr.photo))) == (204, 10, 79)
    chk = script.adapter_checks(rr)
    # every row of a photo gives the photo's azimuth back (answer azimuth minus the pixel's yaw offset), but one
    # whose answer OpenAthena put 4 m on the far side of nadir
    assert chk["yaw_spread_deg"] < 0.1 and len(chk["far_side_rows"]) == 1
    # OpenAthena's logged pixel offsets from fraction x size, the image centre and the roll as a ZYX roll
    assert chk["offsets_max_diff_deg"] < 0.01
    # the ray through the image centre points where the camera's azimuth and slant say (the pose chain of
    # pipeline.ingest.photo_views: gimbal yaw, pitch -slant, roll, ZYX in local NED)
    from pipeline.geometry.rays import camera_rays_m
    from pipeline.ingest.photo_views import photo_views

    for i in range(0, len(rr.point), 17):
        v = photo_views([script.photo_of_row(rr, i, yaw[i])], origin_lla=tuple(rr.drone_lla[i]))
        _, d = camera_rays_m(v.P, np.array([[rr.size_px[0] / 2.0, rr.size_px[1] / 2.0]]))
        e, n, u = d[0]
        assert np.degrees(np.arctan2(e, n)) % 360.0 == pytest.approx(yaw[i], abs=1e-6)
        assert np.degrees(np.arcsin(-u)) == pytest.approx(rr.slant_deg[i], abs=1e-6)
    # off the centre OpenAthena's ray (camera azimuth + the pixel's yaw offset, slant - its pitch offset) is not the
    # ray through the pixel: a pan offset psi turns the azimuth by about psi / cos(slant), not psi
    _, gap, _ = script.ray_geometry(rr, yaw)
    off_deg = np.degrees(np.hypot(*((rr.fraction_xy - 0.5) * np.array(rr.size_px)).T) / rr.f_px[0])
    assert gap[np.argmin(off_deg)] < 0.3 and np.median(gap) > 2.0

def test_each_points_photos_fused(script, data, fused):
    rr, _ = data
    single = script.single_photo_errors_m(rr)
    err = np.array([f.error_m for f in fused])
    assert np.median(err) <= 0.5 * np.median(single)  # 3.43 m against 6.95 m
    # 8 of 10 inside the 95 % ellipse (O8: two of its five rows are taps of O10; Y2: rays from one direction)
    assert sum(map(script.inside, fused)) >= 8
    assert sum(f.error_m < np.median(single[rr.rows_of(k)]) for k, f in enumerate(fused)) >= 8


def test_the_ray_through_the_pixel_beats_openathenas_ray(script, data, fused):
    rr, yaw = data
    oa = [script.fuse(rr, rr.rows_of(k), yaw, line_of_sight="answer") for k in range(len(rr.names))]
    assert np.median([f.error_m for f in oa]) > np.median([f.error_m for f in fused])
    assert sum(map(script.inside, oa)) < sum(map(script.inside, fused))
