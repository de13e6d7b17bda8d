"""The record is scored every flush_interval_s and written every write_interval_s
(fusion.io.rerun_sink): between writes its rows wait in memory, so the file gets fewer, larger
chunks (each costs a row of the footer's index that Rerun holds until the file closes); the rows
are the same, a held record goes out at flush_rows rows, at a view flush and at close, and the
service's configuration reaches the sink."""

from __future__ import annotations

import itertools
from collections import Counter
from pathlib import Path

from rerun.chunk import RrdReader

from tests.io.recording_digest import digest
from tests.io.scenario_run import maneuver_run, record_scenario


def _record_chunks(path: Path) -> Counter[str]:
    return Counter(ch.entity_path for ch in RrdReader(str(path)).stream() if ch.entity_path.startswith("/record/"))


def test_held_record_rows_are_the_same_rows_in_fewer_chunks(tmp_path: Path) -> None:
    kw = {"duration_s": 20.0, "flush_interval_s": 0.0, "view_interval_s": 1e9}  # a record flush every ingest
    record_scenario("mix", tmp_path / "each.rrd", **kw)  # written at every flush (write interval: the flush's)
    record_scenario("mix", tmp_path / "held.rrd", write_interval_s=1e9, write_rows=10**9, **kw)  # written at close only
    assert digest(tmp_path / "held.rrd") == digest(tmp_path / "each.rrd")
    each, held = _record_chunks(tmp_path / "each.rrd"), _record_chunks(tmp_path / "held.rrd")
    assert set(held) == set(each) == {"/record/estimates", "/record/associations", "/record/events", "/record/truth"}
    assert min(each.values()) > 20, each  # one chunk per flush
    assert max(held.values()) == 1, held  # one chunk each, at close


def test_a_held_record_goes_out_at_flush_rows(tmp_path: Path) -> None:
    from fusion.io.rerun_sink import RerunSink

    tr, dets, _truth = maneuver_run(seed=3)
    sink = RerunSink(
        tmp_path / "r.rrd",
        layout=tr.layout,
        position_indices=tr.position_indices,
        velocity_indices=tr.velocity_indices,
        flush_interval_s=0.0,
        write_interval_s=1e9,
        write_rows=10**9,
        view_interval_s=1e9,
        flush_rows=150,
    )
    written = []
    for d in dets:
        sink.log_step(tr.process([d]))
        written.append(sink.rows_written)
    assert written[-1] > 0, "nothing written before close: flush_rows did not bound the held record"
    steps = [b - a for a, b in itertools.pairwise(written) if b > a]
    assert min(steps) >= 150, steps  # each write carries at least flush_rows rows of the record
    sink.close()
    assert sum(_record_chunks(tmp_path / "r.rrd").values()) < len(dets) / 10


def test_the_service_configuration_sets_the_write_interval() -> None:
    from fusion.config import RecordingConfig

    assert RecordingConfig().write_interval_s == 1.0
    assert RecordingConfig().flush_interval_s == 0.2


def test_a_held_record_entity_goes_out_at_write_rows(tmp_path: Path) -> None:
    """Chunks of a few thousand rows: Rerun compresses larger ones worse (fusion.io.rerun_sink.WRITE_ROWS)."""
    kw = {"duration_s": 20.0, "flush_interval_s": 0.0, "view_interval_s": 1e9, "write_interval_s": 1e9}
    record_scenario("mix", tmp_path / "capped.rrd", write_rows=500, **kw)
    chunks = RrdReader(str(tmp_path / "capped.rrd")).stream()
    rows = [ch.num_rows for ch in chunks if ch.entity_path == "/record/estimates"]
    assert len(rows) > 3, rows
    assert max(rows[:-1]) < 500 + 100, rows  # written at the first flush that held write_rows (a flush adds < 100)
