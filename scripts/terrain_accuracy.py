"""Ray-terrain intersection accuracy and cost: pipeline.terrain against an independent reference.

    python scripts/terrain_accuracy.py [--rays 200] [--seed 1]

Two figures per synthetic DEM (pipeline.synth.dem), for random rays from 150-500 m above the terrain's base,
15-75 deg below the horizon, in every direction:

- `vs terrain`: the hit against the analytic terrain the DEM was sampled from (Hills: ridges of 80, 35 and 12 m
  amplitude, 2.4, 1.1 and 0.52 km wavelength), in metres and in DEM posts. This is the `dem` method's error on a
  perfect DEM of that post spacing: the bilinear interpolation between posts plus the ray caster's own error.
  A ray meeting a slope at a grazing angle a turns the DEM's height error dh into dh / sin(a) along the ground:
  `>=2deg` is the largest error in posts over rays meeting the terrain at 2 deg or more, `err*sin` the largest
  error times sin(a) over all rays (at most the DEM's interpolation error, whose bound is printed).
- `vs bilinear`: the hit against a surface that the DEM's bilinear grid represents exactly (a saddle
  a + b x + c y + d x y in the grid's coordinates): the ray caster's own error.

The reference hits come from dense sampling (every 0.5 m) and bisection along each ray on the analytic surface
(pipeline.synth.dem.ray_truth_ecef), sharing no code with the ray caster. Also prints the wall time per ray of one
vectorised call over all rays (median of 3 calls).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rasterio
from rasterio.crs import CRS
from rasterio.transform import from_origin

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pipeline.geometry.frames import ecef_from_lla  # noqa: E402
from pipeline.synth.dem import Hills, bilinear_error_bound_m, incidence_sin, ray_truth_ecef, write_dem  # noqa: E402
from pipeline.terrain import Dem  # noqa: E402

LAT0, LON0 = 46.5, 7.5
HILLS = Hills(LAT0, LON0, base_m=600.0)
CASES = (  # name, CRS, post (m), extent (m), stated vertical datum
    ("geographic 30 m, orthometric (assumed)", "EPSG:4326", 30.0, 6000.0, None),
    ("geographic 90 m, orthometric (assumed)", "EPSG:4326", 90.0, 6000.0, None),
    ("UTM 32N 30 m, EGM96 height", "EPSG:32632+5773", 30.0, 6000.0, None),
    ("UTM 32N 5 m, ellipsoidal (stated)", "EPSG:32632", 5.0, 6000.0, "ellipsoidal"),
    ("geographic 3-D 30 m, ellipsoidal", "EPSG:4979", 30.0, 6000.0, None),
)


def random_rays(n: int, rng: np.random.Generator):
    origins = np.column_stack([LAT0 + rng.uniform(-0.008, 0.008, n), LON0 + rng.uniform(-0.008, 0.008, n),
                               HILLS.base_m + 150 + rng.uniform(0, 350, n)])
    az = rng.uniform(0, 2 * np.pi, n)
    el = np.radians(rng.uniform(-75, -15, n))
    return origins, np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])


def saddle(lat, lon):
    x, y = np.asarray(lon) - LON0, np.asarray(lat) - LAT0
    return 600.0 + 900.0 * x - 400.0 * y + 2.0e5 * x * y


def write_saddle(path: Path, post_m: float) -> Path:
    dlat = post_m / 111_320.0
    dlon = dlat / np.cos(np.radians(LAT0))
    n = round(6000.0 / post_m) + 1
    lon = LON0 + dlon * (np.arange(n) - (n - 1) / 2)
    lat = LAT0 - dlat * (np.arange(n) - (n - 1) / 2)
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float64",
                       crs=CRS.from_epsg(4979),
                       transform=from_origin(lon[0] - dlon / 2, lat[0] + dlat / 2, dlon, dlat)) as ds:
        ds.write(saddle(lat[:, None], lon[None, :])[None])
    return path


def measure(dem: Dem, origins, dirs, truth_fn) -> tuple[np.ndarray, np.ndarray, float]:
    """Errors (m) of the hits, |sin| of the rays' incidence on the surface, and the wall time per ray (s)."""
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        lla, reasons = dem.intersect_many(origins, dirs)
        times.append(time.perf_counter() - t0)
    truth = ray_truth_ecef(origins, dirs, truth_fn)
    ok = np.array([r is None for r in reasons]) & np.isfinite(truth).all(axis=1)
    if not ok.all():
        print(f"  {int((~ok).sum())} ray(s) without a hit or a reference, left out")
    err = np.linalg.norm(ecef_from_lla(lla[ok, 0], lla[ok, 1], lla[ok, 2]) - truth[ok], axis=1)
    return err, incidence_sin(truth[ok], dirs[ok], truth_fn), float(np.median(times)) / len(origins)


def row(name: str, post: float, err: np.ndarray, sin_a: np.ndarray, per_ray_s: float) -> str:
    steep = sin_a > np.sin(np.radians(2.0))
    return (f"{name:42s} {post:5.0f} {err.size:5d} {np.median(err):10.3g} {np.percentile(err, 95):10.3g} "
            f"{err.max():10.3g} {err.max() / post:8.3g} {err[steep].max() / post:9.3g} {(err * sin_a).max():9.3g} "
            f"{per_ray_s * 1e3:8.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    head = (f"{'DEM':42s} {'post':>5s} {'rays':>5s} {'median m':>10s} {'p95 m':>10s} {'max m':>10s} "
            f"{'max/post':>8s} {'>=2deg':>9s} {'err*sin':>9s} {'ms/ray':>8s}")
    with tempfile.TemporaryDirectory() as tmp:
        print("vs terrain (analytic hills the DEM was sampled from)")
        print(head)
        for i, (name, crs, post, extent, stated) in enumerate(CASES):
            path = write_dem(Path(tmp) / f"hills{i}.tif", HILLS, extent_m=extent, post_m=post, crs=crs,
                             vertical_datum=stated)
            origins, dirs = random_rays(args.rays, rng)
            err, sin_a, per_ray = measure(Dem.open(path, vertical_datum=stated), origins, dirs, HILLS.h_wgs84_m)
            bound = bilinear_error_bound_m(HILLS, post)
            print(row(name, post, err, sin_a, per_ray) + f"  (DEM error bound {bound:.3g} m)")
        print("vs bilinear (a saddle the grid represents exactly: the ray caster's own error)")
        print(head)
        for post in (30.0, 90.0):
            dem = Dem.open(write_saddle(Path(tmp) / f"saddle{post:g}.tif", post))
            origins, dirs = random_rays(args.rays, rng)
            err, sin_a, per_ray = measure(dem, origins, dirs, saddle)
            print(row(f"geographic 3-D {post:g} m saddle, ellipsoidal", post, err, sin_a, per_ray))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
