"""`ridgeloc locate PHOTO... [--dem DEM.tif] [--pixel X Y | --marks FILE] [--json]`: a target from drone photos."""

from __future__ import annotations

import argparse
import json
import sys

HELP = ("locate a target from drone photos (DJI, Skydio, Parrot, Teal, Autel): one answer from a photo and a pixel "
        "(laser, DEM or level ground) or from several photos")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("photos", nargs="+", metavar="PHOTO",
                        help="drone JPEG photos (DJI, Skydio, Parrot, Teal, Autel; docs/ingest.md), or folders of them")
    parser.add_argument("--dem", metavar="DEM.tif", help="a GeoTIFF terrain model: adds the `dem` method")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--pixel", nargs=2, type=float, metavar=("X", "Y"),
                       help="the target pixel in every photo (default: the image centre, where the laser points)")
    where.add_argument("--marks", metavar="FILE",
                       help="CSV with a header `photo,x_px,y_px`, or the marks CSV `ridgeloc mark` saves (one "
                            "target): the target pixel per photo (file name); photos not listed have no pixel")
    parser.add_argument("--alt-datum", choices=("amsl", "ellipsoid"), default=None,
                        help="datum of drone-dji:AbsoluteAltitude / EXIF GPSAltitude (default amsl; docs/ingest.md)")
    parser.add_argument("--image-rotation", type=int, choices=(0, 180), default=None,
                        help="180 when the files were turned upside down after capture, 0 when not (default: found "
                             "from two or more marked photos where a desktop program re-saved them; docs/locate.md)")
    parser.add_argument("--bias-prior-deg", type=float, default=None,
                        help="1-sigma prior of the compass/gimbal-yaw bias constant over the flight (default 3; 0: no "
                             "bias state; docs/locate.md, \"Error model\")")
    parser.add_argument("--position-sigma-m", type=float, default=None,
                        help="1-sigma horizontal position offset shared by the photos, per axis (default by RtkFlag: "
                             "1.5 without RTK, RtkStdLon/Lat or 0.5 float, 0.05 fixed)")
    parser.add_argument("--alt-sigma-m", type=float, default=None,
                        help="1-sigma altitude offset shared by the photos (GNSS and datum; default 15 without RTK, "
                             "RtkStdHgt or 1 float, 0.3 fixed)")
    parser.add_argument("--dem-sigma-m", type=float, default=None,
                        help="the DEM's vertical error at the target, 1 sigma (m): adds the DEM as the MLE's terrain "
                             "prior (default: none, the `dem` method only; docs/terrain.md says what to state)")
    parser.add_argument("--dem-datum", choices=("orthometric", "ellipsoidal"), default=None,
                        help="the DEM's heights, when its file does not say or says something ridgeloc does not know "
                             "(docs/terrain.md)")
    level = parser.add_mutually_exclusive_group()
    level.add_argument("--ground", choices=("takeoff",), default=None,
                       help="without laser or DEM: assume the target on level ground at the take-off point's height "
                            "(altitude minus the height above take-off, where the photo states both): the `ground` "
                            "method, a weaker answer (docs/locate.md)")
    level.add_argument("--ground-height-m", type=float, default=None, metavar="H",
                       help="as --ground, with the ground at H m on the photos' altitude datum (AMSL unless "
                            "--alt-datum ellipsoid)")
    parser.add_argument("--ground-sigma-m", type=float, default=None, metavar="S",
                        help="1-sigma error of the assumed ground at the target (default 5 m for the take-off "
                             "ground's relief, 2 m for a stated height)")
    parser.add_argument("-o", "--outdir", default=None,
                        help="also write the run outputs there: targets.csv/.geojson/.kml (the answer), estimates.csv/"
                             ".geojson (every method), report.html, run.json (docs/outputs.md)")
    parser.add_argument("--name", default=None,
                        help="the name in the outputs (default: the first photo's folder name); a marks CSV of "
                             "`ridgeloc mark` adds its target's name: NAME:TARGET, as `ridgeloc run` names it")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the results of another run in the --outdir folder")
    parser.add_argument("--json", action="store_true", help="print one JSON document, the answer first")
    from pipeline.commands.send import add_tak_arguments

    add_tak_arguments(parser)


def stated_errors(photos, args):
    """The photos' default error model (pipeline.photo_errors) with what the user stated on the command line."""
    import dataclasses

    from pipeline.errors import InputError
    from pipeline.photo_errors import photo_error_model

    errors = photo_error_model(photos)
    given = {"bias_prior_deg": args.bias_prior_deg, "shared_h_m": args.position_sigma_m,
             "shared_v_m": args.alt_sigma_m}
    for key, flag in (("bias_prior_deg", "--bias-prior-deg"), ("shared_h_m", "--position-sigma-m"),
                      ("shared_v_m", "--alt-sigma-m")):
        v = given[key]
        if v is not None and not (v >= 0 and v < float("inf")):
            raise InputError(f"{flag} must be a finite number >= 0, got {v}")
    given = {k: float(v) for k, v in given.items() if v is not None}
    if given:
        errors = dataclasses.replace(errors, source=errors.source + " (stated: " + ", ".join(
            f"{k} {v:g}" for k, v in given.items()) + ")", **given)
    return errors


def _default_name(paths) -> str:
    """The target's name when --name is not given: the folder of the first photo (or the folder given)."""
    from pathlib import Path

    first = Path(paths[0]).resolve()
    return (first if first.is_dir() else first.parent).name or "photos"


def main(args) -> int:
    from pipeline.commands import read_photos_reporting
    from pipeline.commands.send import check_send_args, cot_options
    from pipeline.errors import InputError
    from pipeline.locate import (
        check_pixels,
        estimate_row,
        locate_photos,
        marks_target_name,
        read_marks,
        unmarked_reason,
    )
    from pipeline.report.cot import check_flight_name

    cot = cot_options(args)  # a bad CoT type, stale time, URL, certificate or name is refused before any work
    check_send_args(args, args.send)
    check_flight_name(args.name or _default_name(args.photos))
    if args.outdir is not None:  # refused before any work: a file there, or another run's results
        from pathlib import Path

        from pipeline.commands import output_folder
        from pipeline.report.outputs import claim_output_folder

        output_folder(args.outdir)
        claim_output_folder(args.outdir, [args.name or _default_name(args.photos)], args.overwrite)
    terrain = None
    if args.dem_sigma_m is not None and not args.dem:
        raise InputError("--dem-sigma-m is the DEM's vertical error: give the DEM with --dem")
    if args.dem_datum is not None and not args.dem:
        raise InputError("--dem-datum is the DEM's vertical datum: give the DEM with --dem")
    if args.ground_sigma_m is not None and args.ground is None and args.ground_height_m is None:
        raise InputError("--ground-sigma-m is the assumed ground's error: give --ground takeoff or --ground-height-m")
    ground = None
    if args.ground is not None or args.ground_height_m is not None:
        from pipeline.locate import GroundAssumption

        ground = GroundAssumption("takeoff" if args.ground else "height", args.ground_height_m, args.ground_sigma_m)
    if args.dem:
        from pipeline.flight_config import Terrain

        try:
            terrain = Terrain(dem=args.dem, vertical_sigma_m=args.dem_sigma_m, vertical_datum=args.dem_datum)
        except ValueError:
            raise InputError(f"--dem-sigma-m must be a finite number > 0, got {args.dem_sigma_m}") from None
    photos, bad = read_photos_reporting(args.photos, alt_datum=args.alt_datum)
    target = None
    if args.marks:
        pixels = read_marks(args.marks, photos)
        target = marks_target_name(args.marks)  # the name typed on the marks page: NAME:TARGET, as `run` names it
    elif args.pixel:
        pixels = [args.pixel] * len(photos)
    else:
        pixels = None
    if pixels is not None:
        check_pixels(photos, pixels)
    from pipeline.terrain.flight import open_flight_dem

    dem = open_flight_dem(terrain)
    errors = stated_errors(photos, args)
    loc = locate_photos(photos, pixels, dem=dem, rotation_deg=args.image_rotation, errors=errors,
                        dem_sigma_m=args.dem_sigma_m, ground=ground)
    from pathlib import Path

    from pipeline.locate import location_result
    from pipeline.report.answers import answer_row, answers_text
    from pipeline.report.labels import one_decimal

    notes = list(loc.notes)
    if dem is not None and args.dem_sigma_m is None:
        notes.append("the DEM serves the dem method only: state its vertical error with --dem-sigma-m to add it to "
                     "the mle as a terrain prior (docs/terrain.md)")
    name = args.name or _default_name(args.photos)
    result = location_result(name, {"command": "locate", "photos": [p.path for p in photos]}, loc, notes,
                             target=target, dem=dem, dem_sigma_m=args.dem_sigma_m,
                             unmarked=unmarked_reason(loc, pixels, "--marks, --pixel"))
    answer = answer_row(result)
    if args.outdir is None and answer["status"] != "located":  # no estimates.csv to point to: the list below
        answer["reason"] = answer["reason"].replace(
            "estimates.csv says why for each", "`estimates` says why for each" if args.json
            else "the list of every method says why for each")
    rows = {m: estimate_row(e, loc.views) for m, e in loc.estimates.items()}
    for m, (status, reason) in loc.unsolved.items():
        rows[m] = {"status": status, "reason": reason}
    doc = {"answer": answer, "photos": [p.path for p in photos],
           "bad_photos": [{"path": p, "error": e} for p, e in bad],
           "origin_lla": list(loc.views.origin_lla), "ranges_used": int(loc.obs.has_range.sum()),
           "error_model": loc.errors.to_dict(), "estimates": rows, "notes": notes}
    if args.outdir is not None:
        from pipeline.report.outputs import write_run_outputs

        write_run_outputs(args.outdir, [result], [], {"command": "locate", "outdir": str(args.outdir)},
                          rewrite_groups=True, cot=cot)
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(answers_text([answer]))
        print(f"\n{len(photos)} photo(s), {doc['ranges_used']} laser range(s) used"
              + (f", {len(bad)} unreadable" if bad else "") + "; every method:")
        for m, r in rows.items():
            if "lat_deg" in r:
                cep = "" if r["cep50_m"] is None else f"  CEP50 {r['cep50_m']:.2f} m"
                # rounded as targets.csv is before shown as the answer's line is: the answer's method prints the
                # same digits (651.0504 m is 651.05 there, shown 651.0; here it was 651.1)
                lat, lon, h, msl = (round(r[k], d) for k, d in (("lat_deg", 8), ("lon_deg", 8), ("h_m", 3),
                                                                 ("alt_msl_m", 3)))
                print(f"  {m:10s} {lat:.7f} {lon:.7f}  h {one_decimal(h)} m (ellipsoid)  {one_decimal(msl)} m "
                      f"MSL{cep}")
            else:
                print(f"  {m:10s} {r['status']}: {r['reason']}")
        for note in doc["notes"]:
            print(f"note: {note}")
        if args.outdir is not None:
            print(f"wrote {Path(args.outdir) / 'targets.csv'} and the rest of the run outputs in {args.outdir}")
    sent = 0
    if args.send:
        from pipeline.commands.send import send_events_to, send_run_outputs
        from pipeline.report.cot import cot_entries

        sent = (send_run_outputs(args.outdir, args) if args.outdir is not None
                else send_events_to([e.xml for e in cot_entries([result], options=cot)], args.send, args))
    if answer["status"] != "located":  # exit 0 only with an answer
        print(f"ridgeloc: error: the target is not located: {answer['reason']}",
              file=sys.stderr)
        return 1
    return 1 if bad or sent else 0
