"""Photo zoo (docs/locate.md, "Evaluation"): generated DJI photo flights (`pipeline/synth/photos.py`: 5 photos with
laser, errors of a consumer drone without RTK drawn from families of their own: compass bias uniform 1-5 deg, gimbal
pitch bias +-0.5 deg, a wandering GNSS error of 0.5-2 m per axis, altitude datum offset +-30 m; targets on synthetic
hills with a GeoTIFF DEM), each written as JPEGs, read back and located by

  mle      all photos, marked pixels + laser ranges, under locate's default error model (pipeline/photo_errors.py)
  mle+dem  the same with the DEM as the MLE's terrain prior (as `ridgeloc locate --dem` runs it)
  dji      DJI's one-shot laser target of the first photo (drone-dji:LRFTarget*), as DJI Pilot shows it
  dji-mean the mean of the five one-shot targets
  dem      the ray through the first photo's marked pixel onto the DEM (OpenAthena's method)
  answer, answer+dem  the target's one answer (`pipeline.locate.photo_answer`, every method run, as `ridgeloc
           locate` and targets.csv give it: the MLE when its fit checks pass, else the most precise determined
           method; none where no method is determined), without and with the DEM

Prints horizontal and vertical median errors and, for the MLE and answer rows, the share of flights whose truth
lies in the 95 % horizontal ellipse (chi-square 2 dof) and in the 95 % ellipsoid (3 dof); a flight without an
answer counts as not holding it.

    python scripts/photo_zoo.py [--flights 100] [--seed 0] [--bias-prior-deg B] [--dem-sigma-m 5] [--rtk]
                                [--no-laser] [--wander-tau-s T]

--no-laser: photos without LRF tags, the target marked up to 150 px from the image centre (no dji rows).
--rtk: RTK-fixed flights instead (pipeline.synth.photos.RTK_FIXED_ERRORS: GNSS error 1-5 cm, datum offset +-0.3 m).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CHI2_2DOF_95 = 5.991464547107979
CHI2_3DOF_95 = 7.814727903251178
MLE_ROWS = ("mle", "mle+dem")
ANSWER_ROWS = ("answer", "answer+dem")


def run(n_flights: int, seed: int, bias_prior_deg: float | None, dem_sigma_m: float, workdir: Path,
        rtk: bool = False, laser: bool = True, wander_tau_s: float | None = None) -> dict:
    import pymap3d

    from pipeline.geometry.frames import enu_from_lla
    from pipeline.ingest.photo import read_photos
    from pipeline.locate import locate_photos, photo_answer
    from pipeline.photo_errors import photo_error_model
    from pipeline.synth.dem import Hills, write_dem
    from pipeline.synth.photos import RTK_FIXED_ERRORS, PhotoFlightSpec, simulate_photo_flight, write_photo_flight
    from pipeline.terrain import Dem

    hills = Hills(46.5, 7.5, base_m=600.0)
    dem_path = write_dem(workdir / "dem.tif", hills, extent_m=5000.0, post_m=30.0, crs="EPSG:32632")
    dem = Dem.open(dem_path)
    rng = np.random.default_rng(seed)
    rows = {m: [] for m in ("mle", "mle+dem", "answer", "answer+dem", "dji", "dji-mean", "dem")}
    inside = {m: ([], []) for m in MLE_ROWS + ANSWER_ROWS}
    failed = []
    methods = {row: {} for row in ANSWER_ROWS}  # how often each method was the answer
    for k in range(n_flights):
        e0, n0 = rng.uniform(-600, 600, 2)
        lat, lon, _ = np.ravel(pymap3d.enu2geodetic(e0, n0, 0.0, 46.5, 7.5, 0.0))
        spec = PhotoFlightSpec(seed=seed * 100_000 + k, lat_deg=float(lat), lon_deg=float(lon), hills=hills,
                               laser=laser, mark_offset_px=0.0 if laser else 150.0,
                               **(RTK_FIXED_ERRORS if rtk else {}))
        flight = simulate_photo_flight(spec)
        folder = workdir / f"f{k:03d}"
        write_photo_flight(flight, folder)
        photos, bad = read_photos([folder])
        assert not bad, bad
        truth = tuple(flight.truth["target_lla"])
        errors = photo_error_model(photos, **({} if wander_tau_s is None else {"wander_tau_s": wander_tau_s}))
        if bias_prior_deg is not None:
            errors = dataclasses.replace(errors, bias_prior_deg=bias_prior_deg)
        loc = locate_photos(photos, flight.marks_px, errors=errors)
        with_dem = locate_photos(photos, flight.marks_px, dem=dem, dem_sigma_m=dem_sigma_m, errors=errors)
        answers = {"answer": (loc, photo_answer(loc)),
                   "answer+dem": (with_dem, photo_answer(with_dem, dem, dem_sigma_m))}
        one = locate_photos(photos[:1], flight.marks_px[:1], dem=dem, methods=["dem"])

        def err(views, X, truth=truth):
            return enu_from_lla(*views.lla(X), origin_lla=truth)

        for row, res in (("mle", loc), ("mle+dem", with_dem)):
            if "mle" not in res.estimates:
                failed.append((k, row, res.unsolved.get("mle")))
                continue
            e = res.estimates["mle"]
            d = err(res.views, e.position_m)
            rows[row].append(d)
            cov = np.asarray(e.covariance_m2)
            inside[row][0].append(float(d[:2] @ np.linalg.solve(cov[:2, :2], d[:2])) <= CHI2_2DOF_95)
            inside[row][1].append(float(d @ np.linalg.solve(cov, d)) <= CHI2_3DOF_95)
        for row, (res, a) in answers.items():
            if not a.located:
                failed.append((k, row, a.reason))
                inside[row][0].append(False), inside[row][1].append(False)
                continue
            d = err(res.views, a.position_m)
            rows[row].append(d)
            cov = np.asarray(a.covariance_m2)
            inside[row][0].append(float(d[:2] @ np.linalg.solve(cov[:2, :2], d[:2])) <= CHI2_2DOF_95)
            inside[row][1].append(float(d @ np.linalg.solve(cov, d)) <= CHI2_3DOF_95)
            methods[row][a.method] = methods[row].get(a.method, 0) + 1
        if "dji" in loc.estimates:
            pts = np.array(loc.estimates["dji"].extras["points_m"])
            rows["dji"].append(err(loc.views, pts[0]))
            rows["dji-mean"].append(err(loc.views, pts.mean(axis=0)))
        if "dem" in one.estimates:
            rows["dem"].append(err(one.views, one.estimates["dem"].position_m))
        else:
            failed.append((k, "dem", one.unsolved.get("dem")))
    return {"rows": {m: np.array(v) for m, v in rows.items()},
            "inside": {m: (np.array(h), np.array(s)) for m, (h, s) in inside.items()}, "failed": failed,
            "methods": methods,
            "errors": errors}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bias-prior-deg", type=float, default=None,
                    help="the compass bias prior instead of the error model's (pipeline/photo_errors.py)")
    ap.add_argument("--dem-sigma-m", type=float, default=5.0, help="the DEM's stated vertical sigma (as --dem-sigma-m)")
    ap.add_argument("--no-laser", action="store_true",
                    help="photos without laser (a consumer drone), the target up to 150 px from the centre")
    ap.add_argument("--rtk", action="store_true",
                    help="RTK-fixed flights (RtkFlag 50, centimetre GNSS, datum known to a decimetre)")
    ap.add_argument("--wander-tau-s", type=float, default=None,
                    help="the wandering errors' correlation time instead of the error model's (s; 1e12: all shared, "
                         "the per-photo sigmas the photo-to-photo noise alone)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        res = run(args.flights, args.seed, args.bias_prior_deg, args.dem_sigma_m, Path(tmp), rtk=args.rtk,
                  laser=not args.no_laser, wander_tau_s=args.wander_tau_s)
    e = res["errors"]
    print(f"{args.flights} flights, seed {args.seed}; error model (the last flight's): {e.source}, compass bias prior "
          f"{e.bias_prior_deg} deg, shared offset {e.shared_h_m} m horizontal / {e.shared_v_m} m vertical, "
          f"per photo {e.sigma.to_dict()}; DEM sigma {args.dem_sigma_m} m")
    print("method     n   median horiz m   p90 horiz m   median |vert| m   95 % ellipse / ellipsoid holds truth")
    for m, d in res["rows"].items():
        if len(d) == 0:
            print(f"{m:9s}  0")
            continue
        h = np.hypot(d[:, 0], d[:, 1])
        cover = ""
        if m in res["inside"]:
            ih, i3 = res["inside"][m]
            cover = (f"   {ih.mean() * 100:5.1f} % ({ih.sum()}/{ih.size}) / "
                     f"{i3.mean() * 100:5.1f} % ({i3.sum()}/{i3.size})")
        print(f"{m:9s} {len(d):3d}   {np.median(h):13.2f}   {np.percentile(h, 90):11.2f}   "
              f"{np.median(np.abs(d[:, 2])):14.2f}{cover}")
    for m, counts in res["methods"].items():
        print(f"{m} from: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1])))
    for f in res["failed"]:
        print("unsolved:", f)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
