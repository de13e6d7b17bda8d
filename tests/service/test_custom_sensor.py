"""A custom measurement model given in the config by import path, through the real service
path; refused at load when its Jacobian is wrong."""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np
import pytest

from fusion import messages as m
from fusion.config import decode_service_config
from fusion.errors import ConfigError
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker
from publishers.stream import build_stream
from tests.service.harness import EstimateCollector, client, latest, put_all, running_service, scenario_config

MODEL = "tests.service.custom_sensor_models:RangeBearing"


def _custom(cfg, *, wrong: bool = False):
    """radar2d's configuration with its radar replaced by the custom range-bearing model."""
    (radar,) = cfg.tracker.sensors
    text = f"""
namespace = "{cfg.namespace}"
[tracker]
[[tracker.sensors]]
id = "{radar.id}"
kind = "custom"
model = "{MODEL}"
[tracker.sensors.params]
station = [0.0, 0.0]
range_std_m = {radar.range_std_m}
bearing_std_rad = {radar.bearing_std_rad}
{"wrong_jacobian = 1" if wrong else ""}
"""
    custom = decode_service_config(text)
    return msgspec.structs.replace(cfg, tracker=msgspec.structs.replace(cfg.tracker, sensors=custom.tracker.sensors))


def _as_vector(key: str, payload: bytes) -> tuple[str, bytes]:
    """A radar message as the custom sensor's z = (range, bearing) in a cartesian message."""
    msg = m.decode_any(payload)
    if not isinstance(msg, m.Measurement):
        return key, payload
    d = msg.data
    std = None if d.range_std_m is None else [d.range_std_m, d.bearing_std_rad]
    return key, m.encode(msgspec.structs.replace(msg, data=m.Cartesian(pos_m=[d.range_m, d.bearing_rad], std_m=std)))


def test_a_custom_measurement_model_tracks_like_the_built_in_radar(tmp_path: Path) -> None:
    spec, cfg = scenario_config("radar2d")
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    custom = _custom(cfg)
    with running_service(custom, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            col = EstimateCollector(s, cfg.namespace)
            put_all(s, [_as_vector(x.key, x.payload) for x in samples])
            assert svc.wait_idle(timeout_s=60.0)
            got = latest(col.all_of(svc))
        finally:
            s.close()
    assert svc.status_dict()["counts"]["applied"] == 200
    # the built-in radar on the original messages, offline
    tracker = Tracker(cfg.tracker)
    pipe = Pipeline(tracker, wire.Codec(cfg.namespace))
    enc = wire.estimate_encoder(tracker.layout, tracker.model_name)
    want = latest([m.decode_estimate(enc(e)) for x in samples for e in pipe.ingest([(0, x.key, x.payload)]).to_publish])
    assert len(got) == len(want) > 150
    by_time = {k[1]: e for k, e in want.items()}
    for k, e in got.items():
        w = by_time[k[1]]
        np.testing.assert_allclose(e.state, w.state, rtol=1e-6, atol=1e-6, err_msg=str(k))
        np.testing.assert_allclose(e.cov, w.cov, rtol=1e-5, atol=1e-6, err_msg=str(k))


def test_a_custom_measurement_model_with_a_wrong_jacobian_is_refused_at_load() -> None:
    _, cfg = scenario_config("radar2d")
    with pytest.raises(ConfigError, match=r"RangeBearing: jacobian entry \[1, 0\].*finite differences"):
        Tracker(_custom(cfg, wrong=True).tracker)


def test_a_custom_sensor_refuses_a_pose_it_cannot_apply() -> None:
    with pytest.raises(ConfigError, match="pose cannot be applied"):
        decode_service_config(f"""
[tracker]
[[tracker.sensors]]
id = "r"
kind = "custom"
model = "{MODEL}"
heading_rad = 1.0
""")
