"""The raw input stream (`.fstream`) of a long-running service: rotated, size-limited, and
never a reason to stop tracking; and retention of old recordings.

`RotatingStream` writes records to `<stem>.fstream` beside the current Rerun file: when the
recording moves to a new file (`follow()` returns another path), the stream moves with it to
the new stem at its next write or `follow()` (the service calls it between batches and after
the recording's last flush), so each `.rrd` has its `.fstream`. A stream that reaches `rotate_bytes` on its own
(large payloads) goes on in `<stem>-1.fstream`, `<stem>-2.fstream`, ... Every file is a
complete stream file (fusion.io.streamfile), readable on its own. An OSError (disk full, folder
gone) ends the stream: logged once, kept in `error`; later records are counted in `lost` and
not written, and tracking goes on. The next rotation tries again.

`Retention(directory, prefix, keep_files, keep_bytes)`: `sweep(open_paths)` deletes the oldest
`<prefix>-*.rrd` and `<prefix>-*.fstream` files (names sort by time) while more than
`keep_files` recordings (.rrd) are kept or all of them take more than `keep_bytes` (0: no
limit); files still open are never deleted. The service sweeps whenever a file is rotated.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Sequence
from pathlib import Path

from fusion.io.streamfile import Record, StreamWriter

log = logging.getLogger("fusion.recording")
STREAM_SUFFIX = ".fstream"


class RotatingStream:
    """See the module docstring."""

    def __init__(self, path: str | Path, *, namespace: str, rotate_bytes: int,
                 follow: Callable[[], Path] | None = None) -> None:
        self.namespace = namespace
        self.rotate_bytes = rotate_bytes
        self._follow = follow
        self._base = Path(path)
        self._part = 0
        self._followed = follow() if follow is not None else None
        self.files: list[Path] = []
        self.error: str | None = None
        self.lost = 0
        self.records = 0  # written
        self._w: StreamWriter | None = None
        self._bytes = 0
        self._open()

    @property
    def path(self) -> Path:
        return self.files[-1] if self.files else self._base

    def _open(self) -> None:
        p = self._base if self._part == 0 else self._base.with_name(f"{self._base.stem}-{self._part}{STREAM_SUFFIX}")
        try:
            self._w = StreamWriter(p, namespace=self.namespace)
        except OSError as e:
            self._fail(p, e)
            return
        self.files.append(p)
        self._bytes = 0
        self.error = None

    def _fail(self, p: Path, e: OSError) -> None:
        msg = f"stream file {p} failed: {e.strerror or e}"
        if msg != self.error:
            log.error("%s; tracking and publishing go on, the input is not recorded", msg)
        self.error = msg
        if self._w is not None:
            with contextlib.suppress(OSError):  # the file is lost already, its error is the one reported
                self._w.close()
            self._w = None

    def _rotate(self) -> None:
        if self._w is not None:
            try:
                self._w.close()
            except OSError as e:
                self._fail(self.path, e)
        self._open()

    def follow(self) -> None:
        """Move to the recording's new file if it moved, also while no record comes: the
        recording moves at a batch's steps, after the stream took the batch, so without this the
        file a run's last batch moved it to had no stream file."""
        if self._follow is not None and (now := self._follow()) != self._followed:
            self._followed, self._base, self._part = now, now.with_suffix(STREAM_SUFFIX), 0
            self._rotate()

    def write(self, arrival_ns: int, key: str, payload: bytes) -> None:
        self.write_many([(arrival_ns, key, payload)])

    def write_many(self, records: Sequence[Record]) -> None:
        """Append a batch of records, one write per file it goes to: a part holds records up
        to the first that takes it to rotate_bytes (counted as payload + key + 16 per record),
        the rest go on in the next part. Records that cannot be written are counted in `lost`."""
        self.follow()
        i, n = 0, len(records)
        while i < n:
            if self._w is not None and self._bytes >= self.rotate_bytes:
                self._part += 1
                self._rotate()
            if self._w is None:
                self.lost += n - i
                return
            j, size = i, self._bytes
            if i == 0:  # the common case at once: no record before the last fills the part
                costs = [len(r[2]) + len(r[1]) + 16 for r in records]
                total = sum(costs)
                if size + total - costs[-1] < self.rotate_bytes:
                    j, size = n, size + total
            while j < n and size < self.rotate_bytes:
                size += len(records[j][2]) + len(records[j][1]) + 16
                j += 1
            try:
                self._w.write_many(records[i:j])
            except OSError as e:
                self._fail(self.path, e)
                self.lost += n - i
                return
            self._bytes = size
            self.records += j - i
            i = j

    def close(self) -> None:
        if self._w is not None:
            try:
                self._w.close()
            except OSError as e:
                self._fail(self.path, e)
            self._w = None


class Retention:
    """See the module docstring."""

    def __init__(self, directory: str | Path, *, prefix: str, keep_files: int, keep_bytes: int) -> None:
        self.directory = Path(directory)
        self.prefix = prefix
        self.keep_files = keep_files
        self.keep_bytes = keep_bytes
        self.deleted: list[Path] = []
        self._seen: tuple[Path, ...] = ()

    def maybe_sweep(self, open_paths: tuple[Path, ...]) -> None:
        """Sweep when the open files changed since the last call (a rotation)."""
        if open_paths != self._seen:
            self._seen = open_paths
            self.sweep(open_paths)

    def sweep(self, open_paths: tuple[Path, ...] = ()) -> list[Path]:
        if not (self.keep_files or self.keep_bytes):
            return []
        keep = {p.resolve() for p in open_paths}
        files = sorted(p for ext in (".rrd", STREAM_SUFFIX) for p in self.directory.glob(f"{self.prefix}-*{ext}"))
        sizes = {}
        for p in files:
            try:
                sizes[p] = p.stat().st_size
            except OSError:
                continue
        total = sum(sizes.values())
        n_rrd = sum(1 for p in sizes if p.suffix == ".rrd")
        gone = []
        for p in sorted(sizes, key=lambda q: q.name):
            over_count = self.keep_files and n_rrd > self.keep_files
            over_bytes = self.keep_bytes and total > self.keep_bytes
            if not (over_count or over_bytes):
                break
            if p.resolve() in keep:
                continue
            try:
                p.unlink()
            except OSError as e:
                log.warning("retention: cannot delete %s: %s", p, e.strerror or e)
                continue
            total -= sizes[p]
            n_rrd -= p.suffix == ".rrd"
            gone.append(p)
        if gone:
            log.info("retention: deleted %d old recording file%s (%s)", len(gone), "" if len(gone) == 1 else "s",
                     ", ".join(p.name for p in gone))
        self.deleted.extend(gone)
        return gone
