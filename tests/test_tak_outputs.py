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
from pathlib import Path

import pytest

from pipeline.cli import main as cli_main
from support.tak import UdpListener, atak_import, compare_run_events, parse_event

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ("group1", "three_targets", "h20_laser")


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
    """callsign -> CotEvent of OUT/cot/*.cot."""
    events = {}
    for f in sorted((out / "cot").glob("*.cot")):
        e = parse_event(f.read_bytes()).cotEvent
        events[e.detail.contact.callsign] = e
    return events


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
    report = compare_run_events(out)
    assert len(report) == 7
    for r in report:
        assert r["status"] == r["answer_status"] == "located"
        assert max(r["d_lat_answer_deg"], r["d_lon_answer_deg"]) <= 1e-7 and r["d_hae_answer_m"] <= 0.01, r
        assert r["ce"] == pytest.approx(r["ce90_m"], rel=1e-3, abs=0.01), r
        assert r["le"] == pytest.approx(r["le90_m"], rel=1e-3, abs=0.01), r
        # the schema's 1-sigma reading would be smaller: for these ellipses CE90 is about 2.1 x sigma
        assert r["ce"] > 1.9 * r["sigma_h_m"], r


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


def test_a_marker_carries_the_warnings_of_its_answer(tmp_path):
    """A TAK user sees only the marker: the real KLV clip's answer, whose laser ranges all end at sea level (the
    payload's computed range), says so in its remarks as targets.csv's reason does, head first."""
    import xml.etree.ElementTree as ET

    clip = ROOT.parent / "shared" / "fmv" / "aphill_klv_10s.ts"
    if not clip.is_file():
        pytest.skip(f"{clip} absent (the shared read-only material is not beside this checkout)")
    assert cli_main(["run", str(clip), "-o", str(tmp_path / "out"), "--no-figures", "-q"]) == 0
    (row,) = list(csv.DictReader((tmp_path / "out" / "targets.csv").open()))
    assert "warning: the laser ranges all end at sea level" in row["reason"]
    # no config to state accuracies in: the advice names how to write one for the clip
    assert (f"in a flight config for the clip (`ridgeloc init {clip.resolve()} -o flight.yaml`, then `sigma:`); "
            "warning: ") in row["reason"]
    (cot,) = (tmp_path / "out" / "cot").glob("*.cot")
    text = ET.fromstring(cot.read_bytes()).find("detail/remarks").text
    warnings = [ln for ln in text.splitlines() if ln.startswith("WARNING: ")]
    assert any(ln.startswith("WARNING: the laser ranges all end at sea level (+0.6 m") for ln in warnings), text
    # a clip alone states no accuracies: its CE90 rests on defaults, which the marker says too
    assert "WARNING: sensor accuracies not stated (sigma.position_m, sigma.attitude_deg)" in warnings
    assert all(": " not in ln[len("WARNING: "):] for ln in warnings)  # the head of each, not the advice
