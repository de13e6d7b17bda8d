"""Track lifecycle and predictions through the real service path: a publisher, Zenoh on
loopback, the service, the recording. Events on the wire, snapshot?t_ns, periodic predicted
snapshots, Cartesian sensor poses, the configured noise as the default R."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from fusion import messages as m
from fusion.config import ServiceConfig, decode_service_config
from fusion.io import wire
from fusion.io.streamfile import StreamReader
from fusion.pipeline import Pipeline
from fusion.prediction import predicted_key
from fusion.tracking.tracker import Tracker
from tests.service.harness import Collector, EstimateCollector, client, latest, put_all, query, running_service

NS = "lc"
STEP_NS = 100_000_000


def _config(sensor: str, *, extra: str = "") -> ServiceConfig:
    return decode_service_config(f"""
namespace = "{NS}"
publish_tentative = {"true" if "tentative" in extra else "false"}
{extra.replace("tentative", "")}
[tracker]
[[tracker.sensors]]
{sensor}
[tracker.motion]
model = "cv"
ndim = 2
accel_psd_m2s3 = 0.01
[tracker.lifecycle]
confirm_m = 2
confirm_n = 3
max_misses = 3
coast_s = 100.0
""")


CAM = 'id = "cam"\nkind = "cartesian"\nstd_m = [1.0, 1.0]'


def _meas(k: int, seq: int, pos: list[float], std: list[float] | None = (1.0, 1.0)) -> tuple[str, bytes]:
    msg = m.Measurement(sensor_id="cam", t_ns=k * STEP_NS, seq=seq,
                        data=m.Cartesian(pos_m=pos, std_m=None if std is None else list(std)))
    return m.meas_key(NS, "cam"), m.encode(msg)


def _a_then_b(rng: np.random.Generator) -> list[tuple[str, bytes]]:
    """Target A at (0, 0) for scans 1-15, then only target B at (1000, 0) for scans 16-30:
    A coasts and is deleted for misses."""
    out = []
    for k in range(1, 31):
        x = 0.0 if k <= 15 else 1000.0
        out.append(_meas(k, k, [x + rng.normal(), rng.normal()]))
    return out


def _offline(cfg: ServiceConfig, stream: Path) -> tuple[Tracker, list[m.Event]]:
    """The recorded input through the tracker offline, one record at a time."""
    tracker = Tracker(cfg.tracker)
    pipe = Pipeline(tracker, wire.Codec(cfg.namespace), publish_tentative=cfg.publish_tentative)
    events = []
    for rec in StreamReader(stream):
        events.extend(wire.event_message(ev) for ev in pipe.ingest([rec]).events_to_publish)
    return tracker, events


def test_deleted_and_coasting_events_are_published(tmp_path: Path) -> None:
    cfg = _config(CAM)
    samples = _a_then_b(np.random.default_rng(3))
    with running_service(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            col = Collector(s, m.all_events_key(NS), m.decode_event)
            put_all(s, samples)
            assert svc.wait_idle(timeout_s=30.0)
            got = col.wait_for(svc.outbox.events)
        finally:
            s.close()
    assert len(got) == svc.outbox.events > 0
    kinds = {(e.track_id, e.kind, e.reason) for e in got if not e.withdrawn}
    (a,) = {e.track_id for e in got if e.kind == "deleted"}
    assert (a, "confirmed", None) in kinds and (a, "coasting", None) in kinds
    assert (a, "deleted", "misses") in kinds, kinds
    deleted = [e for e in got if e.kind == "deleted"]
    assert deleted[0].t_ns == 19 * STEP_NS, "A misses scans 16-19: deleted at the 4th miss (max_misses 3)"
    assert any(e.kind == "confirmed" and e.track_id != a for e in got), "B's confirmation"
    _, offline = _offline(cfg, tmp_path / "live.fstream")
    assert sorted(got, key=m.encode) == sorted(offline, key=m.encode)


def test_snapshot_predicted_to_a_requested_time(tmp_path: Path) -> None:
    cfg = _config(CAM)
    rng = np.random.default_rng(5)
    samples = [_meas(k, k, [10.0 * k * 0.1 + rng.normal(), 5.0 + rng.normal()]) for k in range(1, 21)]
    t_ask = 25 * STEP_NS
    with running_service(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            put_all(s, samples)
            assert svc.wait_idle(timeout_s=30.0)
            snap = m.decode_snapshot(query(s, f"{m.snapshot_key(NS)}?t_ns={t_ask}"))
            plain = m.decode_snapshot(query(s, m.snapshot_key(NS)))
            bad = list(s.get(f"{m.snapshot_key(NS)}?t_ns=soon", timeout=5.0))
            unknown = list(s.get(f"{m.snapshot_key(NS)}?when=1", timeout=5.0))
        finally:
            s.close()
    (e,) = snap.estimates
    assert e.status == "predicted" and e.t_ns == t_ask and len(e.cov) == 16
    (p,) = plain.estimates
    assert p.status == "confirmed" and p.t_ns == 20 * STEP_NS
    # exactly the offline tracker's prediction on the same input
    tracker, _ = _offline(cfg, tmp_path / "live.fstream")
    (want,) = tracker.predict(t_ask)
    assert e.state == want.x.tolist() and e.cov == want.P.ravel().tolist()
    # x(T) = x + v (T - t): 0.5 s ahead of the last update at 10 m/s
    assert e.state[0] == pytest.approx(p.state[0] + 0.5 * p.state[1], abs=1e-9)
    assert np.trace(np.reshape(e.cov, (4, 4))) > np.trace(np.reshape(p.cov, (4, 4))), "predicting adds Q"
    assert "t_ns must be an integer" in bad[0].err.payload.to_string()
    assert "unknown snapshot parameter 'when'" in unknown[0].err.payload.to_string()


def test_periodic_predicted_snapshots_on_the_stream_clock(tmp_path: Path) -> None:
    """Target A seen by cam for 2 s, then target B by cam2 for 2 s: from 2 s on, A is predicted
    to every tick (cam2 has never seen A: its scans are no chances for A, so A lives on)."""
    cam2 = 'id = "cam2"\nkind = "cartesian"\nstd_m = [1.0, 1.0]'
    cfg = _config(CAM + "\n[[tracker.sensors]]\n" + cam2, extra="[publication]\nperiod_s = 0.5")
    rng = np.random.default_rng(6)
    truth_a = {k: (10.0 * k * 0.1, 5.0) for k in range(1, 21)}
    samples = [_meas(k, k, [x + rng.normal(), y + rng.normal()]) for k, (x, y) in truth_a.items()]
    for k in range(21, 41):
        msg = m.Measurement(sensor_id="cam2", t_ns=k * STEP_NS, seq=k,
                            data=m.Cartesian(pos_m=[1000.0 + rng.normal(), rng.normal()], std_m=[1.0, 1.0]))
        samples.append((m.meas_key(NS, "cam2"), m.encode(msg)))
    with running_service(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            col = Collector(s, predicted_key(NS), m.decode_snapshot)
            put_all(s, samples, pause_s=0.01)  # 10x real time
            assert svc.wait_idle(timeout_s=30.0)
            got = col.wait_for(svc.outbox.predicted)
        finally:
            s.close()
    assert len(got) == svc.outbox.predicted
    # ticks at the multiples of 0.5 s from the first measurement (0.1 s) to the stream clock's
    # end (robust: about the second newest sensor time), each once, in order
    end = svc.tracker.now_ns
    assert end is not None and 3.8e9 < end <= 4.0e9 and len(got) == end // 500_000_000
    a_predicted = []
    for k, sn in enumerate(got, start=1):
        tick = k * 500_000_000
        for e in sn.estimates:
            # predicted to the tick, or given at a later update that had already arrived
            assert (e.status, e.t_ns) == ("predicted", tick) or (e.status == "confirmed" and e.t_ns > tick)
            a = e.state[0] < 500.0
            tx, ty = (10.0 * e.t_ns / 1e9, 5.0) if a else (1000.0, 0.0)
            P = np.reshape(e.cov, (4, 4))
            d = np.array([e.state[0] - tx, e.state[2] - ty])
            assert d @ np.linalg.solve(P[np.ix_([0, 2], [0, 2])], d) < 25.0, (e.t_ns, e.state)
            if a and e.status == "predicted" and tick > 2_000_000_000:
                a_predicted.append((tick, e.state[0], P[0, 0]))
    assert [t for t, _, _ in a_predicted] == [k * 500_000_000 for k in range(5, len(got) + 1)]
    assert all(v1 < v2 for (_, _, v1), (_, _, v2) in itertools.pairwise(a_predicted)), "uncertainty grows"


def _first_estimates(cfg: ServiceConfig, tmp: Path, samples: list[tuple[str, bytes]]) -> list[m.Estimate]:
    """Every estimate the service published for `samples`, in the consumer's view, by time."""
    with running_service(cfg, tmp) as (svc, endpoint):
        s = client(endpoint)
        try:
            col = EstimateCollector(s, NS)
            put_all(s, samples)
            assert svc.wait_idle(timeout_s=30.0)
            got = col.all_of(svc)
        finally:
            s.close()
    return sorted(latest(got).values(), key=lambda e: (e.t_ns, e.track_id))


def test_a_cartesian_sensor_pose_is_applied(tmp_path: Path) -> None:
    """A camera at (100, 0) turned 1 rad: z = (10, 0) in its frame is (100 + 10 cos 1, 10 sin 1)."""
    cfg = _config('id = "cam"\nkind = "cartesian"\nstd_m = [0.1, 0.1]\nposition_m = [100.0, 0.0]\nheading_rad = 1.0')
    samples = [_meas(k, k, [10.0, 0.0], std=(0.1, 0.1)) for k in range(1, 11)]
    est = _first_estimates(cfg, tmp_path, samples)
    assert est and est[-1].status == "confirmed"
    x, y = est[-1].state[0], est[-1].state[2]
    assert (x, y) == pytest.approx((100.0 + 10.0 * math.cos(1.0), 10.0 * math.sin(1.0)), abs=1e-3)


def test_the_configured_noise_is_the_default_and_a_message_noise_wins(tmp_path: Path) -> None:
    """std_m = 2 in the config: a birth from a message without noise has position variance 4,
    one from a message with std 5 has 25 (the birth's position covariance is R)."""
    cfg = _config('id = "cam"\nkind = "cartesian"\nstd_m = [2.0, 2.0]', extra="tentative")
    samples = [_meas(1, 1, [0.0, 0.0], std=None), _meas(1, 2, [5000.0, 0.0], std=(5.0, 5.0))]
    est = _first_estimates(cfg, tmp_path, samples)
    by_x = {round(e.state[0]): np.reshape(e.cov, (4, 4)) for e in est}
    assert by_x[0][0, 0] == pytest.approx(4.0) and by_x[0][2, 2] == pytest.approx(4.0)
    assert by_x[5000][0, 0] == pytest.approx(25.0) and by_x[5000][2, 2] == pytest.approx(25.0)
