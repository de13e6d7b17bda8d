"""A flush stops at pause() between its parts (fusion.io.rerun_sink: after the steps' rows,
after scoring, between viewed tracks, before each entity it sends), so the recording's thread can
let the service's loop run a scan in the middle of a flush (fusion.io.sink_thread); the file is
the same with or without the pauses."""

from __future__ import annotations

from pathlib import Path

from fusion.io.rerun_sink import RerunSink
from tests.io.recording_digest import digest
from tests.io.scenario_run import maneuver_run


def _record(path: Path, pause: object = None) -> RerunSink:
    tr, dets, truth = maneuver_run(seed=3)
    sink = RerunSink(path, layout=tr.layout, position_indices=tr.position_indices,
                     velocity_indices=tr.velocity_indices, flush_interval_s=1e9, view_interval_s=0.0, flush_rows=400,
                     pause=pause)  # type: ignore[arg-type]
    for t, x in sorted(truth.items()):
        sink.log_truths([("target", t, x)])
    for d in dets:
        sink.log_step(tr.process([d]))
    return sink


def test_every_entity_sent_follows_a_pause_and_the_file_is_the_same(tmp_path: Path) -> None:
    trace: list[tuple[str, str]] = []
    sink = _record(tmp_path / "paused.rrd", pause=lambda: trace.append(("pause", "")))
    send = sink.rec.send_columns

    def noted(entity: str, **kw: object) -> None:
        trace.append(("send", entity))
        send(entity, **kw)  # type: ignore[arg-type]

    sink.rec.send_columns = noted  # type: ignore[method-assign]
    for _ in range(3):
        sink.flush()
    sink.close()
    sends = [k for k, (what, _) in enumerate(trace) if what == "send"]
    assert len(sends) > 20, "the flushes sent too little to test"
    assert all(trace[k - 1][0] == "pause" for k in sends), "an entity was sent with no pause before it"
    assert sum(w == "pause" for w, _ in trace) > len(sends), "no pause between the other parts of a flush"
    _record(tmp_path / "plain.rrd").close()
    assert digest(tmp_path / "paused.rrd") == digest(tmp_path / "plain.rrd")
