"""The motion section names each model's noise in its own units: "ca" takes a jerk density."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import CartesianSensorConfig, MotionConfig, TrackerConfig
from fusion.tracking.tracker import Tracker

SENSORS = [CartesianSensorConfig(id="c", std_m=[1.0, 1.0])]


def test_ca_takes_the_jerk_density() -> None:
    tr = Tracker(TrackerConfig(sensors=SENSORS, motion=MotionConfig(model="ca", jerk_psd_m2s5=0.4)))
    dt = 0.5
    Q = tr.motion.Q(np.zeros(6), dt)
    axis = 0.4 * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                           [dt**3 / 6, dt**2 / 2, dt]])
    np.testing.assert_allclose(Q[:3, :3], axis, rtol=1e-12)
    np.testing.assert_allclose(Q[3:, 3:], axis, rtol=1e-12)


@pytest.mark.parametrize("motion", [MotionConfig(model="ca"), MotionConfig(model="ca", accel_psd_m2s3=0.4),
                                    MotionConfig(model="ca", accel_psd_m2s3=0.4, jerk_psd_m2s5=0.4)],
                         ids=["no-noise", "accel-field", "both"])
def test_ca_with_the_acceleration_field_names_the_jerk_field(motion: MotionConfig) -> None:
    with pytest.raises(ValueError, match=r"'ca' takes its noise as motion\.jerk_psd_m2s5 \(m\^2/s\^5"):
        TrackerConfig(sensors=SENSORS, motion=motion)


def test_jerk_on_another_model_is_refused() -> None:
    with pytest.raises(ValueError, match=r"jerk_psd_m2s5 is the noise of model 'ca'; model 'cv' takes accel_psd"):
        TrackerConfig(sensors=SENSORS, motion=MotionConfig(model="cv", jerk_psd_m2s5=0.4))


def test_imm_modes_are_named_for_people() -> None:
    from fusion.config import load_service_config, mode_names
    from fusion.io.track_rows import _mode_names
    from publishers.spec import load_scenario_file, scenario_path

    assert mode_names(load_service_config("configs/service.toml").tracker) == ["cv", "ct"]
    assert mode_names(load_scenario_file(scenario_path("maneuver2d")).service.tracker) == ["cv 1", "cv 2"]
    assert mode_names(load_scenario_file(scenario_path("radar2d")).service.tracker) == []
    assert _mode_names(("cv", "ct"), 2) == ["cv", "ct"] and _mode_names((), 2) == ["mode 0", "mode 1"]
