"""Issue 12, item 4: when the mle's error model does not fit a flight, every output says so, not only the
console and the notes: estimates.csv (and estimates.geojson) give the fit message as the row's `reason`, the answer
in targets.kml says it, and report.html marks the estimate; an unsolved method shows its status in report.html."""

from __future__ import annotations

import csv
import io

import numpy as np

from pipeline.report.exports import estimates_csv_text, estimates_geojson, targets_kml
from pipeline.report.html import report_html
from pipeline.results import GroupResult
from pipeline.solve.estimate import Estimate, Status
from pipeline.solve.observations import Observations

MISFIT = ("the error model does not fit this flight: the residuals are 2.0 times larger than the error model says "
          "(chi-square 348 on 87 degrees of freedom, p = 1e-33); the covariance was inflated (ellipse axes x2.0) "
          "by what the residuals show, which cannot show an error that stays constant over the flight: the ellipse "
          "may still be too small")


def _group(name: str, consistent: bool) -> GroupResult:
    n = 3
    P = np.tile(np.hstack([np.eye(3), np.zeros((3, 1))]), (n, 1, 1))
    obs = Observations(P=P, pixel=np.array([[0.1, 0.2], [0.2, 0.1], [0.3, 0.1]]),
                       platform_m=np.array([[0.0, -1000, 500], [500, -1000, 500], [1000, -900, 500]]),
                       range_m=np.array([1200.0, 1250.0, 1300.0]), truth_m=np.zeros(3))
    # a misfit within the answer rule's 9 x (variance): the MLE is still the answer, and says it does not fit
    fit = {"consistent": consistent, "chi2": 348.0, "dof": 87.0, "p_value": 1e-33,
           "covariance_inflation": 4.0 if not consistent else 1.0, "message": None if consistent else MISFIT}
    mle = Estimate("mle", np.array([3.0, 4.0, 0.0]), 7, Status.CONVERGED, covariance_m2=np.diag([4.0, 9.0, 16.0]),
                   extras={"fit": fit, "rejected": []})
    vision = Estimate("vision", np.array([1.0, 1.0, 1.0]), 3, Status.CONVERGED)
    r = GroupResult(name=name, origin_lla=(34.0, 108.0, 400.0), observations=obs,
                    estimates={"vision": vision, "mle": mle}, truth_m=np.zeros(3), intersection_angle_deg=30.0,
                    timings_s={"solve": 0.01}, tracking={})
    r.settings["solve_failures"] = {"range": {"status": "degenerate", "reason": "range: the ranges are collinear"}}
    return r


def test_a_misfit_mle_row_says_why_in_targets_csv_geojson_and_kml():
    bad, good = _group("misfit", consistent=False), _group("fits", consistent=True)
    rows = {(t["group"], t["method"]): t for t in csv.DictReader(io.StringIO(estimates_csv_text([bad, good])))}
    assert rows[("misfit", "mle")]["reason"] == MISFIT and rows[("misfit", "mle")]["status"] == "converged"
    assert rows[("misfit", "mle")]["cep50_m"] != ""  # the inflated covariance is still given
    assert rows[("fits", "mle")]["reason"] == ""
    # vision on these three toy frames: its answer is not determined, so it is no point, and says why
    assert rows[("misfit", "vision")]["reason"].startswith("not determined: ")
    assert rows[("misfit", "vision")]["lat_deg"] == "" and rows[("misfit", "vision")]["determined"] == "false"
    feats = [f["properties"] for f in estimates_geojson([bad])["features"]
             if f["properties"]["kind"] == "estimate" and f["properties"]["method"] == "mle"]
    assert feats[0]["reason"] == MISFIT
    assert b"does not fit this flight" in targets_kml([bad])


def test_report_html_marks_a_misfit_mle_and_names_an_unsolved_methods_status():
    html = report_html([_group("misfit", consistent=False), _group("fits", consistent=True)], [], {},
                       figures={"misfit": {}, "fits": {}}, interactive=False)
    summary = html.split("(the paper's Table 4)</h2>")[1].split("</table>")[0]
    assert summary.count(" ‡") == 1 and f'title="{MISFIT}"' in summary
    assert summary.count('">degenerate</td>') == 2  # the unsolved range, with its reason as the cell's title
    misfit, fits = html.split('id="group-misfit"')[1].split('id="group-fits"')
    assert "converged ‡" in misfit and "‡" not in fits.split("<h2>Run settings")[0].split("</table>")[0]
    assert "<b>Laser ranging algorithm</b> (degenerate): range: the ranges are collinear" in misfit


def test_geojson_lines_of_sight_mark_the_observations_the_mle_rejected():
    r = _group("g", consistent=True)
    r.estimates["mle"].extras["rejected"] = [
        {"frame": 1, "t_ns": 1, "residual": "range", "value": 400.0, "sigmas": 80.0},
        {"frame": 2, "t_ns": 2, "residual": "u", "value": 60.0, "sigmas": 17.0},
        {"frame": 2, "t_ns": 2, "residual": "v", "value": 50.0, "sigmas": 14.0}]
    lines = {f["properties"]["frame"]: f["properties"] for f in estimates_geojson([r])["features"]
             if f["properties"]["kind"] == "line_of_sight"}
    assert [lines[i]["mle_rejected"] for i in (0, 1, 2)] == [None, "range", "u, v"]
