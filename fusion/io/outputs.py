"""The service's files: the recording (behind its guard, on its own thread with [recording]
background), the raw input stream beside it, and the retention of a rotating set.

`open_outputs` builds them from the service's configuration once its Zenoh session is open (so a
service that cannot start leaves no files behind): one file at `recording_path` (no rotation:
`fusion demo`), else a rotating set in `recording_dir` (the config's directory unless given)
when [recording] is enabled; the stream file at `stream_path`, else beside the recording when
[recording] stream is on (following a rotating set's files). `Outputs.recording` is where the
pipeline and the loop send the recording's calls: the recording's thread, or the guard.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from fusion.config import RecordingConfig
from fusion.io import wire
from fusion.io.recording import RotatingSink, service_recording
from fusion.io.recording_guard import GuardedSink
from fusion.io.rerun_sink import RerunSink
from fusion.io.sink_thread import SinkThread
from fusion.io.stream_rotation import Retention, RotatingStream


class Outputs:
    """What `open_outputs` made (each None where not configured)."""

    def __init__(self, sink: RotatingSink | RerunSink | None, stream: RotatingStream | None,
                 writer: SinkThread | None, retention: Retention | None) -> None:
        self.sink = sink
        self.stream = stream
        self.writer = writer  # the recording's thread (fusion.io.sink_thread), started
        self.retention = retention
        self.guard = None if sink is None else GuardedSink(sink)
        if self.guard is None:
            self.writer = None
        elif self.writer is not None:
            self.writer.start(self.guard)

    @property
    def recording(self) -> SinkThread | GuardedSink | None:
        """Where the pipeline and the loop send the recording's calls: its thread, or the guard."""
        return self.writer if self.writer is not None else self.guard

    def files(self) -> tuple[Path, ...]:
        """The files being written now (a rotating set's current ones)."""
        return tuple(p.path for p in (self.sink, self.stream) if p is not None)

    def maybe_sweep(self) -> None:
        """The stream beside the recording's current file, and the retention of a rotating set
        when a file rotated."""
        if self.stream is not None:
            self.stream.follow()
        if self.retention is not None:
            self.retention.maybe_sweep(self.files())

    def error(self) -> str | None:
        """Why the recording or the stream stopped writing, if one did."""
        errors = [g.error for g in (self.guard, self.stream) if g is not None and g.error]
        return "; ".join(errors) or None

    def recording_bytes(self) -> int:
        if isinstance(self.sink, RotatingSink):
            return self.sink.size_bytes()
        return self.sink.path.stat().st_size if self.sink is not None and self.sink.path.exists() else 0

    def close(self) -> None:
        """Close the recording (its last flush) and the stream (moved to the recording's last
        file first), then apply the retention."""
        if self.recording is not None:
            self.recording.close()
        if self.stream is not None:
            self.stream.follow()  # the recording may have moved to a new file since the last batch
            self.stream.close()
        if self.retention is not None:
            self.retention.sweep(self.files())


def open_outputs(rc: RecordingConfig, *, namespace: str, recording_dir: str | Path | None,
                 recording_path: str | Path | None, stream_path: str | Path | None, sink_args: Mapping[str, Any],
                 counts: Callable[[], dict[str, int]]) -> Outputs:
    """The files (module docstring). `sink_args`: the recording's layout, indices and meta
    (RerunSink's keywords); `counts`: the service's counts, for the recording's counts rows."""
    rdir = Path(recording_dir) if recording_dir is not None else Path(rc.directory)
    writer = SinkThread(counts=counts) if rc.background else None
    common: dict[str, Any] = dict(sink_args)
    common["counts"] = counts if writer is None else writer.counts
    common["pause"] = None if writer is None else writer.pause
    sink: RotatingSink | RerunSink | None = None
    if recording_path is not None:
        sink = RerunSink(recording_path, recording_id=Path(recording_path).stem, flush_interval_s=rc.flush_interval_s,
                         write_interval_s=rc.write_interval_s, flush_min_rows=rc.flush_min_rows, **common)
    elif rc.enabled:
        sink = service_recording(rc, rdir, **common)
    try:
        rotating = sink if isinstance(sink, RotatingSink) else None
        stream = None
        if stream_path is not None or (sink is not None and rc.stream):
            sp = Path(stream_path) if stream_path is not None else sink.path.with_suffix(wire.STREAM_SUFFIX)  # type: ignore[union-attr]
            follow = None if rotating is None or stream_path is not None else (lambda: rotating.path)
            stream = RotatingStream(sp, namespace=namespace, rotate_bytes=int(rc.rotate_mb * 1e6), follow=follow)
        retention = None if rotating is None else Retention(rdir, prefix=rc.prefix, keep_files=rc.keep_files,
                                                            keep_bytes=int(rc.keep_mb * 1e6))
    except BaseException:
        if sink is not None:
            sink.close()
        raise
    return Outputs(sink, stream, writer, retention)
