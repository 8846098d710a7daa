"""`ridgeloc run` writes one CoT event per located answer (OUT/cot/) and a TAK data package (OUT/targets.zip), on
three of the sample flights (video, three named targets, drone photos), run twice into two folders, the second
time with --send to a loopback UDP listener.

Checked against what the outputs were made from, not against the writer's own numbers: each event's point
against targets.csv and against the answer's ENU position in result.json converted here with pymap3d; ce and le
against CE90 and LE90 computed here from the answer's covariance (CE90 by integrating the horizontal Gaussian over
a disc, not with ridgeloc's code); the package as ATAK's importer reads one (tests/support/tak.py).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from scipy import integrate, optimize

from pipeline.cli import main as cli_main
from support.tak import UdpListener, atak_import, parse_event

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ("group1", "three_targets", "h20_laser")
Z90 = 1.6448536269514722  # the standard normal's 90 % two-sided quantile


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two runs of the same flights into two folders; the second sends its events to a UDP listener."""
    tmp = tmp_path_factory.mktemp("tak_runs")
    config = tmp / "run.yaml"
    config.write_text("groups:\n" + "".join(f"  - {ROOT / 'configs' / 'flights' / f}.yaml\n" for f in FLIGHTS))
    assert cli_main(["run", str(config), "-o", str(tmp / "a"), "--no-figures", "-q"]) == 0
    with UdpListener() as listener:
        code = cli_main(["run", str(config), "-o", str(tmp / "b"), "--no-figures", "-q", "--send",
                         f"udp://127.0.0.1:{listener.port}", "--cot-stale", "2h"])
        n = len(list((tmp / "b" / "cot").glob("*.cot")))
        received = listener.wait_for(n, 10)
    assert code == 0
    return tmp / "a", tmp / "b", received


def _events(out: Path) -> dict:
    """callsign -> (uid, CotEvent) of OUT/cot/*.cot."""
    events = {}
    for f in sorted((out / "cot").glob("*.cot")):
        e = parse_event(f.read_bytes()).cotEvent
        events[e.detail.contact.callsign] = e
    return events


def _answers(out: Path) -> dict:
    """target name (targets.csv's `name`) -> (answer dict of result.json, origin_lla)."""
    answers = {}
    for flight in FLIGHTS:
        doc = json.loads((out / flight / "result.json").read_text())
        for r in doc.get("targets") or [doc]:
            name = r["name"] if r.get("target") is None else f"{r['name']}:{r['target']}"
            answers[name] = (r["answer"], r["origin_lla"])
    return answers


def ce90_by_integration(cov2: np.ndarray) -> float:
    """Radius of the disc holding 90 % of a zero-mean 2-D Gaussian of covariance `cov2`: P(r) = 1 / (2 pi
    sqrt|C|) * integral over theta of (1 - exp(-r^2 a / 2)) / a, a = u' C^-1 u (polar coordinates)."""
    inv, det = np.linalg.inv(cov2), np.linalg.det(cov2)

    def a(theta):
        u = np.array([math.cos(theta), math.sin(theta)])
        return float(u @ inv @ u)

    def p(r):
        return integrate.quad(lambda t: (1 - math.exp(-r * r * a(t) / 2)) / a(t), 0, 2 * math.pi,
                              limit=200)[0] / (2 * math.pi * math.sqrt(det))

    top = 10 * math.sqrt(np.trace(cov2))
    return optimize.brentq(lambda r: p(r) - 0.9, 1e-9, top, xtol=1e-9)


def test_one_event_per_located_answer_at_the_answers_point(runs):
    out, _, _ = runs
    rows = list(csv.DictReader((out / "targets.csv").open()))
    located = {r["name"]: r for r in rows if r["status"] == "located"}
    events = _events(out)
    assert len(located) == 7 and set(events) == set(located)
    for name, e in events.items():
        row = located[name]
        assert abs(e.lat - float(row["lat_deg"])) <= 1e-7 and abs(e.lon - float(row["lon_deg"])) <= 1e-7
        assert abs(e.hae - float(row["alt_m"])) <= 0.01  # hae: WGS84 ellipsoidal, as alt_m
        assert (e.type, e.how) == ("a-u-G", "m-f")


def test_the_point_is_the_answers_position_and_ce_le_are_ce90_le90_of_its_covariance(runs):
    out, _, _ = runs
    answers = _answers(out)
    events = _events(out)
    for name, e in events.items():
        answer, origin = answers[name]
        assert answer["status"] == "located"
        lat, lon, h = pymap3d.enu2geodetic(*answer["position_m"], *origin)
        assert abs(e.lat - lat) <= 1e-7 and abs(e.lon - lon) <= 1e-7 and abs(e.hae - h) <= 0.01, name
        cov = np.asarray(answer["covariance_m2"])
        ce90 = ce90_by_integration(cov[:2, :2])
        le90 = Z90 * math.sqrt(cov[2, 2])
        assert e.ce == pytest.approx(ce90, rel=1e-3, abs=0.01), name
        assert e.le == pytest.approx(le90, rel=1e-3, abs=0.01), name
        # the schema's 1-sigma reading would be smaller: for these ellipses CE90 is about 2.1 x sigma
        assert e.ce > 1.9 * math.sqrt(np.trace(cov[:2, :2]) / 2), name


def test_two_runs_of_the_same_flights_give_the_same_uids(runs):
    a, b, _ = runs
    uids_a = {n: e.uid for n, e in _events(a).items()}
    uids_b = {n: e.uid for n, e in _events(b).items()}
    assert uids_a == uids_b and len(set(uids_a.values())) == len(uids_a) == 7


def test_the_data_package_imports_with_every_event(runs):
    out, _, _ = runs
    imported = atak_import((out / "targets.zip").read_bytes())
    assert set(imported["events"]) == {e.uid for e in _events(out).values()}
    manifest_uids = set(imported["events"])
    assert len(imported["entries"]) == len(manifest_uids) + 1  # the events and the manifest, nothing else


def test_run_send_delivers_every_event_valid_for_the_stale_time_asked(runs):
    _, out, received = runs
    events = _events(out)
    got = {}
    for datagram in received:
        e = parse_event(datagram).cotEvent
        got[e.uid] = e
    assert set(got) == {e.uid for e in events.values()}
    for e in got.values():
        assert e.staleTime - e.startTime == 2 * 3600 * 1000
