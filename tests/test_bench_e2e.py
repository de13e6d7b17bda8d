"""The end-to-end benchmark's load and harness (bench/e2e_*.py, bench/service_e2e.py): the
messages are valid and tracked as intended, re-stamping moves every sensor time, and (slow) one
short throughput and latency run against a real `fusion serve` adds up. No timing is asserted."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from bench.e2e_load import MSGS_PER_TARGET_S, Prepared, Scene
from fusion import messages as m
from fusion.config import load_service_config
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "service.toml"


def test_scene_schedule_and_validity() -> None:
    t0 = 1_700_000_000_000_000_000
    scans = []
    for t, s, payloads in Scene(7, seed=3).ticks(t0):
        scans.append((t, s, [m.decode_measurement(p) for p in payloads]))
        if len(scans) == 12:
            break
    radar = [t - t0 for t, s, _ in scans if s == 0]
    cam = [t - t0 for t, s, _ in scans if s == 1]
    assert radar == [k * 100_000_000 for k in range(len(radar))]  # 10 Hz
    assert cam == [50_000_000 + k * 200_000_000 for k in range(len(cam))]  # 5 Hz
    for t, s, msgs in scans:
        assert len(msgs) == 7 and {x.t_ns for x in msgs} == {t}
        assert {x.sensor_id for x in msgs} == {("radar1", "cam1")[s]}
    seqs = [x.seq for _, s, msgs in scans if s == 0 for x in msgs]
    assert seqs == list(range(len(seqs)))


def test_restamp_moves_every_sensor_time() -> None:
    p = Prepared(5, 200, seed=1)
    for t0 in (1_800_000_000_000_000_000, 1_800_000_123_456_789_000):
        p.restamp(t0)
        got = [m.decode_measurement(bytes(b)).t_ns - t0 for b in p.buf]
        assert got == p.rel_ns
    # 200 messages = 40 scans of 5; 3 scans (radar, camera, radar) per 200 ms: the 40th is the radar at 2.6 s
    assert len(p.buf) == 200 and p.rel_ns[-1] == 2_600_000_000


def test_the_shipped_tracker_follows_every_target() -> None:
    """Every message is applied (none refused) and every target ends as one confirmed track (a
    true measurement outside the 0.999 gate starts a tentative track now and then)."""
    targets = 30
    p = Prepared(targets, targets * MSGS_PER_TARGET_S * 2, seed=5)  # 2 s
    tracker, c = _through_the_shipped_tracker(p, batch=500)
    assert c.applied == len(p.buf) and not c.refused
    assert len(tracker.confirmed()) == targets and len(tracker.tracks) <= targets + 5


def _through_the_shipped_tracker(p: Prepared, *, batch: int, t0: int | None = None) -> tuple[Tracker, m.Counts]:
    """The prepared messages, stamped from t0 (now if None), through the shipped configuration's
    pipeline in batches of `batch` samples in the order sent: the tracker and the pipeline's counts."""
    t0 = time.time_ns() if t0 is None else t0
    p.restamp(t0)
    keys = [m.meas_key("demo", s) for s in ("radar1", "cam1")]
    records = [(t0 + rel, keys[s], bytes(b)) for s, b, rel in zip(p.sensor, p.buf, p.rel_ns, strict=True)]
    tracker = Tracker(load_service_config(CONFIG).tracker)
    pipe = Pipeline(tracker, wire.Codec("demo"))
    for i in range(0, len(records), batch):
        pipe.ingest(records[i:i + batch])
    return tracker, pipe.counts()


def test_late_order_holds_back_a_tenth_within_25_scans() -> None:
    """Prepared's `late`: the same messages; those after the first LATE_WARM_SCANS scans held back
    with probability ~0.1 and sent after a scan 1 to LATE_MAX_SCANS scans later; the rest in
    time order. Through the shipped tracker they give the tracks of the time order, bit for bit,
    every one applied (none left the window)."""
    from bench.e2e_load import LATE_MAX_SCANS, LATE_WARM_SCANS

    targets, n = 20, 20 * MSGS_PER_TARGET_S * 6  # 6 s: 90 scans
    a, b = Prepared(targets, n, seed=5), Prepared(targets, n, seed=5, late=0.1)
    assert sorted(bytes(x) for x in a.buf) == sorted(bytes(x) for x in b.buf)
    scan_times = sorted(set(a.rel_ns))
    scan_of = {t: k for k, t in enumerate(scan_times)}
    newest, held, backs = -1, 0, []
    for rel in b.rel_ns:  # the scan each message belongs to, against the newest scan sent before it
        k = scan_of[rel]
        if k < newest:
            held += 1
            backs.append(newest - k)
            assert k >= LATE_WARM_SCANS
        newest = max(newest, k)
    timed = sum(1 for rel in a.rel_ns if scan_of[rel] >= LATE_WARM_SCANS)
    assert 0.07 < held / timed < 0.13, held / timed
    assert min(backs) >= 1 and max(backs) <= LATE_MAX_SCANS
    tracks = []
    t0 = time.time_ns()
    for p in (a, b):
        tracker, c = _through_the_shipped_tracker(p, batch=50, t0=t0)
        assert c.applied == len(p.buf) and not c.refused
        ts = tracker.track_set
        tracks.append((ts.ids.tobytes(), ts.X.tobytes(), ts.P.tobytes()))
    assert tracks[0] == tracks[1] and c.late_applied > 0


@pytest.mark.slow
def test_short_runs_against_a_real_service(tmp_path: Path) -> None:
    from bench.e2e_procs import Publisher
    from bench.service_e2e import latency_run, throughput_run

    with Publisher() as pub:
        pub.call("prepare", {"targets": 10, "messages": 1500, "seed": 1}, timeout_s=120.0)
        r = throughput_run(pub, tmp_path / "tp", n=1500, targets=10, recording=True, window_s=1.0,
                           warm_deadline_s=120.0, after_warm_s=60.0)
        assert r["drained"] and r["counts_add_up"] and not r["refused"], r
        assert r["applied"] == r["received"] and r["recording_bytes_per_meas"] > 0
        lat = latency_run(pub, tmp_path / "lat", rate=150, recording=False, duration_s=4.0, grace_s=30.0, warm_s=1.0)
        assert lat["kept_up"] and lat["coverage"] > 0.9, lat
        assert np.isfinite(lat["p50_ms"]) and lat["p50_ms"] <= lat["p99_ms"] <= lat["max_ms"]
        late = latency_run(pub, tmp_path / "late", rate=150, recording=False, duration_s=4.0, grace_s=30.0,
                           warm_s=1.0, late=0.1)  # held back after 2 s (LATE_WARM_SCANS)
        assert late["kept_up"] and not late["refused"] and late["sent"] < lat["sent"], late


def test_the_dense_scene_is_the_mix_s_sensors_over_its_targets() -> None:
    """Prepared(dense=True): the mix's radar (10 Hz) and camera (5 Hz, at the radar's times) over
    mix_truth's targets, with missed detections and clutter; re-stamped like the grid; through
    the shipped tracker every message is applied and nearly every target is held by a confirmed
    track (two cross and the rest converge, so not every one)."""
    targets = 20
    p = Prepared(targets, 600, seed=4, dense=True)
    assert len(p.buf) == 600
    msgs = [m.decode_measurement(bytes(b)) for b in p.buf]
    t0 = msgs[0].t_ns
    radar = sorted({x.t_ns - t0 for x in msgs if x.sensor_id == "radar1"})
    cam = sorted({x.t_ns - t0 for x in msgs if x.sensor_id == "cam1"})
    assert np.all(np.diff(radar) == 100_000_000) and np.all(np.diff(cam) == 200_000_000) and set(cam) <= set(radar)
    per_radar_scan = np.bincount([radar.index(x.t_ns - t0) for x in msgs if x.sensor_id == "radar1"])
    assert per_radar_scan.max() > targets, "no clutter"
    assert per_radar_scan.min() < targets + 2, "no missed detection or clutter-free scan"
    assert [s for s in p.sensor] == [0 if x.sensor_id == "radar1" else 1 for x in msgs]
    p.restamp(1_800_000_000_000_000_000)
    assert [m.decode_measurement(bytes(b)).t_ns - 1_800_000_000_000_000_000 for b in p.buf] == p.rel_ns
    tracker, c = _through_the_shipped_tracker(p, batch=200)
    assert c.applied == len(p.buf) and not c.refused
    assert targets - 3 <= len(tracker.confirmed()) <= targets + 3
