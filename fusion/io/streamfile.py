"""Recorded input streams (`.fstream`): every sample with its arrival time, for `fusion replay`.

Format (little-endian):
    header   b"FUSIONST" | u16 format version (2) | u32 n | n bytes of JSON metadata
    frame*   u32 n | u32 crc32(body) | body: msgpack [[arrival_ns: int, key: str, payload: bytes], ...]
A frame holds the records of one write: a batch (`write_many`, the service's per-batch call) or
one record (`write`). Frames are appended unbuffered, one write each, so a crash costs at most
the records of the write under way; the reader detects a cut or corrupt last frame, skips it, and
reports it (one line through logging, "fusion.stream", and `StreamReader.truncated`). A corrupt
header raises StreamFormatError. Version 1 files (a frame per record, its body one
[arrival_ns, key, payload]) are read as before. Version 2 writes a batch as one msgpack array
and one checksum: 0.17 us a record written against 0.63 for a frame each (5 000 records of 147
bytes), which was 4 % of the service's loop in a blast at 100 targets (bench/HISTORY.md).

`read_records(path)` also accepts `.jsonl`: one JSON message per line (fusion.messages, as
written by `encode_json`); the arrival time of a line is its t_ns.
"""

from __future__ import annotations

import json
import logging
import struct
import time
import zlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import msgspec

from fusion import messages as m
from fusion.errors import InputError

MAGIC = b"FUSIONST"
VERSION = 2
_HDR = struct.Struct("<8sHI")
_FRAME = struct.Struct("<II")
_enc = msgspec.msgpack.Encoder()
_DECODERS = {1: msgspec.msgpack.Decoder(tuple[int, str, bytes]).decode,  # a frame per record
             2: msgspec.msgpack.Decoder(list[tuple[int, str, bytes]]).decode}  # a frame per write

Record = tuple[int, str, bytes]
log = logging.getLogger("fusion.stream")


def frame(records: Sequence[Record]) -> bytes:
    """One frame: u32 len(body) | u32 crc32(body) | body (msgpack [[arrival_ns, key, payload], ...])."""
    try:
        body = _enc.encode(records)  # the service's records: (int, str, bytes) as they are
    except TypeError:  # numpy integers, or the like: made plain first
        body = _enc.encode([(int(a), k, bytes(p)) for a, k, p in records])
    return _FRAME.pack(len(body), zlib.crc32(body)) + body


class StreamFormatError(InputError):
    """Not a fusion stream file, or an unsupported version."""


class StreamWriter:
    """Appends records to a new stream file."""

    def __init__(self, path: str | Path, *, namespace: str, meta: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        info = {"namespace": namespace, "created_ns": time.time_ns(), **(meta or {})}
        blob = json.dumps(info, sort_keys=True).encode()
        self._f = self.path.open("wb", buffering=0)
        self._f.write(_HDR.pack(MAGIC, VERSION, len(blob)) + blob)
        self.records = 0

    def write(self, arrival_ns: int, key: str, payload: bytes) -> None:
        """Append one record (a frame of its own)."""
        self._f.write(frame([(arrival_ns, key, payload)]))
        self.records += 1

    def write_many(self, records: Sequence[Record]) -> int:
        """Append records as one frame, with one write; the bytes written (0 for none)."""
        if not records:
            return 0
        blob = frame(records)
        self._f.write(blob)
        self.records += len(records)
        return len(blob)

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()

    def __enter__(self) -> StreamWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class StreamReader:
    """Reads a stream file: `meta`, then the records in file order."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.truncated = False
        self.trailing_bytes = 0
        self._data = self.path.read_bytes()
        if len(self._data) < _HDR.size:
            raise StreamFormatError(f"{self.path}: too short for a fusion stream header")
        magic, version, n = _HDR.unpack_from(self._data, 0)
        if magic != MAGIC:
            raise StreamFormatError(f"{self.path}: not a fusion stream (magic {magic!r})")
        if version not in _DECODERS:
            raise StreamFormatError(f"{self.path}: stream format version {version}, this reader knows "
                                    f"{', '.join(map(str, sorted(_DECODERS)))}")
        self.version: int = version
        try:
            self.meta: dict[str, Any] = json.loads(self._data[_HDR.size:_HDR.size + n])
        except ValueError as e:
            raise StreamFormatError(f"{self.path}: corrupt header metadata: {e}") from None
        self._start = _HDR.size + n

    def __iter__(self) -> Iterator[Record]:
        data, pos, end = self._data, self._start, len(self._data)
        decode, one = _DECODERS[self.version], self.version == 1
        while pos < end:
            if pos + _FRAME.size > end:
                break
            n, crc = _FRAME.unpack_from(data, pos)
            body = data[pos + _FRAME.size:pos + _FRAME.size + n]
            if len(body) < n or zlib.crc32(body) != crc:
                break
            if one:
                yield decode(body)
            else:
                yield from decode(body)
            pos += _FRAME.size + n
        if pos < end:
            self.truncated = True
            self.trailing_bytes = end - pos
            log.warning("%s: skipped a partial or corrupt last frame (%d bytes at offset %d): the recording was cut "
                        "short, the records before it are complete", self.path, end - pos, pos)


def read_jsonl(path: str | Path, *, namespace: str) -> Iterator[Record]:
    """Records from a .jsonl file of messages; a bad line raises InputError naming the line."""
    with Path(path).open("rb") as f:
        for i, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                msg = m.decode_json(line)
            except m.MessageError as e:
                raise InputError(f"{path}:{i}: {e}") from None
            if isinstance(msg, m.Measurement):
                yield msg.t_ns, m.meas_key(namespace, msg.sensor_id), m.encode(msg)
            elif isinstance(msg, m.Input):
                yield msg.t_ns, m.input_key(namespace, msg.source_id), m.encode(msg)
            elif isinstance(msg, m.Truth):
                yield msg.t_ns, m.truth_key(namespace, msg.target_id), m.encode(msg)
            else:
                raise InputError(f"{path}:{i}: a stream holds measurements, control inputs and truth, "
                                 f"not {type(msg).__name__}")


def read_records(path: str | Path, *, namespace: str = "demo") -> tuple[Iterator[Record], dict[str, Any]]:
    """(records, metadata) of a .fstream or a .jsonl file."""
    p = Path(path)
    if p.suffix == ".jsonl":
        return read_jsonl(p, namespace=namespace), {"namespace": namespace}
    r = StreamReader(p)
    return iter(r), r.meta
