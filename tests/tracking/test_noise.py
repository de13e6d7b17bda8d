"""One source of truth for sensor noise: the configured noise is the default; a measurement's own
noise wins; with neither, the measurement is refused with the reason (issue #12, item 4)."""

from __future__ import annotations

import numpy as np

from fusion.config import CartesianSensorConfig, RadarSensorConfig, TrackerConfig
from fusion.tracking.detection import Detection, Reason
from fusion.tracking.tracker import Tracker


def _first_P(sensor, z, R=None) -> np.ndarray:
    tr = Tracker(TrackerConfig(sensors=[sensor]))
    (e,) = tr.process([Detection.of(sensor.id, 0, 0, z, R)]).estimates
    return e.P


def test_configured_noise_is_the_default_and_a_messages_own_wins() -> None:
    quiet = CartesianSensorConfig(id="cam", std_m=[1.0, 1.0])
    loud = CartesianSensorConfig(id="cam", std_m=[1000.0, 1000.0])
    assert _first_P(quiet, [0.0, 0.0])[0, 0] == 1.0
    assert _first_P(loud, [0.0, 0.0])[0, 0] == 1e6  # the configuration is no longer ignored
    assert _first_P(loud, [0.0, 0.0], np.diag([4.0, 4.0]))[0, 0] == 4.0  # the message's own R wins


def test_radar_noise_from_the_configuration() -> None:
    a = RadarSensorConfig(id="r", range_std_m=1.0, bearing_std_rad=0.001)
    b = RadarSensorConfig(id="r", range_std_m=1e3, bearing_std_rad=0.001)
    Pa, Pb = _first_P(a, [1000.0, 0.0]), _first_P(b, [1000.0, 0.0])
    assert Pb[0, 0] > 1e5 * Pa[0, 0]


def test_no_noise_anywhere_is_refused() -> None:
    tr = Tracker(TrackerConfig(sensors=[CartesianSensorConfig(id="cam")]))
    (r,) = tr.process([Detection.of("cam", 0, 0, [0.0, 0.0])]).refused
    assert r.reason == Reason.INVALID and "no noise" in r.detail
    assert not tr.process([Detection.of("cam", 0, 1, [0.0, 0.0], np.eye(2))]).refused
