"""Ids are matched in full: "$" matches before a final newline, so 'cam1\n' passed once."""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest

from fusion import messages as m
from fusion.errors import InputError
from tests.service.harness import client, running_service, scenario_config
from tests.service.reliability_helpers import publisher, settled_status

ODD = ["cam1\n", "cam1\r", "cam1\n\n", "\ncam1", "cam 1", "cam1/x", "cam*", "", "a" * 65, "câm1", "cam1\x00"]


def _meas(sensor_id: str) -> bytes:
    return m.encode(m.Measurement(sensor_id=sensor_id, t_ns=1, seq=0, data=m.Cartesian(pos_m=[1.0, 2.0])))


@pytest.mark.parametrize("bad", ODD, ids=repr)
def test_decoders_refuse_ids_that_are_not_a_full_match(bad: str) -> None:
    with pytest.raises(m.InvalidMessageError, match="sensor_id"):
        m.decode_measurement(_meas(bad))
    truth = m.encode(m.Truth(target_id=bad, t_ns=1, state=[0.0], layout=["x"]))
    with pytest.raises(m.InvalidMessageError, match="target_id"):
        m.decode_truth(truth)
    inp = m.encode(m.Input(source_id=bad, t_ns=1, seq=0, u=[0.0]))
    with pytest.raises(m.InvalidMessageError, match="source_id"):
        m.decode_input(inp)
    with pytest.raises(m.InvalidMessageError):
        m.decode_json(m.encode_json(m.Measurement(sensor_id=bad, t_ns=1, seq=0, data=m.Cartesian(pos_m=[1.0]))))


@pytest.mark.parametrize("bad", ODD, ids=repr)
def test_key_builders_refuse_ids_that_are_not_a_full_match(bad: str) -> None:
    with pytest.raises(InputError):
        m.meas_key("demo", bad)
    with pytest.raises(InputError):
        m.truth_key(bad, "x")


@pytest.mark.parametrize("good", ["cam1", "a" * 64, "A.b-c_9"], ids=repr)
def test_good_ids_pass(good: str) -> None:
    assert m.decode_measurement(_meas(good)).sensor_id == good
    assert m.meas_key("demo", good).endswith("/" + good)


def test_the_service_refuses_a_trailing_newline_id_on_the_sensors_key(tmp_path: Path) -> None:
    """Through a real zenoh client: 'cam1\\n' on fusion/NS/meas/cam1 is refused as invalid,
    'x\\n' on truth/x too; the good cam1 message is applied."""
    _, cfg = scenario_config("mix")
    cam = [s for s in cfg.tracker.sensors if s.id == "cam1"]
    cfg = msgspec.structs.replace(cfg, tracker=msgspec.structs.replace(cfg.tracker, sensors=cam))
    ns = cfg.namespace
    with running_service(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            pub, tpub = publisher(s, m.meas_key(ns, "cam1")), publisher(s, m.truth_key(ns, "x"))
            pub.put(_meas("cam1\n"))
            tpub.put(m.encode(m.Truth(target_id="x\n", t_ns=1, state=[0.0, 0.0, 0.0, 0.0],
                                      layout=["x", "vx", "y", "vy"])))
            pub.put(_meas("cam1"))
            status = settled_status(svc, s, ns)
        finally:
            s.close()
    c = status.counts
    assert c.received == 3
    assert c.refused.get("invalid") == 2
    assert c.applied == 1 and c.truth == 0
