"""CoT events, uids, data packages and the cot/ folder (pipeline.tak, pipeline.report.cot), read back with TAK
libraries ridgeloc did not write (takproto, PyTAK's receiver)."""

from __future__ import annotations

import shutil
from datetime import datetime, timedelta, timezone

import pytest

from pipeline.cli import main as cli_main
from pipeline.errors import InputError
from pipeline.report.cot import flight_key, mgrs_spaced, write_cot_outputs
from pipeline.tak.cot import (
    UNKNOWN,
    CotTarget,
    check_type,
    event_xml,
    parse_cot_time,
    parse_duration_s,
    read_event,
    restamp,
    target_uid,
    to_bytes,
)
from pipeline.tak.package import data_package
from support.synthetic import synthetic_group
from support.tak import atak_import, parse_event

NOW = datetime(2026, 11, 25, 12, 0, 0, 250000, tzinfo=timezone.utc)
TARGET = CotTarget(uid="ridgeloc-test", callsign="bridge:north pier", lat_deg=-33.86785012, lon_deg=151.21072987,
                   hae_m=31.4159, ce90_m=4.25, le90_m=6.5, remarks="line 1\nline <2> & 3",
                   attributes={"method": "mle"})


def test_an_event_parses_as_cot_and_holds_the_target():
    msg = parse_event(event_xml(TARGET, NOW, "a-h-G", 3600))
    e = msg.cotEvent
    assert (e.uid, e.type, e.how) == ("ridgeloc-test", "a-h-G", "m-f")
    assert (e.lat, e.lon, e.hae, e.ce, e.le) == pytest.approx((-33.86785012, 151.21072987, 31.416, 4.25, 6.5),
                                                              abs=1e-9)
    assert e.detail.contact.callsign == "bridge:north pier"
    assert "<remarks>line 1\nline &lt;2&gt; &amp; 3</remarks>" in e.detail.xmlDetail
    assert (e.sendTime, e.startTime) == (int(NOW.timestamp() * 1000),) * 2  # takproto: ms since the epoch
    assert e.staleTime - e.startTime == 3600 * 1000
    assert e.detail.precisionLocation.geopointsrc == e.detail.precisionLocation.altsrc == "CALC"


def test_unknown_errors_are_the_schemas_unknown():
    e = parse_event(event_xml(CotTarget("u", "c", 1.0, 2.0, 3.0, None, float("nan")), NOW)).cotEvent
    assert (e.ce, e.le) == (UNKNOWN, UNKNOWN)


def test_cot_types_and_durations_are_checked():
    assert check_type("a-u-G") == "a-u-G" and check_type("b-m-p-s-m") == "b-m-p-s-m"
    for bad in ("", "a u G", "a--G", "-a", "a-u-G;x;y"):
        with pytest.raises(InputError, match="not a CoT type"):
            check_type(bad)
    assert [parse_duration_s(x) for x in ("90", "90s", "30m", "24h", "7d", "1.5h", 60)] == \
        [90, 90, 1800, 86400, 604800, 5400, 60]
    for bad in ("0", "-5m", "5 weeks", "", "inf"):
        with pytest.raises(InputError):
            parse_duration_s(bad)


def test_uids_are_stable_and_distinct():
    assert target_uid("flight A\nT1") == target_uid("flight A\nT1")
    assert len({target_uid("flight A\nT1"), target_uid("flight A\nT2"), target_uid("flight B\nT1")}) == 3
    assert target_uid("x").startswith("ridgeloc-")


def test_restamping_keeps_the_validity_it_was_written_with():
    event = read_event(event_xml(TARGET, NOW, stale_s=7200), "t.cot")
    later = NOW + timedelta(days=3)
    restamp(event, later)
    assert parse_cot_time(event.get("time")) == parse_cot_time(event.get("start")) == later.replace(microsecond=250000)
    assert parse_cot_time(event.get("stale")) - later == timedelta(hours=2)
    restamp(event, later, 60)
    assert parse_cot_time(event.get("stale")) - later == timedelta(seconds=60)
    assert parse_event(to_bytes(event)).cotEvent.uid == "ridgeloc-test"


@pytest.mark.parametrize("data", [b"", b"not xml", b"<kml/>", b"<event uid='x'/>",
                                  b"<!DOCTYPE x [<!ENTITY a 'aaaa'>]><event uid='x'><point/></event>",
                                  b"<event uid='x' time='yesterday' start='' stale=''><point/></event>"])
def test_a_file_that_is_not_an_event_is_refused_in_one_line_naming_it(data):
    with pytest.raises(InputError) as exc:
        read_event(data, "some/file.cot")
    assert str(exc.value).startswith("some/file.cot: not a CoT event") and "\n" not in str(exc.value)


def test_mgrs_is_spaced_as_people_read_it():
    assert mgrs_spaced("49SBU9399604341") == "49S BU 93996 04341"
    assert mgrs_spaced("4QFJ1234567890") == "4Q FJ 12345 67890"
    assert mgrs_spaced("32TLS849506") == "32T LS 849 506"
    assert mgrs_spaced("odd") == "odd"


@pytest.fixture(scope="module")
def groups():
    return [synthetic_group(f"flight{i}", seed=i) for i in range(3)]


def test_the_cot_folder_and_data_package_hold_every_located_answer(groups, tmp_path):
    entries = write_cot_outputs(tmp_path, groups)
    files = sorted((tmp_path / "cot").glob("*.cot"))
    assert [f.name for f in files] == ["flight0.cot", "flight1.cot", "flight2.cot"]
    imported = atak_import((tmp_path / "targets.zip").read_bytes())
    assert set(imported["events"]) == {e.uid for e in entries} == {parse_event(f.read_bytes()).cotEvent.uid
                                                                 for f in files}
    assert imported["name"] == f"ridgeloc {tmp_path.name}"
    for e in entries:  # the package holds the very events of cot/
        assert imported["events"][e.uid].SerializeToString() == parse_event(
            (tmp_path / "cot" / e.file_name).read_bytes()).SerializeToString()
    # the package uid follows the events, so the package of a re-run replaces the earlier one on a device
    again = atak_import(data_package(write_cot_outputs(tmp_path / "again", groups), "x"))
    assert again["uid"] == imported["uid"]


def test_a_rerun_replaces_the_cot_folder_and_leaves_no_stale_event(groups, tmp_path):
    write_cot_outputs(tmp_path, groups)
    (tmp_path / "cot" / "left-by-hand.cot").write_bytes(b"x")
    write_cot_outputs(tmp_path, groups[:1])
    assert [f.name for f in (tmp_path / "cot").iterdir()] == ["flight0.cot"]
    assert len(atak_import((tmp_path / "targets.zip").read_bytes())["events"]) == 1
    write_cot_outputs(tmp_path, [])
    assert list((tmp_path / "cot").iterdir()) == [] and not (tmp_path / "targets.zip").exists()


def test_a_flights_identity_is_its_name_and_its_files_names_and_sizes(groups, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    (a / "flight.tlog").write_bytes(b"0" * 100)
    (a / "photos").mkdir()
    (a / "photos" / "DJI_0001.JPG").write_bytes(b"1" * 10)
    shutil.copytree(a, b)
    r = groups[0]

    def key(folder, name="f"):
        r.settings["files"] = {"telemetry": [str(folder / "flight.tlog")], "video": None,
                               "photos": [str(folder / "photos")]}
        r.name = name
        try:
            return flight_key(r)
        finally:
            r.settings.pop("files")
            r.name = "flight0"

    assert key(a) == key(b)  # a copy elsewhere is the same flight
    assert key(a) != key(a, "g")
    (b / "photos" / "DJI_0001.JPG").write_bytes(b"1" * 11)
    assert key(a) != key(b)  # another photo: another flight


def test_the_cli_refuses_a_bad_type_or_stale_time_in_one_line(tmp_path, capsys):
    (tmp_path / "cot").mkdir()
    (tmp_path / "cot" / "t.cot").write_bytes(event_xml(TARGET, NOW))
    assert cli_main(["send", str(tmp_path), "--cot-type", "a u G", "--to", "udp://127.0.0.1:9"]) == 1
    assert cli_main(["send", str(tmp_path), "--cot-stale", "soon", "--to", "udp://127.0.0.1:9"]) == 1
    assert cli_main(["run", "no-such.yaml", "--cot-type", "a u G"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and all(line.startswith("ridgeloc: error: not a") for line in err), err
