"""bench.recording_truth's data without truth: every measurement kept, in its scan and place, no
truth sample left (the benchmark compares the recording's cost on both)."""

from __future__ import annotations

from bench import recording_cost as rc
from bench.recording_truth import without_truth


def test_without_truth_keeps_every_measurement_in_place() -> None:
    data = rc.batches(3, 1.0, ns="demo")
    stripped = without_truth(data)
    assert len(stripped) == len(data)
    assert any("/truth/" in k for recs in data for _, k, _ in recs)
    assert not any("/truth/" in k for recs in stripped for _, k, _ in recs)
    assert stripped == [[r for r in recs if "/meas/" in r[1]] for recs in data]
    assert (rc._measurements_so_far(stripped) == rc._measurements_so_far(data)).all()
