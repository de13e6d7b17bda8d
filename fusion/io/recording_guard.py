"""A recording that fails must not stop tracking: the Rerun sink behind a guard.

`GuardedSink(sink)` passes every call on to the sink (fusion.io.recording.RotatingSink or
fusion.io.rerun_sink.RerunSink). The first call that fails with OSError or rerun's RuntimeError
("No space left on device", "Failed to create file", a folder gone) ends the recording: the
error is logged once, kept in `error`, every later call is a no-op, and the service goes on
tracking and publishing; its status says the recording failed and why (fusion.service).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from fusion.tracking.results import StepResult

log = logging.getLogger("fusion.recording")
RECORDING_ERRORS = (OSError, RuntimeError)  # rerun reports write failures as RuntimeError


class GuardedSink:
    """See the module docstring."""

    def __init__(self, sink: Any) -> None:
        self.sink = sink
        self.error: str | None = None

    @property
    def path(self) -> Path:
        return self.sink.path

    def _call(self, name: str, *args: Any, **kw: Any) -> None:
        if self.error is not None:
            return
        try:
            getattr(self.sink, name)(*args, **kw)
        except RECORDING_ERRORS as e:
            self.error = f"recording {self.sink.path} failed: {type(e).__name__}: {e}"
            log.error("%s; tracking and publishing go on without it", self.error)

    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        self._call("log_step", result, arrival_ns=arrival_ns)

    def log_truth(self, target_id: str, t_ns: int, state: Any) -> None:
        self._call("log_truth", target_id, t_ns, state)

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        self._call("log_text", t_ns, text, level)

    def maybe_flush(self) -> None:
        self._call("maybe_flush")

    def close(self) -> None:
        self._call("close")
