"""An entity of the views that holds view_rows_max rows goes out with the next record flush
instead of waiting for the view flush (fusion.io.rerun_sink.VIEW_ROWS_MAX): the same rows in the
file, written in more pieces, so a view flush never converts a long stretch of the all-track
entities at once."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from rerun.chunk import RrdReader

from tests.io.recording_digest import digest
from tests.io.scenario_run import record_scenario


def _chunks(path: Path) -> Counter[str]:
    return Counter(ch.entity_path for ch in RrdReader(str(path)).stream() if not ch.is_static)


def test_full_view_entities_go_out_with_the_record_and_the_rows_are_the_same(tmp_path: Path) -> None:
    kw = {"duration_s": 20.0, "flush_rows": 300, "flush_interval_s": 1e9, "view_interval_s": 1e9}
    record_scenario("mix", tmp_path / "default.rrd", **kw)  # views only at close
    record_scenario("mix", tmp_path / "small.rrd", view_rows_max=200, **kw)
    assert digest(tmp_path / "small.rrd") == digest(tmp_path / "default.rrd")
    default, small = _chunks(tmp_path / "default.rrd"), _chunks(tmp_path / "small.rrd")
    assert default["/world/estimates"] == 1 and default["/events"] == 1
    n = digest(tmp_path / "small.rrd")["/world/estimates"]["rows"]
    assert n > 1000
    # written at the record flushes (every 300 pending rows) once 200 were held: each piece holds
    # 200 rows or more, one every few record flushes: mix's 1701 rows in 8 pieces
    assert small["/world/estimates"] >= n // 400
    assert small["/world/estimates"] <= n // 200 + 1
    assert small["/record/estimates"] == default["/record/estimates"]  # the record's flushes are unchanged
