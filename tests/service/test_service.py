"""The service end to end over real in-process Zenoh sessions on loopback."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import msgspec
import numpy as np
import pytest

from fusion import messages as m
from fusion.io import wire
from fusion.io.streamfile import StreamReader
from fusion.io.zenoh_bus import free_tcp_port
from fusion.pipeline import Pipeline
from fusion.replay import replay
from fusion.scenarios import REFERENCE_NAMES
from fusion.tracking.tracker import Tracker
from publishers.publish import publish
from publishers.stream import build_stream
from tests.service.harness import (
    client,
    held_back,
    latest,
    put_all,
    query,
    rrd_rows,
    run_live,
    running_service,
    scenario_config,
)

RERUN = Path(__import__("rerun_cli").__file__).parent / "rerun"


def _offline(cfg, stream: Path, *, tracker: Tracker | None = None) -> list[m.Estimate]:
    """The same input through the tracker offline, one record at a time in arrival order: what
    the service should have published."""
    tracker = tracker if tracker is not None else Tracker(cfg.tracker)
    pipe = Pipeline(tracker, wire.Codec(cfg.namespace), publish_tentative=cfg.publish_tentative)
    enc = wire.estimate_encoder(tracker.layout, tracker.model_name)
    out = []
    for rec in StreamReader(stream):
        out.extend(m.decode_estimate(enc(e)) for e in pipe.ingest([rec]).to_publish)
    return out


@pytest.mark.parametrize("name", REFERENCE_NAMES, ids=str)
def test_reference_scenario_end_to_end(name: str, tmp_path: Path) -> None:
    cfg, samples, counts, got, svc = run_live(name, tmp_path)
    n_meas = sum(1 for s in samples if "/meas/" in s.key)
    assert counts["meas"] == n_meas
    assert len(got) == svc.published > 0, "estimates published and received differ"
    st = svc.status_dict()["counts"]
    assert st["applied"] == n_meas and st["truth"] == sum(1 for s in samples if "/truth/" in s.key)
    assert st["inputs"] == sum(1 for s in samples if "/input/" in s.key)  # cv1d_d's control inputs
    assert st["received"] == len(samples) == (st["applied"] + st["inputs"] + st["truth"] + st["duplicates"]
                                              + sum(st["refused"].values()) + st["queued"])
    # exactly what the tracker produces offline on the same input
    off_tracker = Tracker(cfg.tracker)
    offline = _offline(cfg, tmp_path / "live.fstream", tracker=off_tracker)
    assert latest(got, keep_revision=False) == latest(offline, keep_revision=False)
    live, off = svc.tracker.counts, off_tracker.counts
    if live.replays == off.replays == 0 and live.rescans == off.rescans == 0:  # no revisions to differ by
        assert sorted(msgspec.json.encode(e) for e in got) == sorted(msgspec.json.encode(e) for e in offline)
    assert all(e.status != "tentative" for e in got), "a tentative track was published"
    confirmed = {e.track_id for e in got if e.status == "confirmed"}
    assert len(confirmed) == 1, f"one target, {len(confirmed)} confirmed tracks"
    # the service's recording holds every estimate it published, with covariance, NIS and truth
    rows = rrd_rows(tmp_path / "live.rrd")
    (tid,) = confirmed
    n = sum(1 for e in got if e.track_id == tid and e.status == "confirmed")
    from fusion.io.labels import short_id

    lab = short_id(tid)
    for entity in (f"/world/tracks/{lab}/now", f"/world/tracks/{lab}/cov", f"/tracks/{lab}/std"):
        assert rows[entity] == n, entity
    assert rows[f"/tracks/{lab}/nis"] == sum(1 for e in got if e.track_id == tid and e.nis is not None)
    assert rows[f"/tracks/{lab}/nees"] > 0.9 * n, "estimates were not scored against the truth"
    assert rows["/events"] > 0
    v = subprocess.run([str(RERUN), "rrd", "verify", str(tmp_path / "live.rrd")], capture_output=True, text=True,
                       timeout=60)
    assert v.returncode == 0, v.stderr


@pytest.mark.parametrize("name", ["cv1d_d", "helix3d", "helix3d_ekf", "helix3d_ekf_doc"], ids=str)
def test_the_service_tracks_as_well_as_the_reference_filter(name: str, tmp_path: Path) -> None:
    """Through the real service path: cv1d_d with its control input on the wire, the helix
    scenarios with the source document's 5-state models loaded by import path. Position RMSE
    within 10 % of the offline reference filter (fusion.scenarios.run_reference)."""
    from fusion.scenarios import reference, run_reference

    spec, _ = scenario_config(name)
    _, _, _, got, svc = run_live(name, tmp_path)
    if name == "cv1d_d":
        assert svc.status_dict()["counts"]["applied"] == 100 and svc.tracker.counts.inputs == 100
    ref = reference(name, seed=spec.seed)
    est = {e.t_ns: e.state for e in latest(got).values() if e.status == "confirmed"}
    d = len(ref.meas.indices)  # type: ignore[attr-defined]
    idx = list(range(d)) if name != "cv1d_d" else [0]
    rows = [(k, est[int(t)]) for k, t in enumerate(ref.t_ns) if int(t) in est]
    assert len(rows) > 0.9 * ref.n_steps
    err = np.array([np.asarray(x)[idx] - ref.truth[k, idx] for k, x in rows])
    rmse = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    off = run_reference(ref)
    ks = [k for k, _ in rows]
    rmse_ref = float(np.sqrt(np.mean(np.sum((off.x[ks][:, idx] - ref.truth[ks][:, idx]) ** 2, axis=1))))
    assert rmse < 1.1 * rmse_ref, (rmse, rmse_ref)


def test_replay_equals_live_and_is_deterministic(tmp_path: Path) -> None:
    # 20x real time: small batches, so jittered arrivals reach the tracker late and force replays;
    # some measurements held back until the rest is handled, so replays happen however busy the machine
    _, _, _, got, svc = run_live("mix", tmp_path, duration_s=8.0, speed=20.0,
                                 held=held_back(7_000_000_000, 7_600_000_000))
    assert svc.tracker.counts.late_applied > 0, "the mix should deliver late measurements"
    stream = tmp_path / "live.fstream"
    est_a, est_b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    ra = replay(stream, out=tmp_path / "a.rrd", estimates=est_a)
    replay(stream, out=tmp_path / "b.rrd", estimates=est_b)
    assert est_a.read_bytes() == est_b.read_bytes(), "two replays differ"
    replayed = [m.decode_json(line) for line in est_a.read_bytes().splitlines()]
    assert ra.estimates == len(replayed)
    assert len(got) == svc.published, "the live subscriber missed estimates"
    assert latest(replayed, keep_revision=False) == latest(got, keep_revision=False), \
        "replay differs from what the live service published"


GOOD_SENSOR = "cam1"


def _good_and_bad(ns: str) -> tuple[list[tuple[str, bytes]], dict[str, int], int]:
    """1000 good measurements of the mix's camera and 1000 bad messages of every kind, interleaved."""
    rng = np.random.default_rng(11)
    good = []
    for k in range(1000):
        t = (k // 5 + 1) * 100_000_000
        msg = m.Measurement(sensor_id=GOOD_SENSOR, t_ns=t, seq=k,
                            data=m.Cartesian(pos_m=[100.0 * (k % 5) + rng.normal(), 50.0 + rng.normal()],
                                             std_m=[3.0, 3.0]))
        good.append((m.meas_key(ns, GOOD_SENSOR), m.encode(msg)))
    key = m.meas_key(ns, GOOD_SENSOR)

    def meas(**kw) -> m.Measurement:
        base = dict(sensor_id=GOOD_SENSOR, t_ns=50_000_000, seq=0,
                    data=m.Cartesian(pos_m=[1.0, 2.0], std_m=[1.0, 1.0]))
        base.update(kw)
        return m.Measurement(**base)

    kinds = {
        # random bytes: refused as malformed, or as invalid when they happen to decode as msgpack
        "malformed": lambda i, j: (key, bytes(rng.integers(0, 256, 12, dtype=np.uint8))),
        "invalid": lambda i, j: (key, msgspec.msgpack.encode({"type": "measurement", "sensor_id": GOOD_SENSOR,
                                                              "t_ns": 1, "seq": 5000 + i, "data": {"type": "radar"}})),
        "nan": lambda i, j: (key, m.encode(meas(seq=10_000 + i, data=m.Cartesian(pos_m=[math.nan, 1.0],
                                                                                 std_m=[1.0, 1.0])))),
        "unknown_sensor": lambda i, j: (m.meas_key(ns, "ghost"), m.encode(meas(sensor_id="ghost", seq=i))),
        "bad_covariance": lambda i, j: (key, m.encode(meas(seq=20_000 + i, data=m.Cartesian(
            pos_m=[1.0, 2.0], cov_m2=[1.0, 2.0, 2.0, 1.0])))),
        "future": lambda i, j: (key, m.encode(meas(seq=30_000 + i, t_ns=10**15))),
        "too_late": lambda i, j: (key, m.encode(meas(seq=40_000 + i, t_ns=1))),
        "duplicate": lambda i, j: good[j],  # the latest good message, sent again
    }
    bad_counts = {k: 125 for k in kinds}
    out: list[tuple[str, bytes]] = []
    bad_iter = [(k, i) for i in range(125) for k in kinds]
    for j, g in enumerate(good):
        out.append(g)
        if j >= 100 and bad_iter:  # after the stream is under way (too_late needs a newest time)
            for _ in range(2):
                if bad_iter:
                    k, i = bad_iter.pop(0)
                    out.append(kinds[k](i, j))
    assert not bad_iter
    return out, bad_counts, len(good)


def test_good_and_bad_input(tmp_path: Path) -> None:
    _, cfg = scenario_config("mix")
    # the camera alone: a configured sensor that has not spoken yet holds the window open for
    # source_idle_s (fusion.tracking.clock), and this test wants old data refused at once
    cam = [s for s in cfg.tracker.sensors if s.id == GOOD_SENSOR]
    cfg = msgspec.structs.replace(cfg, tracker=msgspec.structs.replace(cfg.tracker, sensors=cam))
    stream, bad_counts, n_good = _good_and_bad(cfg.namespace)
    with running_service(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            put_all(s, stream)
            assert svc.wait_idle(timeout_s=60.0)
            status = m.decode_status(query(s, m.status_key(cfg.namespace)))
        finally:
            s.close()
    c = status.counts
    assert c.applied == n_good, "a good measurement was lost"
    assert c.duplicates == bad_counts["duplicate"]
    refused = dict(c.refused)
    # NaN is refused at decode as invalid; random bytes as malformed or invalid
    assert refused.pop("malformed", 0) + refused.pop("invalid") == sum(bad_counts[k] for k in ("malformed", "invalid",
                                                                                               "nan"))
    assert refused == {k: v for k, v in bad_counts.items() if k not in ("duplicate", "nan", "invalid", "malformed")}
    assert c.received == c.applied + c.truth + c.duplicates + sum(c.refused.values()) + c.queued
    assert c.received == len(stream)


def test_status_and_snapshot(tmp_path: Path) -> None:
    spec, cfg = scenario_config("radar2d")
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    with running_service(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            publish(s, samples, speed=0.0, match_timeout_s=5.0)
            assert svc.wait_idle(timeout_s=30.0)
            time.sleep(0.15)  # the loop refreshes the answers every 0.1 s
            status = m.decode_status(query(s, m.status_key(cfg.namespace)))
            snap = m.decode_snapshot(query(s, m.snapshot_key(cfg.namespace)))
        finally:
            s.close()
    c = status.counts
    assert c.applied == 200
    assert c.received == c.applied + c.truth + c.duplicates + sum(c.refused.values()) + c.queued == 400
    assert status.tracks == {"confirmed": 1}
    assert status.latency["radar"].count == 200
    assert status.recording is not None and status.recording_bytes > 0
    assert len(snap.estimates) == 1 and snap.estimates[0].status == "confirmed"
    assert snap.estimates[0].t_ns == 20_000_000_000


def test_sigterm_leaves_a_complete_recording(tmp_path: Path) -> None:
    spec, cfg = scenario_config("maneuver2d")
    from publishers.spec import scenario_path

    conf = scenario_path("maneuver2d")  # a scenario file: serve takes its [service] table
    port = free_tcp_port()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "fusion", "serve", "--config", str(conf), "--listen", f"tcp/127.0.0.1:{port}",
         "--recordings", str(tmp_path / "rec")],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, cwd=Path(__file__).resolve().parents[2],
    )
    try:
        seen = []
        for _ in range(20):
            line = proc.stdout.readline().decode()  # type: ignore[union-attr]
            seen.append(line)
            if "serving" in line or not line:
                break
        assert "serving" in line, "".join(seen)
        samples, _ = build_stream(spec, namespace=cfg.namespace)
        s = client(f"tcp/127.0.0.1:{port}")
        try:
            publish(s, samples[: len(samples) // 2], speed=0.0, match_timeout_s=10.0)
            time.sleep(0.5)
        finally:
            s.close()
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out.decode()
    files = sorted((tmp_path / "rec").glob("*.rrd"))
    assert files, "no recording written"
    v = subprocess.run([str(RERUN), "rrd", "verify", str(files[0])], capture_output=True, text=True, timeout=60)
    assert v.returncode == 0, v.stderr
    from fusion.io.inspect import summarise

    summary = summarise(files[0])
    assert summary.complete and summary.counts["applied"] > 0


def test_demo_runs(tmp_path: Path) -> None:
    from publishers.demo import demo_report, run_demo

    r = run_demo(scenario="mix", duration_s=5.0, out=tmp_path / "demo.rrd", speed=0.0)
    assert r.recording.exists() and r.stream.exists()
    assert len(r.summary.tracks) >= 4
    assert r.summary.position_rmse is not None and r.summary.position_rmse < 10.0
    assert "rerun " in demo_report(r)


@pytest.mark.parametrize(("name", "steps"), [("cv1d_c", 50), ("helix3d", 100)], ids=str)
def test_the_demo_runs_the_whole_scenario_by_default(name: str, steps: int, tmp_path: Path) -> None:
    from publishers.demo import run_demo

    r = run_demo(scenario=name, out=tmp_path / f"{name}.rrd", speed=0.0)
    assert r.published.get("meas") == steps and r.counts["applied"] == steps
