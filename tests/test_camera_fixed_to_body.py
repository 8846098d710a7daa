"""`camera.fixed_to_body`: a camera on the airframe (no gimbal) turns with the vehicle: its line of sight is the
vehicle's attitude composed with the mounting R_optical_from_gimbal (body FRD -> optical)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.flight import Flight
from pipeline.flight_config import load_flight_config

ROOT = Path(__file__).resolve().parents[1]
NADIR = ((0.0, 1.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 0.0, 1.0))  # looking straight down, image top forward


def test_the_camera_turns_with_the_vehicle_under_its_mounting():
    config = load_flight_config(ROOT / "configs" / "flights" / "group1.yaml")
    fixed = dataclasses.replace(config, camera=dataclasses.replace(config.camera, fixed_to_body=True,
                                                                   R_optical_from_gimbal=NADIR))
    with Flight.open(fixed) as flight:
        assert flight.log.gimbal.source.endswith("(camera fixed to the body)")
        assert any("camera.fixed_to_body: the gimbal attitude of" in w for w in flight.notes)  # group1 has one
        att = flight.log.attitude
        t = att.t_ns[len(att.t_ns) // 4: len(att.t_ns) // 4 + 20]  # attitude samples: no interpolation
        poses, inside = flight.poses(t)
        assert inside.all()
        # expected: ENU <- NED (at the origin; the vehicle is within a few km: the level frames differ by < 0.1 deg)
        # <- body (the logged attitude, wxyz) <- optical (the mounting's transpose)
        R_enu_from_ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
        R_ned_from_body = Rotation.from_quat(att.quat_wxyz[np.searchsorted(att.t_ns, t)][:, [1, 2, 3, 0]]).as_matrix()
        expected = R_enu_from_ned @ R_ned_from_body @ np.array(NADIR).T
        angle = np.degrees(Rotation.from_matrix(np.swapaxes(expected, 1, 2) @ poses.R_enu0_from_optical).magnitude())
        assert angle.max() < 0.1
        # a nadir camera on a nearly level vehicle looks down: its optical axis (z) has an ENU up component near -1
        assert (poses.R_enu0_from_optical[:, 2, 2] < -0.9).all()
    with Flight.open(config) as flight:  # without the key the gimbal is the log's
        assert not flight.log.gimbal.source.endswith("(camera fixed to the body)")


def test_the_attitudes_clock_offset_moves_the_camera_with_it():
    """The camera is the attitude: `clock.attitude_offset_s` shifts it as it shifts the attitude (the gimbal's
    own offset, for a gimbal set aside, does not apply)."""
    config = load_flight_config(ROOT / "configs" / "flights" / "group1.yaml")
    camera = dataclasses.replace(config.camera, fixed_to_body=True, R_optical_from_gimbal=NADIR)
    shifted = dataclasses.replace(config, camera=camera,
                                  clock=dataclasses.replace(config.clock, attitude_offset_s=0.5, gimbal_offset_s=3.0))
    with Flight.open(shifted) as flight:
        c = shifted.clock
        g, a = flight.log.gimbal, flight.log.attitude
        assert (g.t_ns + c.offset_ns("gimbal") == a.t_ns + c.offset_ns("attitude")).all()


def test_a_log_without_attitude_asks_for_the_attitude_alone(monkeypatch):
    """fixed_to_body on a log with a position only: the one thing to give is the attitude the camera turns with
    (not 'no attitude, gimbal', a gimbal the key says there is none of); check labels the mounting as the body's."""
    import pytest

    import pipeline.ingest
    from pipeline.check.flight import mapping_lines
    from pipeline.errors import InputError
    from pipeline.flight.flight import read_flight_logs
    from pipeline.ingest.model import FlightLog

    config = load_flight_config(ROOT / "configs" / "flights" / "group1.yaml")
    fixed = dataclasses.replace(config, camera=dataclasses.replace(config.camera, fixed_to_body=True))
    real = read_flight_logs(config)

    def position_only(*args, **kwargs):
        return FlightLog(path=real.path, position=real.position, formats=["tlog"])

    with monkeypatch.context() as m:
        m.setattr(pipeline.ingest, "read_flight", position_only)
        with pytest.raises(InputError) as info:
            read_flight_logs(fixed)
    msg = str(info.value)
    assert "supply only position: no attitude (camera.fixed_to_body: the camera turns with it);" in msg
    assert "gimbal" not in msg
    with Flight.open(fixed) as flight:
        (mount,) = [line for line in mapping_lines(flight) if line.lstrip().startswith("mount")]
    assert mount.endswith("(body FRD: camera.fixed_to_body)")
    with Flight.open(config) as flight:
        (mount,) = [line for line in mapping_lines(flight) if line.lstrip().startswith("mount")]
    assert mount.endswith("(gimbal FRD)")
