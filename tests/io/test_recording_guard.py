"""fusion.io.recording_guard.GuardedSink: every call is passed on until one fails with a recording
error (OSError, rerun's RuntimeError); from then on every call is a no-op and the error is kept.
Any other exception is a bug and propagates."""

from __future__ import annotations

from typing import Any

import pytest

from fusion.io.recording_guard import GuardedSink

CALLS = {"log_step": ((None,), {"arrival_ns": 5}), "log_truths": (([("t0", 1, [0.0])],), {}),
         "log_text": ((1, "hello", "WARN"), {}), "maybe_flush": ((), {}), "close": ((), {})}


class Sink:
    path = "x.rrd"

    def __init__(self, fail: str | None = None, error: type[BaseException] = OSError) -> None:
        self.calls: list[tuple[str, tuple, dict]] = []
        self.fail, self.error = fail, error

    def __getattr__(self, name: str) -> Any:
        if name not in CALLS:
            raise AttributeError(name)

        def call(*args: Any, **kw: Any) -> None:
            self.calls.append((name, args, kw))
            if name == self.fail:
                raise self.error("No space left on device")
        return call


def _all(g: GuardedSink) -> None:
    for name, (args, kw) in CALLS.items():
        getattr(g, name)(*args, **kw)


def test_every_call_is_passed_on_with_its_arguments() -> None:
    s = Sink()
    g = GuardedSink(s)
    _all(g)
    assert [(n, a, k) for n, a, k in s.calls] == [(n, a, k) for n, (a, k) in CALLS.items()]
    assert g.error is None


@pytest.mark.parametrize("name", sorted(CALLS))
@pytest.mark.parametrize("error", [OSError, RuntimeError])
def test_a_recording_error_in_any_call_ends_the_recording_and_nothing_else(name: str,
                                                                           error: type[BaseException]) -> None:
    s = Sink(fail=name, error=error)
    g = GuardedSink(s)
    _all(g)  # the failing call does not raise
    assert g.error == f"recording x.rrd failed: {error.__name__}: No space left on device"
    n = len(s.calls)
    assert [c[0] for c in s.calls] == list(CALLS)[:n] and s.calls[-1][0] == name
    _all(g)  # every later call is a no-op
    assert len(s.calls) == n


@pytest.mark.parametrize("name", sorted(CALLS))
def test_other_errors_are_bugs_and_propagate(name: str) -> None:
    g = GuardedSink(Sink(fail=name, error=ValueError))
    args, kw = CALLS[name]
    with pytest.raises(ValueError):
        getattr(g, name)(*args, **kw)
    assert g.error is None
