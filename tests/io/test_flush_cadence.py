"""When the record is scored (fusion.io.rerun_sink.RerunSink.maybe_flush): every flush_interval_s
once flush_min_rows rows wait, every write_interval_s whatever waits, at once at flush_rows. A
flush costs about the same however few rows it holds, so a slow stream (10 targets in real time:
~30 measurements in 0.2 s) is scored at the write cadence, not five times as often.

Real time with wide margins: the intervals tested against are 0.01 s and >= 0.4 s apart."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from fusion.config import RecordingConfig
from fusion.io.recording import service_recording
from fusion.io.rerun_sink import RerunSink

LAYOUT = ("x", "vx", "y", "vy")
STATE = np.array([1.0, 0.0, 2.0, 0.0])


def _truths(sink, n: int, t0_ns: int) -> None:
    for k in range(n):  # one pending row each
        sink.log_truths([(f"t{k}", t0_ns, STATE)])


def _sink(path: Path, **kw) -> RerunSink:
    return RerunSink(path, layout=LAYOUT, position_indices=(0, 2), velocity_indices=(1, 3), **kw)


def test_few_rows_wait_for_the_write_interval_many_go_at_the_flush_interval(tmp_path: Path) -> None:
    with _sink(tmp_path / "a.rrd", flush_interval_s=0.01, write_interval_s=0.4, flush_min_rows=50) as sink:
        start = time.monotonic()
        _truths(sink, 10, 1_000_000_000)
        time.sleep(0.05)
        sink.maybe_flush()
        assert sink.flushes == 0, "10 rows < flush_min_rows were scored before the write interval"
        time.sleep(max(0.0, 0.45 - (time.monotonic() - start)))
        sink.maybe_flush()
        assert sink.flushes == 1, "rows waiting a write interval were not scored"
        _truths(sink, 60, 2_000_000_000)
        time.sleep(0.05)
        sink.maybe_flush()
        assert sink.flushes == 2, "flush_min_rows rows waiting a flush interval were not scored"
        _truths(sink, 10, 3_000_000_000)
        sink.maybe_flush()
        assert sink.flushes == 2


def test_flush_rows_go_at_once(tmp_path: Path) -> None:
    with _sink(tmp_path / "b.rrd", flush_interval_s=60.0, write_interval_s=60.0, flush_rows=100,
               flush_min_rows=50) as sink:
        _truths(sink, 99, 1_000_000_000)
        sink.maybe_flush()
        assert sink.flushes == 0
        _truths(sink, 1, 2_000_000_000)
        sink.maybe_flush()
        assert sink.flushes == 1


@pytest.mark.parametrize("min_rows", [0, 50])
def test_the_service_configuration_reaches_the_sink(tmp_path: Path, min_rows: int) -> None:
    rc = RecordingConfig(flush_interval_s=0.01, write_interval_s=60.0, flush_min_rows=min_rows)
    rotating = service_recording(rc, tmp_path, layout=LAYOUT, position_indices=(0, 2), velocity_indices=(1, 3))
    try:
        _truths(rotating, 10, 1_000_000_000)
        time.sleep(0.05)
        rotating.maybe_flush()
        assert rotating.sink.flushes == (1 if min_rows == 0 else 0)
    finally:
        rotating.close()


def test_the_shipped_minimum() -> None:
    # ~1 450 measurements (~2.75 rows each): 0.2 s holds more from ~7 300 measurements/s on
    assert RecordingConfig().flush_min_rows == 4000
