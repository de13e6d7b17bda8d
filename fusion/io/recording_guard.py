"""A recording that fails must not stop tracking: the Rerun sink behind a guard.

`GuardedSink(sink)` passes every call on to the sink (fusion.io.recording.RotatingSink or
fusion.io.rerun_sink.RerunSink). The first call that fails with OSError or rerun's RuntimeError
("No space left on device", "Failed to create file", a folder gone) ends the recording: the
error is logged once, kept in `error`, every later call is a no-op, and the service goes on
tracking and publishing; its status says the recording failed and why (fusion.service).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
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

    def _failed(self, e: BaseException) -> None:
        self.error = f"recording {self.sink.path} failed: {type(e).__name__}: {e}"
        log.error("%s; tracking and publishing go on without it", self.error)

    # each call written out, not dispatched by name: log_step comes once per batch, log_text per
    # refusal, and the dispatch (a getattr, an argument tuple) made a call 0.24 us instead of 0.09
    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        if self.error is None:
            try:
                self.sink.log_step(result, arrival_ns=arrival_ns)
            except RECORDING_ERRORS as e:
                self._failed(e)

    def log_truths(self, truths: Sequence[tuple[str, int, Any]]) -> None:
        if self.error is None:
            try:
                self.sink.log_truths(truths)
            except RECORDING_ERRORS as e:
                self._failed(e)

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        if self.error is None:
            try:
                self.sink.log_text(t_ns, text, level)
            except RECORDING_ERRORS as e:
                self._failed(e)

    def maybe_flush(self) -> None:
        if self.error is None:
            try:
                self.sink.maybe_flush()
            except RECORDING_ERRORS as e:
                self._failed(e)

    def close(self) -> None:
        if self.error is None:
            try:
                self.sink.close()
            except RECORDING_ERRORS as e:
                self._failed(e)
