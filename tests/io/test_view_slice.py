"""A view flush writes the record at once and the views' entities VIEW_SLICE per later call of
maybe_flush (fusion.io.rerun_sink.VIEW_SLICE), so the service's loop never waits for all of them
in one call: the same rows in the file, and nothing left unwritten at close."""

from __future__ import annotations

import itertools
from pathlib import Path

from rerun.chunk import RrdReader

from tests.io.recording_digest import digest
from tests.io.scenario_run import maneuver_run, record_scenario


def test_sliced_view_flushes_write_the_same_rows(tmp_path: Path) -> None:
    kw = {"duration_s": 20.0, "flush_rows": 300, "flush_interval_s": 1e9, "view_interval_s": 0.0}
    record_scenario("mix", tmp_path / "whole.rrd", view_slice=10**6, **kw)  # every flush a view flush, all at once
    record_scenario("mix", tmp_path / "sliced.rrd", view_slice=3, **kw)
    assert digest(tmp_path / "sliced.rrd") == digest(tmp_path / "whole.rrd")


def test_the_views_entities_wait_for_later_calls_and_close_writes_them(tmp_path: Path) -> None:
    from fusion.io.rerun_sink import RerunSink

    tr, dets, truth = maneuver_run(seed=3)
    sink = RerunSink(tmp_path / "r.rrd", layout=tr.layout, position_indices=tr.position_indices,
                     velocity_indices=tr.velocity_indices, flush_interval_s=1e9, view_interval_s=0.0, view_slice=2,
                     flush_rows=400)  # a view flush every 400 rows (log_step calls maybe_flush)
    for t, x in sorted(truth.items()):
        sink.log_truths([("target", t, x)])
    waiting = []
    for d in dets:
        sink.log_step(tr.process([d]))
        waiting.append(sink.waiting)
    assert max(waiting) > 2, "the views' entities all went out with the record"
    drained = [a - b for a, b in itertools.pairwise(waiting) if 0 < b < a]
    assert drained and set(drained) == {2}, "a call between view flushes writes view_slice entities"
    sink.close()
    assert sink.waiting == 0
    written = {ch.entity_path for ch in RrdReader(str(tmp_path / "r.rrd")).stream()}
    assert {"/world/estimates", "/events"} <= written
