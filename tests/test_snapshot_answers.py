"""The snapshot answer reuses the bytes each estimate was published with (kept by identity), encodes
an estimate of the snapshot that was not published as it is, and keeps only the snapshot's bytes
after a refresh."""

from __future__ import annotations

import pytest

from fusion import messages as m
from fusion.io import wire
from fusion.snapshot_answers import SnapshotAnswers
from tests.io.scenario_run import maneuver_run


def test_refresh_uses_the_published_bytes_and_encodes_the_rest() -> None:
    tr, dets, _ = maneuver_run(seed=3)
    ests = [e for d in dets[:40] for e in tr.process([d]).estimates]
    a, b = ests[-2], ests[-1]
    revised = b.with_revision(b.revision + 1)  # the same key, another estimate: not what was published
    snapshot = [a, revised]
    answers = SnapshotAnswers("demo", tr, lambda: snapshot)
    answers.published([a, b], [b"KEPT-A", b"KEPT-B"])
    answers.refresh()
    enc = wire.estimate_encoder(tr.layout, tr.model_name)
    assert answers.payload == wire.snapshot_of_encoded([b"KEPT-A", enc(revised)])
    snapshot[:] = [revised]
    answers.refresh()  # the kept bytes of what left the snapshot are gone; revised's are reused
    assert answers.payload == wire.snapshot_of_encoded([enc(revised)])
    assert m.decode_snapshot(answers.payload).estimates[0].revision == b.revision + 1
    with pytest.raises(ValueError, match="2 estimates, 1 payloads"):
        answers.published([a, b], [b"x"])
