"""DJI SRT whose cues carry no altitude (Mavic 2 Pro firmware: `[latitude: ..] [longtitude: ..]` only): the
horizontal track is read and the altitude said to be missing; it comes from the mapping's srt.altitude_m or from
another log of the flight. Expected values are read off the cue text below."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import ConfigError
from pipeline.ingest import read_flight

# the layout as Mavic 2 Pro firmware writes it: spaces before the colons, `longtitude`, no altitude key
CUES = "".join(
    f"{k + 1}\n00:00:{k // 30:02d},{(k % 30) * 33:03d} --> 00:00:{(k + 1) // 30:02d},{((k + 1) % 30) * 33:03d}\n"
    f'<font size="36">SrtCnt : {k + 1}, DiffTime : 33ms\n2019-06-22 18:53:57,{617 + 33 * k:03d},432\n'
    f"[iso : 100] [shutter : 1/1600.0] [fnum : 280] [ev : 0] [ct : 5400] [color_md : default] [focal_len : 280] "
    f"[latitude : 41.38793{k}] [longtitude : 2.17422{k}] </font>\n\n" for k in range(3))


def _write(tmp_path, text=CUES):
    p = tmp_path / "DJI_0001.SRT"
    p.write_text(text)
    return p


def test_the_horizontal_track_is_read_and_the_altitude_said_missing(tmp_path):
    log = read_flight([_write(tmp_path)])
    p = log.position
    assert p.alt_datum == "missing" and np.isnan(p.alt_m).all()
    assert p.lat_deg.tolist() == [41.387930, 41.387931, 41.387932] and p.lon_deg[2] == 2.174222
    assert p.t_ns.tolist() == [0, 33_000_000, 66_000_000]
    assert any("no altitude in the subtitles: horizontal track read (3 positions), altitude missing" in w
               for w in log.warnings)
    assert "altitude" in log.missing_for_localization()


def test_the_altitude_from_the_mapping(tmp_path):
    log = read_flight([_write(tmp_path)], {"srt": {"altitude_m": 152.5, "abs_datum": "amsl"}})
    assert log.position.alt_datum == "amsl" and log.position.alt_m.tolist() == [152.5] * 3
    assert "altitude" not in log.missing_for_localization()
    assert any("altitude 152.5 m (amsl) from the mapping's srt.altitude_m" in w for w in log.warnings)
    with pytest.raises(ConfigError, match="altitude_mm"):
        read_flight([_write(tmp_path)], {"srt": {"altitude_mm": 1}})


def test_the_altitude_from_another_log_of_the_flight(tmp_path):
    other = tmp_path / "DJI_0002.SRT"  # a second file of the flight with absolute altitudes
    other.write_text(CUES.replace("] </font>", "] [altitude: 213.5] </font>"))
    log = read_flight([_write(tmp_path), other])
    assert log.position.alt_datum == "amsl" and log.position.source == "DJI_0002.SRT"
    np.testing.assert_allclose(log.position.alt_m, 213.5)
    assert any("DJI_0001.SRT has no altitudes; the positions of DJI_0002.SRT are used" in w for w in log.warnings)


def test_a_run_without_any_altitude_fails_in_one_line(tmp_path):
    from pipeline.sync.assemble import frame_states

    log = read_flight([_write(tmp_path)])
    log.attitude = log.gimbal = log.position  # placeholders: the altitude check comes first
    with pytest.raises(ConfigError, match="altitude datum 'missing'"):
        frame_states(log, np.array([0]))
