"""One Rerun .rrd file being written: its stream, the entities' columns sent to it, their series
styles, the layout (blueprint) and the kind of its time axes.

fusion.io.rerun_sink decides what goes out and when; this module only writes. `send` makes one
`send_columns` call per entity (in name order), after the entity's series style (static, once per
entity); the time axes are `t` (sensor time), `step` (the sink's step counter) and `arrival`,
each a duration from the stream's start or a timestamp, decided from the first rows written
(fusion.io.labels.is_epoch) and kept for the file (Rerun keeps one type per timeline).
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
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id)
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
        self.rec.send_blueprint(blueprint.build(ndim=ndim, axes=axes, viewed=viewed, written=self.written,
                                                centre=centre, extent_m=extent_m))

    def close(self) -> None:
        """Finish the file (complete footer)."""
        self.rec.flush()
        self.rec.disconnect()
