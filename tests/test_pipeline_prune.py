"""The service prunes the publication view after publishing a batch (Pipeline.ingest(...,
prune=False), then Pipeline.prune), not inside ingest: what is published and what the view keeps
are the same as with the pruning inside, batch for batch."""

from __future__ import annotations

from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker
from tests.test_held_scans import _records


def _published(out) -> list[tuple]:  # type: ignore[no-untyped-def]
    return [(e.key, e.revision, e.status) for e in out.to_publish]


def test_pruning_after_publishing_publishes_and_keeps_the_same() -> None:
    records, service = _records(20, 6.0)
    inside = Pipeline(Tracker(service.tracker), wire.Codec(service.namespace))
    after = Pipeline(Tracker(service.tracker), wire.Codec(service.namespace))
    unpruned = Pipeline(Tracker(service.tracker), wire.Codec(service.namespace))
    for i in range(0, len(records), 40):
        chunk = records[i:i + 40]
        a = inside.ingest(chunk)
        b = after.ingest(chunk, prune=False)
        unpruned.ingest(chunk, prune=False)
        assert _published(a) == _published(b)
        assert a.events_to_publish == b.events_to_publish
        after.prune()
        assert inside.view.latest.keys() == after.view.latest.keys()
        assert inside.view.tracks == after.view.tracks
    # the pruning forgot keys (the test shows something), which a pipeline never pruned keeps
    assert len(inside.view.latest) < len(unpruned.view.latest) / 2, (len(inside.view.latest), len(unpruned.view.latest))
