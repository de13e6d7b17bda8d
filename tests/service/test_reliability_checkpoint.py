"""Checkpoints in the service: a restarted service resumes its tracks with the same ids and
says how old the checkpoint was; a bad or foreign checkpoint is moved aside with a clear
message and the service starts clean."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import msgspec
import pytest

from fusion import messages as m
from fusion.config import CheckpointConfig, ServiceConfig
from fusion.io.checkpoint import read_checkpoint
from fusion.service import Service
from publishers.publish import publish
from publishers.stream import Sample, build_stream
from tests.service.harness import EstimateCollector, client, query, scenario_config
from tests.service.reliability_helpers import service_thread


@contextmanager
def service_in(cfg: ServiceConfig, rec: Path) -> Iterator[tuple[Service, str]]:
    """The service as `fusion serve --recordings rec` runs it (rotating files, the default
    checkpoint rec/<prefix>.checkpoint)."""
    with service_thread(cfg, recording_dir=rec) as (svc, endpoint, _):
        yield svc, endpoint


def later(samples: list[Sample], dt_ns: int) -> list[Sample]:
    """The samples with every sensor and truth time moved dt_ns later."""
    out = []
    for x in samples:
        msg = m.decode_any(x.payload)
        out.append(Sample(x.arrival_ns, x.key, m.encode(msgspec.structs.replace(msg, t_ns=msg.t_ns + dt_ns))))
    return out


def _status(endpoint: str, ns: str) -> m.ServiceStatus:
    s = client(endpoint)
    try:
        return m.decode_status(query(s, m.status_key(ns)))
    finally:
        s.close()


def test_a_restarted_service_resumes_its_tracks_with_the_same_ids(tmp_path: Path) -> None:
    spec, cfg = scenario_config("radar2d")
    spec = msgspec.structs.replace(spec, duration_s=4.0)
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    half = len(samples) // 2
    rec = tmp_path / "rec"
    with service_in(cfg, rec) as (svc, endpoint):
        s = client(endpoint)
        try:
            col = EstimateCollector(s, cfg.namespace)
            publish(s, samples[:half], speed=1.0, match_timeout_s=5.0)
            stopped_ns = time.monotonic_ns()
            assert svc.wait_idle(timeout_s=30.0)
            first = {e.track_id for e in col.snapshot() if e.status == "confirmed"}
        finally:
            s.close()
    assert len(first) == 1
    cp = rec / f"{cfg.recording.prefix}.checkpoint"
    assert read_checkpoint(cp, cfg.tracker) is not None, "no checkpoint at shutdown"
    with service_in(cfg, rec) as (svc, endpoint):
        st = _status(endpoint, cfg.namespace)
        assert st.checkpoint is not None and st.checkpoint.resumed_tracks == 1
        assert 0.0 < st.checkpoint.resumed_age_s < 30.0
        assert st.checkpoint.refused is None and st.tracks == {"confirmed": 1}
        s = client(endpoint)
        try:
            col = EstimateCollector(s, cfg.namespace)
            # the sensor kept its own clock running through the outage: its times move on by it
            publish(s, later(samples[half:], time.monotonic_ns() - stopped_ns), speed=1.0, match_timeout_s=5.0)
            assert svc.wait_idle(timeout_s=30.0)
            time.sleep(0.15)
            st = m.decode_status(query(s, m.status_key(cfg.namespace)))
            second = {e.track_id for e in col.snapshot()}
        finally:
            s.close()
    assert second == first, "the resumed track got another id"
    c = st.counts  # this run's counts, adding up
    assert c.received == len(samples) - half
    assert c.received == c.applied + c.truth + c.duplicates + sum(c.refused.values()) + c.queued
    # Sources' clocks are resumed too (fusion.tracking.clock): they run on with the wall clock, so a
    # sensor that goes on in real time (its times moved on by the outage) is on time after the
    # restart; data it buffered during an outage longer than lag_s would be too late.
    n_meas = sum(1 for x in samples[half:] if "/meas/" in x.key)
    assert c.applied + c.refused.get("too_late", 0) == n_meas
    assert c.applied >= n_meas - 2


def test_checkpoints_are_written_on_the_interval(tmp_path: Path) -> None:
    spec, cfg = scenario_config("radar2d")
    cfg = msgspec.structs.replace(cfg, checkpoint=CheckpointConfig(interval_s=0.2))
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    with service_in(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            publish(s, samples[:100], speed=0.0, match_timeout_s=5.0)
            assert svc.wait_idle(timeout_s=30.0)
            time.sleep(0.6)
            st = m.decode_status(query(s, m.status_key(cfg.namespace)))
        finally:
            s.close()
        r = read_checkpoint(tmp_path / f"{cfg.recording.prefix}.checkpoint", cfg.tracker)
        assert r is not None and r.age_s < 5.0
    assert st.checkpoint is not None and st.checkpoint.written >= 2 and st.checkpoint.last_written_age_s < 1.0


@pytest.mark.parametrize("kind", ["garbage", "cut", "foreign", "namespace"], ids=str)
def test_a_bad_checkpoint_is_moved_aside_and_the_service_starts_clean(kind: str, tmp_path: Path,
                                                                      caplog: pytest.LogCaptureFixture) -> None:
    spec, cfg = scenario_config("radar2d")
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    cp = tmp_path / "state" / "tracker.checkpoint"  # a configured path, the same for both configurations
    cfg = msgspec.structs.replace(cfg, checkpoint=CheckpointConfig(path=str(cp)))
    cp.parent.mkdir()
    if kind == "garbage":
        cp.write_bytes(b"\x00not a checkpoint" * 10)
    else:
        other = {"cut": cfg, "foreign": msgspec.structs.replace(scenario_config("mix")[1], checkpoint=cfg.checkpoint),
                 "namespace": msgspec.structs.replace(cfg, namespace=cfg.namespace + "-other")}[kind]
        sent = {"cut": samples[:100], "foreign": [],
                "namespace": build_stream(spec, namespace=other.namespace)[0][:100]}
        with service_in(other, tmp_path) as (svc, endpoint):
            s = client(endpoint)
            try:
                publish(s, sent[kind], speed=0.0, match_timeout_s=5.0)
                assert svc.wait_idle(timeout_s=30.0)
            finally:
                s.close()
        if kind == "cut":
            cp.write_bytes(cp.read_bytes()[:-40])
        if kind == "namespace":  # the other namespace's service had tracks to resume
            assert read_checkpoint(cp, other.tracker, namespace=other.namespace).tracks > 0  # type: ignore[union-attr]
    with caplog.at_level(logging.WARNING, logger="fusion.checkpoint"), service_in(cfg, tmp_path) as (svc, endpoint):
        st = _status(endpoint, cfg.namespace)
    assert st.checkpoint is not None and st.checkpoint.resumed_tracks == 0 and st.checkpoint.refused
    assert st.tracks == {}
    if kind == "namespace":
        assert f"written by the service on namespace {cfg.namespace + '-other'!r}" in st.checkpoint.refused
    aside = list(cp.parent.glob(f"{cp.name}.bad-*"))
    assert len(aside) == 1
    msg = " ".join(r.getMessage() for r in caplog.records)
    assert "checkpoint refused" in msg and "moved aside to" in msg and "starting with no tracks" in msg
    assert read_checkpoint(cp, cfg.tracker) is not None, "the clean start wrote no new checkpoint at shutdown"
