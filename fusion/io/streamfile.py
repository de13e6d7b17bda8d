"""Recorded input streams (`.fstream`): every sample with its arrival time, for `fusion replay`.

Format (little-endian):
    header   b"FUSIONST" | u16 format version (1) | u32 n | n bytes of JSON metadata
    frame*   u32 n | u32 crc32(body) | body: msgpack [arrival_ns: int, key: str, payload: bytes]
Frames are appended unbuffered, one write per batch of records (`write_many`, the service's
per-batch call) or per record (`write`), so a crash costs at most the frames of the write under
way; the reader detects a cut or corrupt last frame, skips it, and reports it (one line
through logging, "fusion.stream", and `StreamReader.truncated`). A corrupt header raises StreamFormatError.

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
VERSION = 1
_HDR = struct.Struct("<8sHI")
_FRAME = struct.Struct("<II")
_enc = msgspec.msgpack.Encoder()
_dec = msgspec.msgpack.Decoder(tuple[int, str, bytes])

Record = tuple[int, str, bytes]
log = logging.getLogger("fusion.stream")


def frame(arrival_ns: int, key: str, payload: bytes) -> bytes:
    """One frame: u32 len(body) | u32 crc32(body) | body (msgpack [arrival_ns, key, payload])."""
    body = _enc.encode((int(arrival_ns), key, bytes(payload)))
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
        self.frames = 0

    def write(self, arrival_ns: int, key: str, payload: bytes) -> None:
        self._f.write(frame(arrival_ns, key, payload))
        self.frames += 1

    def write_many(self, records: Sequence[Record]) -> int:
        """Append records with one write; the bytes written."""
        enc, head, crc = _enc.encode, _FRAME.pack, zlib.crc32
        parts: list[bytes] = []
        add = parts.append
        for a, k, p in records:  # frame(a, k, p) of each, inline
            body = enc((int(a), k, bytes(p)))
            add(head(len(body), crc(body)))
            add(body)
        blob = b"".join(parts)
        self._f.write(blob)
        self.frames += len(records)
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
        if version != VERSION:
            raise StreamFormatError(f"{self.path}: stream format version {version}, this reader knows {VERSION}")
        try:
            self.meta: dict[str, Any] = json.loads(self._data[_HDR.size:_HDR.size + n])
        except ValueError as e:
            raise StreamFormatError(f"{self.path}: corrupt header metadata: {e}") from None
        self._start = _HDR.size + n

    def __iter__(self) -> Iterator[Record]:
        data, pos, end = self._data, self._start, len(self._data)
        while pos < end:
            if pos + _FRAME.size > end:
                break
            n, crc = _FRAME.unpack_from(data, pos)
            body = data[pos + _FRAME.size:pos + _FRAME.size + n]
            if len(body) < n or zlib.crc32(body) != crc:
                break
            yield _dec.decode(body)
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
            elif isinstance(msg, m.Truth):
                yield msg.t_ns, m.truth_key(namespace, msg.target_id), m.encode(msg)
            else:
                raise InputError(f"{path}:{i}: a stream holds measurements and truth, not {type(msg).__name__}")


def read_records(path: str | Path, *, namespace: str = "demo") -> tuple[Iterator[Record], dict[str, Any]]:
    """(records, metadata) of a .fstream or a .jsonl file."""
    p = Path(path)
    if p.suffix == ".jsonl":
        return read_jsonl(p, namespace=namespace), {"namespace": namespace}
    r = StreamReader(p)
    return iter(r), r.meta
