"""Chunks of a recording read with rerun's own reader, also from a damaged file: a file without
its footer (a crashed or killed writer) is read by a whole-file scan; a file cut inside a frame
is read up to the last complete frame, and the number of bytes dropped is returned."""

from __future__ import annotations

import re
import tempfile
import warnings
from pathlib import Path

FOOTER = b"RRF2FOOT"


def read_chunks(path: Path) -> tuple[list[object], int]:
    """All chunks of the file's recording, and the number of bytes dropped to read it."""
    from rerun.chunk import RrdReader

    def read(p: Path) -> list[object]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer/manifest": the summary reports that itself
            return list(RrdReader(str(p)).stream())

    try:
        return read(path), 0
    except RuntimeError as e:
        m = re.search(r"start (\d+)", str(e))
        if m is None:
            raise
        start = int(m.group(1))
    data = path.read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        cut = Path(tmp) / "prefix.rrd"
        for back in range(0, 65):  # the frame header sits just before the payload start
            cut.write_bytes(data[: start - back])
            try:
                return read(cut), len(data) - (start - back)
            except RuntimeError:
                continue
    raise RuntimeError(f"{path}: no readable prefix before byte {start}")
