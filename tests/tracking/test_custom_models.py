"""A user's model in the tracker, given by import path in the configuration (issue #12, item 2):
the helix models of the source document track as well as the offline reference filter, and a
model with a wrong Jacobian is refused at load with a clear error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fusion.config import CartesianSensorConfig, MotionConfig, TrackerConfig, load_service_config
from fusion.errors import ConfigError
from fusion.scenarios import reference, run_reference
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker

CONFIGS = Path(__file__).resolve().parents[2] / "configs" / "scenarios"


@pytest.mark.parametrize("name", ["helix3d", "helix3d_ekf", "helix3d_ekf_doc"])
def test_helix_models_by_import_path_match_the_reference_filter(name: str) -> None:
    ref = reference(name, seed=1)
    tr = Tracker(load_service_config(CONFIGS / f"{name}.toml").tracker)
    assert tr.layout == ref.layout
    est = {}
    for k in range(ref.n_steps):
        for e in tr.process([Detection.of("pos", int(ref.t_ns[k]), k, ref.z[k], ref.meas.R)]).estimates:
            est[e.t_ns] = e.x
    x = np.array([est[int(t)] for t in ref.t_ns])
    rmse = float(np.sqrt(np.mean(np.sum((x[:, :3] - ref.truth[:, :3]) ** 2, axis=1))))
    off = run_reference(ref)
    rmse_ref = float(np.sqrt(np.mean(np.sum((off.x[:, :3] - ref.truth[:, :3]) ** 2, axis=1))))
    assert rmse < 1.1 * rmse_ref, (rmse, rmse_ref)
    assert len(tr.confirmed()) == 1


def _config(**motion: object) -> TrackerConfig:
    return TrackerConfig(sensors=[CartesianSensorConfig(id="pos", std_m=[1.0])],
                         motion=MotionConfig(model="custom", ndim=1, **motion))  # type: ignore[arg-type]


def test_a_wrong_jacobian_is_refused_at_load() -> None:
    with pytest.raises(ConfigError, match=r"tests\.tracking\.bad_models:WrongJacobian: jacobian entry \[0, 1\]"):
        Tracker(_config(custom="tests.tracking.bad_models:WrongJacobian"))


@pytest.mark.parametrize(("motion", "message"), [
    ({"custom": "tests.tracking.nosuch:Model"}, "cannot import"),
    ({"custom": "fusion.models.helix:Nope"}, "has no 'Nope'"),
    ({"custom": "fusion.models.helix:HelixExact", "params": {"q_pos": -1.0}}, "q_pos must be finite and >= 0"),
    ({"custom": "fusion.models.helix:HelixExact"}, "3-D position; set motion.ndim = 3"),
    ({"custom": "tests.tracking.bad_models:VelocityPerAxisMissing"}, "one velocity per position axis"),
], ids=["no-module", "no-class", "bad-params", "wrong-ndim", "velocity-axes"])
def test_model_mistakes_are_refused_with_the_reason(motion: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        Tracker(_config(**motion))


def test_a_custom_model_needs_priors_for_its_other_components() -> None:
    cfg = TrackerConfig(sensors=[CartesianSensorConfig(id="pos", std_m=[1.0, 1.0, 1.0])],
                        motion=MotionConfig(model="custom", ndim=3, custom="fusion.models.helix:HelixExact"))
    with pytest.raises(ConfigError, match=r"init\.state_std is needed"):
        Tracker(cfg)
