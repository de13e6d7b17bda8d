"""A scan run again reports the associations that changed and the new measurements'
(fusion.tracking.history.revise_associations): kept as the latest per measurement, the reported
rows rebuild every scan's associations as the tracker holds them, whatever the arrival order,
and a re-run reports fewer rows than its scan holds."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.tracking.tracker import Tracker
from tests.tracking.test_selective_replay import arrivals, mixed, shipped


def _rows(block) -> list[tuple]:  # type: ignore[no-untyped-def]
    return [(a.sensor_id, a.t_ns, a.seq, a.outcome, a.track_id, a.nis, a.gated) for a in block.rows()]


@pytest.mark.parametrize("late_fraction", [0.0, 0.1, 0.3])
def test_the_reported_changes_rebuild_every_scans_associations(late_fraction: float) -> None:
    dets = mixed(5, n_targets=12, duration_s=6.0, spread_m=600.0, manoeuvre=(0, 2.0, 4.0, 0.2))
    calls = arrivals(dets, np.random.default_rng(6), late_fraction=late_fraction, max_back=15)
    tr = Tracker(shipped())
    latest: dict[tuple, tuple] = {}
    rows = whole = shorter = 0
    for batch in calls:
        for block in tr.process(batch).associations:
            got = _rows(block)
            rows += len(got)
            for r in got:
                latest[r[:3]] = r
            held = [e for e in tr.history.entries if e.key == (block.t_ns, block.sensor_id)]
            n = len(held[0].associations) if held else len(block)  # type: ignore[arg-type]
            whole += n  # reported whole, as before
            shorter += len(block) < n
    window = [r for e in tr.history.entries for r in _rows(e.associations)]
    assert window and all(latest[r[:3]] == r for r in window)
    if late_fraction:
        assert tr.counts.replays > 5 and shorter > 0, (tr.counts.replays, shorter)
        assert rows < whole / 2, (rows, whole)  # each scan run again reported whole: more than twice the rows
    else:
        assert rows == len(latest)  # in order: each measurement's association once
