"""Progress bars for long commands: on a terminal only, quiet in a pipe or with -q.

tqdm draws them (rate, elapsed time and ETA, redrawn at most ~10 times a second); while a bar
is up, log lines go through tqdm.write (logging_redirect_tqdm) so a warning never shares a line
with the bar.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


def wanted(args: argparse.Namespace) -> bool:
    """Bars only on a terminal, and not with -q."""
    return sys.stderr.isatty() and not getattr(args, "quiet", False)


class Bar:
    """`bar(done, total)` moves the bar to `done` of `total` (total may change). The bar appears
    at the first call, so that its clock starts with the work; a disabled Bar does nothing."""

    def __init__(self, *, enabled: bool, desc: str, unit: str) -> None:
        self._enabled, self._desc, self._unit = enabled, desc, unit
        self._tq: Any = None

    def __call__(self, done: int, total: int | None = None) -> None:
        if not self._enabled:
            return
        if self._tq is None:
            from tqdm import tqdm

            self._tq = tqdm(total=total, desc=self._desc, unit=self._unit, file=sys.stderr, dynamic_ncols=True,
                            mininterval=0.1, leave=False)
        elif total is not None and total != self._tq.total:
            self._tq.total = total
            self._tq.refresh()
        self._tq.update(done - self._tq.n)
        if self._tq.total is not None and done >= self._tq.total:
            self._tq.refresh()  # the final count and rate, whatever the redraw interval

    def close(self) -> None:
        if self._tq is not None:
            self._tq.close()
        self._tq, self._enabled = None, False


@contextmanager
def bar(*, enabled: bool, desc: str, unit: str) -> Iterator[Bar]:
    """A progress bar on stderr while the block runs; log lines are written above it."""
    b = Bar(enabled=enabled, desc=desc, unit=unit)
    if not enabled:
        yield b
        return
    from tqdm.contrib.logging import logging_redirect_tqdm

    with logging_redirect_tqdm():
        try:
            yield b
        finally:
            b.close()


def status(args: argparse.Namespace, text: str) -> None:
    """A line about what is happening, on a terminal only (like the bars)."""
    if wanted(args):
        print(text, file=sys.stderr, flush=True)
