import csv
import io

import numpy as np

from pipeline.report.table4 import report_markdown, table4_csv_text, write_table4
from pipeline.results import GroupFailure, GroupResult
from pipeline.solve.estimate import Estimate, Status
from pipeline.solve.observations import Observations


def _result(name, truth, positions, angle=30.0):
    n = 3
    P = np.tile(np.hstack([np.eye(3), np.zeros((3, 1))]), (n, 1, 1))
    obs = Observations(P=P, pixel=np.array([[0.1, 0.2], [np.nan, np.nan], [0.3, 0.1]]),
                       platform_m=np.array([[0.0, -1000, 500], [500, -1000, 500], [1000, -900, 500]]),
                       range_m=np.array([1200.0, np.nan, 1300.0]), truth_m=truth)
    ests = {m: Estimate(m, np.asarray(p, float), 3, Status.CONVERGED, covariance_m2=np.eye(3) if m == "mle" else None)
            for m, p in positions.items()}
    return GroupResult(name=name, origin_lla=(34.0, 108.0, 400.0), observations=obs, estimates=ests,
                       truth_m=None if truth is None else np.asarray(truth, float), intersection_angle_deg=angle,
                       timings_s={"ingest": 0.1, "track": 0.2, "sync": 0.01, "solve": 0.02},
                       tracking={"correlation": [1.0, None, 0.9], "lost": [False, True, False]})


def test_csv_layout_errors_and_blanks():
    a = _result("group1", [0.0, 0.0, 0.0], {"mle": [3.0, 4.0, 0.0], "ridge": [0.0, 0.0, 10.0]})
    b = _result("group2", None, {"mle": [1.0, 1.0, 1.0]}, angle=24.5)
    rows = list(csv.reader(io.StringIO(table4_csv_text([a, b]))))
    assert rows[0] == ["method", "group1", "group2"]
    body = {r[0]: r[1:] for r in rows[1:]}
    assert [r[0] for r in rows[1:]] == ["ridge", "mle", "intersection_angle_deg", "observations"]  # Table 4 order
    assert body["mle"] == ["5.000", ""]  # no truth: no error
    assert body["ridge"] == ["10.000", ""]  # not run for group2
    assert body["intersection_angle_deg"] == ["30.00", "24.50"]
    assert body["observations"] == ["3", "3"]


def test_markdown_has_paper_beside_ours_estimates_and_failures(tmp_path):
    a = _result("group2", [0.0, 0.0, 0.0], {"ridge": [0.0, 0.0, 10.0], "mle": [3.0, 4.0, 0.0]})
    md = report_markdown([a], [GroupFailure("group9", "cfg.yaml", "cfg.yaml: files.video: file not found")])
    assert "| paper:ridge | 46.33 |" in md and "| ours:ridge | 10.00 |" in md
    assert "**5.00**" in md  # the best of the group in bold
    assert "| Intersection angle (deg) | 30.00 |" in md and "| paper: intersection angle (deg) | 24.03 |" in md
    assert "34.0000000" in md  # the origin's latitude; estimates are given as WGS84 too
    assert "group9 (cfg.yaml): cfg.yaml: files.video: file not found" in md
    md_path, csv_path = write_table4(tmp_path / "out", [a])
    assert md_path.read_text().startswith("# ridgeloc run report") and csv_path.exists()
    assert not list((tmp_path / "out").glob(".tmp-*"))


def test_a_failed_method_keeps_its_row_in_table4_and_estimates_csv():
    """docs/outputs.md promises one row per (group, method) in estimates.csv: a method asked for that could not run
    keeps it, with empty values, status `failed` and its reason."""
    from pipeline.report.exports import estimates_csv_text

    a = _result("group1", [0.0, 0.0, 0.0], {"mle": [3.0, 4.0, 0.0]})
    a.settings["solve_failures"] = {"range": "degenerate geometry: the ranges are collinear"}
    b = _result("group2", [0.0, 0.0, 0.0], {"mle": [1.0, 0.0, 0.0], "range": [0.0, 2.0, 0.0]})
    rows = list(csv.reader(io.StringIO(table4_csv_text([a, b]))))
    body = {r[0]: r[1:] for r in rows[1:]}
    assert body["range"] == ["", "2.000"] and body["mle"] == ["5.000", "1.000"]
    targets = list(csv.DictReader(io.StringIO(estimates_csv_text([a, b]))))
    assert [(t["group"], t["method"]) for t in targets] == [("group1", "range"), ("group1", "mle"),
                                                             ("group2", "range"), ("group2", "mle")]
    failed = targets[0]
    assert failed["status"] == "failed" and "collinear" in failed["reason"]
    assert failed["lat_deg"] == failed["error_m"] == failed["converged"] == failed["alt_msl_m"] == ""
    assert targets[1]["status"] == "converged" and targets[1]["reason"] == "" and targets[1]["error_m"] == "5.0"
    md = report_markdown([a, b])
    assert "| range | — | — | — | — |  | failed | — |" in md


def test_tracking_lost_count_counts_dropped_frames_too():
    """hard_outliers: 2 of 14 frames lost, one then dropped (no range either): the table says 2, as the note."""
    a = _result("hard", [0.0, 0.0, 0.0], {"mle": [3.0, 4.0, 0.0]})
    a.tracking = {"correlation": [1.0, None, 0.9, None], "lost": [False, True, False, True],
                  "used": [True, True, True, False]}
    md = report_markdown([a])
    row = next(ln for ln in md.splitlines() if ln.startswith("| hard | 3 |"))
    assert row.split(" | ")[2] == "2"


def test_a_failure_given_as_status_and_reason_keeps_both():
    """`ridgeloc solve --json` lists unsolved methods as {status, reason}: the exports take either form."""
    from pipeline.report.exports import estimates_csv_text

    a = _result("group1", [0.0, 0.0, 0.0], {"mle": [3.0, 4.0, 0.0]})
    a.settings["solve_failures"] = {"range": {"status": "degenerate", "reason": "ranges collinear"}}
    targets = list(csv.DictReader(io.StringIO(estimates_csv_text([a]))))
    assert (targets[0]["method"], targets[0]["status"], targets[0]["reason"]) == ("range", "degenerate",
                                                                                  "ranges collinear")
    assert "| range | — | — | — | — |  | degenerate | — |" in report_markdown([a])


def test_table4_csv_gives_an_unsolved_methods_status_and_reason():
    """Issue 12: an unsolved method keeps its row in table4.csv with empty values, and its status and reason
    per group (rows status:<method>, reason:<method>, after the numeric rows; empty where it solved)."""
    a = _result("group1", [0.0, 0.0, 0.0], {"mle": [3.0, 4.0, 0.0]})
    a.settings["solve_failures"] = {"range": {"status": "degenerate", "reason": "range: the ranges are collinear"}}
    b = _result("group2", [0.0, 0.0, 0.0], {"mle": [1.0, 0.0, 0.0], "range": [0.0, 2.0, 0.0]})
    rows = list(csv.reader(io.StringIO(table4_csv_text([a, b]))))
    assert [r[0] for r in rows[1:]] == ["range", "mle", "intersection_angle_deg", "observations", "status:range",
                                        "reason:range"]
    body = {r[0]: r[1:] for r in rows[1:]}
    assert body["range"] == ["", "2.000"]
    assert body["status:range"] == ["degenerate", ""]
    assert body["reason:range"] == ["range: the ranges are collinear", ""]
    # nothing unsolved: no status rows
    assert [r[0] for r in csv.reader(io.StringIO(table4_csv_text([b])))][-1] == "observations"


def test_report_md_says_an_unsolved_methods_status_and_reason_in_words():
    """The group's notes give `range not solved (degenerate): <reason>`, not the Python repr of a mapping."""
    a = _result("group1", [0.0, 0.0, 0.0], {"mle": [3.0, 4.0, 0.0]})
    a.settings["solve_failures"] = {"range": {"status": "degenerate", "reason": "range: the ranges are collinear"},
                                    "los": "no frame with both a pixel and a range"}
    md = report_markdown([a])
    assert "- range not solved (degenerate): the ranges are collinear" in md
    assert "- los not solved (failed): no frame with both a pixel and a range" in md
    assert "{'status'" not in md and "'reason'" not in md


def test_photo_methods_have_names_and_no_empty_paper_rows():
    """A run of video and photo flights: the photo methods (`dem`, `dji`) are named in Table 4, estimates.csv and the
    report's legend as the others are (they read 'dem: dem'), have their own colours, and the paper comparison of
    the video groups gets no row of dashes for them."""
    from pipeline.report.exports import estimates_csv_text
    from pipeline.report.labels import METHOD_COLORS, method_label

    video = _result("group1", [0.0, 0.0, 0.0], {"ridge": [0.0, 0.0, 10.0], "mle": [3.0, 4.0, 0.0]})
    photos = _result("h20", [0.0, 0.0, 0.0], {"mle": [1.0, 0.0, 0.0], "dem": [0.0, 2.0, 0.0], "dji": [0.0, 0, 3]})
    md = report_markdown([video, photos])
    assert "| Ray into the terrain model (DEM) | `dem` |" in md and "| DJI's own laser target | `dji` |" in md
    assert "ours:dem" not in md and "ours:dji" not in md and "| ours:mle | 5.00 |" in md
    rows = {r["method"]: r for r in csv.DictReader(io.StringIO(estimates_csv_text([photos])))}
    assert rows["dem"]["method_label"] != "dem" and rows["dji"]["method_label"] != "dji"
    assert all(method_label(m) != m for m in ("dem", "dji", "ground"))
    assert len({METHOD_COLORS[m] for m in ("dem", "dji", "ground", *METHOD_COLORS)}) == len(METHOD_COLORS)
