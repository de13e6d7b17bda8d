"""Tracker checkpoints on disk: written atomically, read back or refused with the reason.

Writing: encode (msgpack) -> a temporary file in the same folder -> fsync -> rename over the
checkpoint -> fsync the folder. A crash at any point leaves the old checkpoint or the new one,
never a torn file; a crash before the rename leaves the temporary file, which
`remove_stale_temps` deletes (the service does at its next start). The file is the bytes
MAGIC, then a msgpack CheckpointFile.

Reading: a missing file is "no checkpoint"; a file that is not a checkpoint, is cut short, or
was written by another configuration raises CheckpointError with the reason (the service then
moves it aside and starts clean; it never crashes on one).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import msgspec

from fusion.config import TrackerConfig
from fusion.errors import ConfigError, FusionError
from fusion.tracking.checkpoint import TrackerState, restore
from fusion.tracking.tracker import Tracker

MAGIC = b"FUSIONCK1\n"


class CheckpointError(FusionError):
    """A checkpoint file that cannot be used, with the reason."""


class CheckpointFile(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    written_wall_ns: int
    state: TrackerState
    namespace: str = ""  # the service's, when a service wrote it ("": unknown, or not a service's)


_enc = msgspec.msgpack.Encoder()
_dec = msgspec.msgpack.Decoder(CheckpointFile)


def write_checkpoint(path: str | Path, tracker: Tracker, *, namespace: str = "", now_wall_ns: int | None = None) -> int:
    """Write the tracker's state (and the namespace of the service it tracks for) to `path`
    atomically; the number of bytes written."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    data = MAGIC + _enc.encode(CheckpointFile(written_wall_ns=now_wall_ns or time.time_ns(), state=tracker.state(),
                                              namespace=namespace))
    tmp = _temp_path(p, os.getpid())
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, p)
    fd = os.open(p.parent, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    return len(data)


def _temp_path(p: Path, pid: int | str) -> Path:
    return p.with_name(f".{p.name}.{pid}.tmp")


def remove_stale_temps(path: str | Path) -> list[Path]:
    """Delete the temporary files of writes to `path` that never reached their rename (the
    writer was killed mid-write); the checkpoint itself is untouched. The paths removed."""
    p = Path(path)
    gone = []
    for t in sorted(p.parent.glob(_temp_path(p, "*").name)):
        try:
            t.unlink()
        except FileNotFoundError:
            continue
        gone.append(t)
    return gone


@dataclass(frozen=True)
class Resumed:
    tracker: Tracker
    age_s: float  # wall time since the checkpoint was written
    tracks: int


def read_checkpoint(path: str | Path, config: TrackerConfig, *, namespace: str = "", now_wall_ns: int | None = None,
                    into: Tracker | None = None) -> Resumed | None:
    """The tracker a checkpoint holds; None when there is none; CheckpointError when unusable:
    also when it was written by a service on another `namespace` (its tracks are of other
    targets: resumed, they showed as confirmed tracks of this one). A checkpoint without a
    namespace (before it was written, or not a service's) is taken by any.
    `into`: a freshly built tracker of `config` to restore in place (others may hold it), once the
    checkpoint has restored cleanly into a scratch one; it is left untouched when it cannot."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as e:
        raise CheckpointError(f"{p}: cannot read it: {e.strerror or e}") from None
    if not data.startswith(MAGIC):
        raise CheckpointError(f"{p}: not a fusion checkpoint (it does not start with {MAGIC!r})")
    try:
        cf = _dec.decode(data[len(MAGIC):])
    except msgspec.DecodeError as e:
        raise CheckpointError(f"{p}: damaged or of another version: {e}") from None
    if namespace and cf.namespace and cf.namespace != namespace:
        raise CheckpointError(f"{p}: written by the service on namespace {cf.namespace!r}, not {namespace!r} "
                              "(a service per namespace needs a [checkpoint] path or [recording] directory of its own)")
    try:
        tracker = Tracker.resume(config, cf.state)
    except (ConfigError, ValueError) as e:
        raise CheckpointError(f"{p}: {e}") from None
    if into is not None:
        restore(into, cf.state)
        tracker = into
    age = ((now_wall_ns or time.time_ns()) - cf.written_wall_ns) / 1e9
    return Resumed(tracker, age, len(tracker.track_set))
