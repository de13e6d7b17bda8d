"""Two sensors scanning at the same times (the mix: radar1 and cam1 every 0.1 s) hand an event from
one scan to the other when a late measurement is replayed: the first scan now confirms the track,
the second's confirmation (the same event) vanishes. A step reports its withdrawals before its new
events, so a consumer applying them in order keeps the event; the events it holds, and those a
subscriber of the published view holds, are the same whatever the batching. The control: in the
old order the consumer loses the confirmation of a track that stayed confirmed."""

from __future__ import annotations

import msgspec
import pytest

import fusion.tracking.tracker as tracker_module
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream
from tests.tracking.helpers import Consumer


def _deliver(batch: int) -> Consumer:
    sf = load_scenario_file(scenario_path("mix"))
    samples, _ = build_stream(msgspec.structs.replace(sf.scenario, duration_s=12.0), namespace=sf.service.namespace)
    records = [(s.arrival_ns, s.key, s.payload) for s in samples]
    pipe = Pipeline(Tracker(sf.service.tracker), wire.Codec(sf.service.namespace))
    consumer = Consumer()
    for i in range(0, len(records), batch):
        consumer.take(pipe.ingest(records[i:i + batch]).result)
    assert pipe.tracker.arrival_counts["replays"] > 0 or batch >= len(records)
    return consumer


def test_events_held_do_not_depend_on_batching_when_sensors_scan_at_the_same_times() -> None:
    whole = _deliver(10**9)
    for batch in (1, 7):
        c = _deliver(batch)
        assert c.events == whole.events, batch
        assert c.subscribed_events == whole.subscribed_events, batch
    assert sum(1 for k in whole.events if k[0] == "confirmed") >= 6


def test_in_the_old_order_a_consumer_loses_an_event(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tracker_module, "withdrawals_first", tuple)
    with pytest.raises(AssertionError, match="reported twice"):
        _deliver(1)
