"""Photo zoo (docs/locate.md, "Evaluation"): generated DJI photo flights (5 photos with laser, a compass bias of
1-5 deg constant per flight, an altitude datum offset of up to +-30 m, a GNSS offset shared by the flight's
photos and a little noise per photo, attitude jitter; targets on
synthetic hills with a GeoTIFF DEM), each written as JPEGs, read back and located by

  mle      all photos, marked pixels + laser ranges, PHOTO_SIGMA (the largest compass bias 5 deg, its size learned)
  dji      DJI's one-shot laser target of the first photo (drone-dji:LRFTarget*), as DJI Pilot shows it
  dji-mean the mean of the five one-shot targets
  dem      the ray through the first photo's marked pixel onto the DEM (OpenAthena's method)

Prints horizontal and vertical median errors and the share of flights whose truth lies in the MLE's 95 %
horizontal ellipse (chi-square 2 dof).

    python scripts/photo_zoo.py [--flights 100] [--seed 0] [--sigma default|matched] [--bias-prior-deg B]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CHI2_2DOF_95 = 5.991464547107979


def run(n_flights: int, seed: int, bias_prior_deg: float | None, workdir: Path, sigma=None) -> dict:
    from pipeline.geometry.frames import enu_from_lla
    from pipeline.ingest.photo import read_photos
    from pipeline.locate import locate_photos
    from pipeline.synth.dem import Hills, write_dem
    from pipeline.synth.photos import PhotoFlightSpec, simulate_photo_flight, write_photo_flight
    from pipeline.terrain import Dem

    hills = Hills(46.5, 7.5, base_m=600.0)
    dem_path = write_dem(workdir / "dem.tif", hills, extent_m=5000.0, post_m=30.0, crs="EPSG:32632")
    dem = Dem.open(dem_path)
    rng = np.random.default_rng(seed)
    rows = {m: [] for m in ("mle", "dji", "dji-mean", "dem")}
    inside, failed = [], []
    for k in range(n_flights):
        e0, n0 = rng.uniform(-600, 600, 2)
        lat, lon, _ = np.ravel(__import__("pymap3d").enu2geodetic(e0, n0, 0.0, 46.5, 7.5, 0.0))
        spec = PhotoFlightSpec(seed=seed * 100_000 + k, lat_deg=float(lat), lon_deg=float(lon), hills=hills)
        flight = simulate_photo_flight(spec)
        folder = workdir / f"f{k:03d}"
        write_photo_flight(flight, folder)
        photos, bad = read_photos([folder])
        assert not bad, bad
        truth = tuple(flight.truth["target_lla"])
        loc = locate_photos(photos, flight.marks_px, bias_prior_deg=bias_prior_deg, methods=["mle", "dji"],
                            **({} if sigma is None else {"sigma": sigma}))
        one = locate_photos(photos[:1], flight.marks_px[:1], dem=dem, methods=["dem"])

        def err(views, X, truth=truth):
            return enu_from_lla(*views.lla(X), origin_lla=truth)

        if "mle" in loc.estimates:
            e = loc.estimates["mle"]
            d = err(loc.views, e.position_m)
            rows["mle"].append(d)
            cov = np.asarray(e.covariance_m2)[:2, :2]
            inside.append(float(d[:2] @ np.linalg.solve(cov, d[:2])) <= CHI2_2DOF_95)
        else:
            failed.append((k, "mle", loc.unsolved.get("mle")))
        pts = np.array(loc.estimates["dji"].extras["points_m"])
        rows["dji"].append(err(loc.views, pts[0]))
        rows["dji-mean"].append(err(loc.views, pts.mean(axis=0)))
        if "dem" in one.estimates:
            rows["dem"].append(err(one.views, one.estimates["dem"].position_m))
        else:
            failed.append((k, "dem", one.unsolved.get("dem")))
    return {"rows": {m: np.array(v) for m, v in rows.items()}, "inside": np.array(inside), "failed": failed}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bias-prior-deg", type=float, default=None)
    ap.add_argument("--sigma", choices=("default", "matched"), default="default",
                    help="the MLE's stated sigmas: locate's defaults (PHOTO_SIGMA), or the generator's own noise")
    args = ap.parse_args()
    from pipeline.solve.observations import Sigma
    from pipeline.synth.photos import PhotoFlightSpec

    spec = PhotoFlightSpec()
    sigma = None if args.sigma == "default" else Sigma(
        pixel_px=spec.mark_sigma_px, range_m=spec.laser_sigma_m,
        position_m=float(np.hypot(spec.gnss_offset_sigma_m[0], spec.gnss_noise_sigma_m[0])),
        attitude_deg=spec.compass_bias_deg[1])  # the largest bias the generator draws

    bias = args.bias_prior_deg
    with tempfile.TemporaryDirectory() as tmp:
        res = run(args.flights, args.seed, bias, Path(tmp), sigma)
    print(f"{args.flights} flights, seed {args.seed}, sigmas {args.sigma}, "
          + ("bias size learned" if bias is None else f"fixed bias prior {bias} deg"))
    print("method     n   median horiz m   p90 horiz m   median |vert| m")
    for m, d in res["rows"].items():
        if len(d) == 0:
            print(f"{m:9s}  0")
            continue
        h = np.hypot(d[:, 0], d[:, 1])
        print(f"{m:9s} {len(d):3d}   {np.median(h):13.2f}   {np.percentile(h, 90):11.2f}   "
              f"{np.median(np.abs(d[:, 2])):14.2f}")
    ins = res["inside"]
    print(f"mle 95 % horizontal ellipse holds the truth in {ins.mean() * 100:.1f} % ({ins.sum()}/{ins.size})")
    for f in res["failed"]:
        print("unsolved:", f)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
