"""fusion.ledger: a run's counts add up over every fate a sample can meet, with a real intake
queue and the shipped pipeline (no Zenoh: the service's parts the counts come from)."""

from __future__ import annotations

from pathlib import Path

from fusion import messages as m
from fusion.config import load_service_config
from fusion.io import wire
from fusion.io.intake_queue import IntakeLimits, IntakeQueue
from fusion.ledger import Ledger
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "service.toml"
S = 1_000_000_000


def _meas(ns: str, sensor: str, t_ns: int, seq: int, x: float) -> tuple[str, bytes]:
    msg = m.Measurement(sensor_id=sensor, t_ns=t_ns, seq=seq, data=m.Cartesian(pos_m=[x, 0.0], std_m=[3.0, 3.0]))
    return m.meas_key(ns, sensor), m.encode(msg)


def _adds_up(c: dict) -> bool:
    return c["received"] == (c["applied"] + c["inputs"] + c["truth"] + c["duplicates"] + sum(c["refused"].values())
                             + c["queued"])


def test_the_counts_add_up_over_every_fate_a_sample_meets() -> None:
    cfg = load_service_config(CONFIG)
    ns = cfg.namespace
    pipe = Pipeline(Tracker(cfg.tracker), wire.Codec(ns))
    q = IntakeQueue(IntakeLimits(queue_max=1000, queue_max_bytes=10**6, max_message_bytes=400),
                    known=["radar1", "cam1"])
    ledger = Ledger(pipe, q)
    good = [_meas(ns, "cam1", S + k * S // 5, k, 100.0 + k) for k in range(10)]
    samples = good + [good[3]]  # the same measurement again: a duplicate
    samples.append((m.meas_key(ns, "cam1"), b"\x93not a measurement"))  # refused when decoded: invalid
    samples.append((m.meas_key(ns, "cam1"), b"x" * 500))  # refused at the door: too large
    samples.append(_meas(ns, "radar9", S, 0, 5.0))  # a sensor the tracker does not know
    for arrival, (key, payload) in enumerate(samples):
        assert q.offer(arrival, key, len(payload), lambda p=payload: p) in (None, "too_large")
    assert ledger.counts(published=0)["queued"] == len(samples) - 1 and _adds_up(ledger.counts(published=0))

    batch = q.drain(len(samples))
    pipe.ingest(batch[:6], more=True)  # the last scan of a cut batch waits for its rest: taken, not applied
    ledger.took(6)
    c = ledger.counts(published=0)
    assert pipe.holding == 1 and c["queued"] == len(samples) - 1 - 6 + 1 and _adds_up(c)
    pipe.ingest(batch[6:])
    ledger.took(len(batch) - 6)
    assert _adds_up(ledger.counts(published=7))
    for arrival, (key, payload) in enumerate(_meas(ns, "cam1", 4 * S, 50 + k, 9.0) for k in range(3)):
        q.offer(100 + arrival, key, len(payload), lambda p=payload: p)
    ledger.dropped(key for _, key, _ in q.drain(3))  # still queued when shutdown's deadline came
    c = ledger.counts(published=7)
    assert _adds_up(c) and c["queued"] == 0 and c["published"] == 7 and c["received"] == len(samples) + 3
    assert c["applied"] == 10 and c["duplicates"] == 1
    assert c["refused"] == {"invalid": 1, "shutdown": 3, "too_large": 1, "unknown_sensor": 1}, c["refused"]
    assert ledger.intake_refused() == {"too_large": 1, "shutdown": 3}
    assert ledger.handled == len(samples) - 1 + 1  # taken by the loop, or refused at the door
    flat = ledger.for_recording()
    assert flat["refused/shutdown"] == 3 and flat["refused/too_large"] == 1 and flat["applied"] == 10


def test_a_resumed_tracker_s_counts_are_not_this_run_s() -> None:
    cfg = load_service_config(CONFIG)
    ns = cfg.namespace
    pipe = Pipeline(Tracker(cfg.tracker), wire.Codec(ns))
    q = IntakeQueue(IntakeLimits(queue_max=100, queue_max_bytes=10**6, max_message_bytes=400), known=["cam1"])
    pipe.ingest([(0, *_meas(ns, "cam1", S, 0, 1.0))])  # what a checkpoint would carry in
    ledger = Ledger(pipe, q)
    ledger.resumed()
    assert ledger.run_counts().applied == 0
    key, payload = _meas(ns, "cam1", 2 * S, 1, 2.0)
    q.offer(1, key, len(payload), lambda: payload)
    pipe.ingest(q.drain(1))
    ledger.took(1)
    c = ledger.counts(published=0)
    assert c["applied"] == 1 and c["received"] == 1 and _adds_up(c)
