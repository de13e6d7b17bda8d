"""The service's checkpoints: resume on start, write on an interval and at shutdown.

`resume(config)` reads the checkpoint (fusion.io.checkpoint): the tracker it holds, with how old
it is; none there: a clean start. A checkpoint that cannot be used (not a checkpoint, cut
short, another configuration, written by the service of another namespace) is moved aside to
`<name>.bad-<wall ns>` with a warning that says why, and the service starts clean: it never
crashes on one, and the bad file stays for a look.
`maybe_write(tracker)` writes when `interval_s` has passed since the last write, `write` at
once (at shutdown). A write that fails (disk full, folder unwritable) is logged once per
distinct error and reported in `status()`; tracking goes on.

`counts_since(now, base)`: a resumed tracker carries the counts of the run that wrote the
checkpoint; the service reports this run's (now - base) so that its counts still add up.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from fusion.config import CheckpointConfig, RecordingConfig
from fusion.io.checkpoint import CheckpointError, read_checkpoint, remove_stale_temps, write_checkpoint
from fusion.tracking.results import Counts
from fusion.tracking.tracker import Tracker

log = logging.getLogger("fusion.checkpoint")


class Checkpointer:
    """Checkpoints of one service at `path` (see the module docstring)."""

    def __init__(self, path: str | Path, *, interval_s: float, namespace: str = "",
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.path = Path(path)
        self.namespace = namespace  # written into each checkpoint; one of another namespace is refused
        self.interval_s = interval_s
        self._clock = clock
        self._last: float | None = None
        self._last_wall_ns: int | None = None
        self.written = 0
        self.error: str | None = None
        self.resumed_tracks = 0
        self.resumed_age_s: float | None = None
        self.refused: str | None = None  # why the checkpoint found at start was not used

    def resume(self, tracker: Tracker) -> bool:
        """Restore the checkpoint into `tracker` (freshly built, in place); False when there is
        none or a bad one was moved aside (`tracker` then untouched). Temporary files of a write
        cut short by a kill are deleted first (the checkpoint is the old one then)."""
        try:
            for t in remove_stale_temps(self.path):
                log.info("removed %s, left by a checkpoint write that was cut short", t)
        except OSError as e:
            log.warning("cannot remove the temporary files of %s: %s", self.path, e.strerror or e)
        try:
            r = read_checkpoint(self.path, tracker.config, namespace=self.namespace, into=tracker)
        except CheckpointError as e:
            aside = self.path.with_name(f"{self.path.name}.bad-{time.time_ns()}")
            try:
                os.replace(self.path, aside)
                where = f"moved aside to {aside}"
            except OSError as oe:
                where = f"and it could not be moved aside ({oe.strerror or oe}); it will be overwritten"
            self.refused = str(e)
            log.warning("checkpoint refused: %s; %s; starting with no tracks", e, where)
            return False
        self._last = self._clock()
        if r is None:
            log.info("no checkpoint at %s: starting with no tracks", self.path)
            return False
        self.resumed_tracks, self.resumed_age_s = r.tracks, r.age_s
        log.info("resumed %d tracks from %s, written %.1f s ago", r.tracks, self.path, r.age_s)
        return True

    def maybe_write(self, tracker: Tracker) -> None:
        now = self._clock()
        if self._last is None:
            self._last = now
        elif now - self._last >= self.interval_s:
            self.write(tracker)

    def write(self, tracker: Tracker) -> None:
        self._last = self._clock()
        try:
            write_checkpoint(self.path, tracker, namespace=self.namespace)
        except OSError as e:
            msg = f"cannot write the checkpoint {self.path}: {e.strerror or e}"
            if msg != self.error:
                log.warning("%s (tracking goes on; the last good checkpoint stays)", msg)
            self.error = msg
            return
        self.written += 1
        self.error = None
        self._last_wall_ns = time.time_ns()

    def status(self) -> dict[str, Any]:
        age = None if self._last_wall_ns is None else (time.time_ns() - self._last_wall_ns) / 1e9
        return {"path": str(self.path), "resumed_tracks": self.resumed_tracks, "resumed_age_s": self.resumed_age_s,
                "refused": self.refused, "written": self.written, "last_written_age_s": age, "error": self.error}


def _minus(a: Any, b: Any) -> Any:
    if isinstance(a, Mapping):
        return {k: v - b.get(k, 0) for k, v in a.items() if v - b.get(k, 0)}
    return a - b


def counts_since(now: Counts, base: Counts) -> Counts:
    """Counts of what happened after `base` was taken (every field is cumulative)."""
    return dataclasses.replace(now, **{f.name: _minus(getattr(now, f.name), getattr(base, f.name))
                                       for f in dataclasses.fields(Counts)})


def service_checkpoint_path(cc: CheckpointConfig, rc: RecordingConfig, *, recording_dir: str | Path | None,
                            one_file: bool) -> Path | None:
    """Where a service keeps its checkpoint (see CheckpointConfig), None for none."""
    if not cc.enabled:
        return None
    if cc.path:
        return Path(cc.path)
    if one_file:
        return None
    return Path(recording_dir if recording_dir is not None else rc.directory) / f"{rc.prefix}.checkpoint"
