"""Publishers: pure seeded streams, every message delivered over real Zenoh, realistic arrivals."""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import Counter, defaultdict
from typing import Any

import msgspec
import pytest

from fusion import messages as m
from fusion.io.zenoh_advanced import RecoveringSubscription
from fusion.scenarios import REFERENCE_NAMES
from publishers.publish import publish
from publishers.spec import (
    LatencySpec,
    ScenarioSpec,
    SimulatedCartesian,
    SimulatedRadar,
    load_scenario_file,
    scenario_path,
)
from publishers.stream import build_stream


def _meas(samples: list) -> list[m.Measurement]:
    return [m.decode_measurement(s.payload) for s in samples if "/meas/" in s.key]


@pytest.mark.parametrize("name", [*REFERENCE_NAMES, "mix"], ids=str)
def test_scenario_file_builds_a_stream(name: str) -> None:
    sf = load_scenario_file(scenario_path(name))
    samples, truths = build_stream(sf.scenario, namespace="t")
    meas = _meas(samples)
    assert meas and truths
    assert [s.arrival_ns for s in samples] == sorted(s.arrival_ns for s in samples)
    assert {x.sensor_id for x in meas} == {s.id for s in sf.service.tracker.sensors}


def test_same_seed_gives_byte_identical_streams() -> None:
    spec = load_scenario_file(scenario_path("mix")).scenario
    a, _ = build_stream(spec, namespace="t")
    b, _ = build_stream(spec, namespace="t")
    c, _ = build_stream(msgspec.structs.replace(spec, seed=spec.seed + 1), namespace="t")
    assert b"".join(s.payload for s in a) == b"".join(s.payload for s in b)
    assert [s.arrival_ns for s in a] == [s.arrival_ns for s in b]
    assert b"".join(s.payload for s in a) != b"".join(s.payload for s in c)


def _mix(jitter_ms: float) -> ScenarioSpec:
    s = SimulatedRadar(id="r", position_m=[0.0, 0.0], rate_hz=10.0, range_std_m=1.0, bearing_std_rad=0.01,
                       latency=LatencySpec(base_ms=10.0, jitter_ms=jitter_ms))
    return ScenarioSpec(source="mix", seed=3, targets=4, duration_s=10.0, sensors=[s])


@pytest.mark.parametrize("jitter_ms", [0.0, 150.0], ids=["no-jitter", "jitter"])
def test_jitter_and_only_jitter_reorders(jitter_ms: float) -> None:
    samples, _ = build_stream(_mix(jitter_ms), namespace="t")
    t = [x.t_ns for x in _meas(samples)]
    out_of_order = sum(1 for a, b in itertools.pairwise(t) if b < a)
    if jitter_ms:
        assert out_of_order > 10
    else:
        assert out_of_order == 0


def test_sensor_effects_are_seen() -> None:
    s = SimulatedCartesian(id="c", std_m=[1.0, 1.0], pd=0.8, clutter_per_scan=3.0,
                           clutter_region_m=[-100.0, 100.0, -100.0, 100.0], dropout=0.1, duplicate=0.1)
    spec = ScenarioSpec(source="mix", seed=5, targets=3, duration_s=20.0, sensors=[s])
    meas = _meas(build_stream(spec, namespace="t")[0])
    per_scan = Counter(x.t_ns for x in meas)
    seqs = [x.seq for x in meas]
    assert len(seqs) != len(set(seqs)), "no duplicates were sent"
    assert max(seqs) + 1 > len(set(seqs)), "no drop-outs (gaps in seq)"
    assert max(per_scan.values()) > 3, "no clutter"


def _collect(session: Any, ns: str) -> tuple[list[bytes], threading.Lock, list[Any]]:
    """The measurements on namespace `ns`, through the service's kind of subscription (the
    publisher waits until it is announced), and subscribers on its inputs and truth (the
    publisher waits for them too); the subscriptions are returned for the caller to hold."""
    got: list[bytes] = []
    lock = threading.Lock()

    def cb(sample: Any) -> None:
        with lock:
            got.append(sample.payload.to_bytes())

    subs = [RecoveringSubscription(session, m.all_meas_key(ns), cb),
            RecoveringSubscription(session, m.all_input_key(ns), lambda sample: None),
            session.declare_subscriber(m.all_truth_key(ns), lambda sample: None)]
    return got, lock, subs


@pytest.mark.parametrize("name", REFERENCE_NAMES, ids=str)
def test_every_message_is_delivered_over_zenoh(name: str, zenoh_hub: tuple, zenoh_client: Any,
                                               caplog: pytest.LogCaptureFixture) -> None:
    hub, _ = zenoh_hub
    got, lock, _subs = _collect(hub, "t")
    sf = load_scenario_file(scenario_path(name))
    samples, _ = build_stream(sf.scenario, namespace="t")
    with caplog.at_level(logging.WARNING, logger="publishers"):
        counts = publish(zenoh_client(), samples, speed=0.0, match_timeout_s=5.0)
    assert not [r for r in caplog.records if "no subscriber matched" in r.message]  # it saw both announced
    expected = _meas(samples)
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        with lock:
            if len(got) >= len(expected):
                break
        time.sleep(0.01)
    with lock:
        received = [m.decode_measurement(b) for b in got]
    assert counts["meas"] == len(expected)
    assert len(received) == len(expected)
    by_sensor: dict[str, list[int]] = defaultdict(list)
    for x in received:
        by_sensor[x.sensor_id].append(x.seq)
    for seqs in by_sensor.values():
        assert sorted(seqs) == list(range(len(seqs))), "a gap in seq with drop-outs off"
