"""One Rerun .rrd file being written: its stream, the entities' columns sent to it, their series
styles, the layout (blueprint) and the kind of its time axes.

fusion.io.rerun_sink decides what goes out and when; this module only writes. `send` makes one
`send_columns` call per entity (in name order), after the entity's series style (static, once per
entity); the time axes are `t` (sensor time), `step` (the sink's step counter) and `arrival`,
each a duration from the stream's start or a timestamp, decided from the first rows written
(fusion.io.labels.is_epoch) and kept for the file (Rerun keeps one type per timeline). A closed
file leaves nothing in rerun-sdk's memory (send_blueprint, release_closed_streams).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from fusion.io import blueprint
from fusion.io.arrow_columns import components, time_index
from fusion.io.columns import Column
from fusion.io.labels import is_epoch


class RerunFile:
    """A recording stream saving to `path`, with `meta` logged first (static JSON)."""

    def __init__(self, path: Path, *, recording_id: str, application_id: str, meta: Mapping[str, Any]) -> None:
        import rerun as rr

        self._rr = rr
        self.path = path
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec: Any = rr.RecordingStream(application_id, recording_id=recording_id)
        self.rec.save(str(self.path))
        self.rec.log("meta", rr.TextDocument(json.dumps(dict(meta), sort_keys=True), media_type="text/plain"),
                     static=True)
        self.rows_written = 0
        self.epoch: bool | None = None  # t is an epoch time (decided from the first rows)
        self.arrival_epoch: bool | None = None
        self.written: set[str] = set()  # the entity paths written ("/record/estimates", ...)
        self._styled: set[str] = set()
        self._layout_key: tuple = ()

    def send(self, cols: Mapping[str, Column], pause: Callable[[], None]) -> bool:
        """One send_columns call per entity with rows (in name order), each after `pause` and its
        style; whether an entity was written for the first time."""
        if cols and self.epoch is None:
            firsts = [c.first_times() for c in cols.values() if len(c)]
            self.epoch = bool(firsts) and is_epoch(min(f[0] for f in firsts))
            self.arrival_epoch = bool(firsts) and is_epoch(min(f[1] for f in firsts))
        n_written = len(self.written)
        for entity in sorted(cols):
            c = cols[entity]
            if not len(c):
                continue
            pause()
            self._style(entity, c)
            t_ns, step, arrival_ns = c.times()
            idx = [time_index("t", t_ns, epoch=bool(self.epoch)), time_index("step", step, epoch=None),
                   time_index("arrival", arrival_ns, epoch=bool(self.arrival_epoch))]
            self.rec.send_columns(entity, indexes=idx, columns=components(c), strict=True)
            self.rows_written += len(c)
            self.written.add("/" + entity)
        return len(self.written) != n_written

    def _style(self, entity: str, c: Column) -> None:
        """Series names and colours, once per entity (static)."""
        if entity in self._styled or "names" not in c.style:
            return
        self._styled.add(entity)
        rr = self._rr
        kw = {"names": list(c.style["names"]), "colors": [list(x) for x in c.style["colors"]]}
        if c.style.get("points"):
            size = float(c.style.get("marker_size", 1.5))
            self.rec.log(entity, rr.SeriesPoints(marker_sizes=[size] * len(kw["names"]), **kw), static=True)
        else:
            self.rec.log(entity, rr.SeriesLines(widths=list(c.style.get("widths", [2.0] * len(kw["names"]))), **kw),
                         static=True)

    def send_layout(self, *, ndim: int, axes: Any, viewed: list[str], centre: list[float], extent_m: float) -> None:
        """(Re)send the layout (fusion.io.blueprint) when the viewed tracks or the views holding
        data changed since it was last sent (a few times per file)."""
        key = blueprint.layout_key(viewed=viewed, axes=axes, written=self.written)
        if key == self._layout_key:
            return
        self._layout_key = key
        send_blueprint(self.rec, blueprint.build(ndim=ndim, axes=axes, viewed=viewed, written=self.written,
                                                 centre=centre, extent_m=extent_m))

    def close(self) -> None:
        """Finish the file (complete footer) and let Rerun free its stream (release_closed_streams)."""
        if self.rec is None:
            return
        self.rec.flush()
        self.rec.disconnect()
        self.rec = None  # the last reference: its __del__ hands the stream to rerun's orphans
        release_closed_streams()


def send_blueprint(rec: Any, layout: Any) -> None:
    """`rec.send_blueprint(layout)` (made active and default), without the stream it leaves behind.
    rerun-sdk (0.41) logs a blueprint into a stream of its own with an in-memory sink whose storage
    holds that stream: the two hold each other, and each blueprint sent stayed in memory for the
    life of the process (~0.4 MB each, measured 2026-12-07; a rotating recording sends a few per
    file). The same steps as rerun.sinks.send_blueprint, then the blueprint's stream disconnected,
    which drops its sink and so the storage's hold on it; release_closed_streams frees it."""
    import rerun_bindings
    from rerun.recording_stream import RecordingStream

    stream = RecordingStream._from_native(rerun_bindings.new_blueprint(
        application_id=rec.get_application_id(), make_default=False, make_thread_default=False, default_enabled=True))
    stream.set_time("blueprint", sequence=0)
    layout.to_blueprint()._log_to_stream(stream)
    storage = stream.memory_recording().storage
    rerun_bindings.send_blueprint(storage, True, True, recording=rec.to_native())
    stream.disconnect()


def release_closed_streams() -> None:
    """Free the native streams of the closed files. rerun-sdk (0.41) keeps every RecordingStream
    it made in a process-wide list (rerun_bindings' all_recordings, then its orphans once the
    Python object is gone) until `flush_and_cleanup_orphaned_recordings`, which it calls only in
    `rr.init`: each file a rotating recording closed held ~0.7 MB there (its entities' state; a
    file of 160 entities, measured 2026-12-07), each blueprint it sent ~0.4 MB (send_blueprint).
    That call flushes every stream (blocking) and clears the global data recording, which is set
    again after it (a caller's `rr.init` recording is held by the reference taken here, so it
    is not dropped)."""
    import rerun as rr
    import rerun_bindings

    current = rr.get_global_data_recording()
    rerun_bindings.flush_and_cleanup_orphaned_recordings()
    if current is not None:
        rr.set_global_data_recording(current)
