"""What a recording holds, as a digest to compare two recordings of the same run: per entity, the
number of rows (static and not) and a hash of its rows, read back with rerun's RrdReader.

A row is the tuple of its columns (the timelines and every component, RowId left out) as Python
values, floats rounded to 10 significant digits (two correct computations of the same figure may
differ in the last bits); the rows of an entity are sorted before hashing, so how they were cut
into chunks (the flush cadence) does not matter. `/__properties` (the recording's start time)
is left out, and so is the meta's random run id.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import pyarrow as pa
from rerun.chunk import RrdReader

from tests.io.scenario_run import record_scenario


def _canon(v: Any) -> Any:
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return float(f"{v:.10g}")
    if isinstance(v, list | tuple):
        return [_canon(x) for x in v]
    if isinstance(v, dict):
        return {k: _canon(x) for k, x in sorted(v.items())}
    return v


def _without_run_id(text: Any) -> Any:
    """The meta JSON without its "run_id" (other values as given)."""
    try:
        info = json.loads(text)
    except (TypeError, ValueError):
        return text
    if isinstance(info, dict):
        info.pop("run_id", None)
        return json.dumps(info, sort_keys=True)
    return text


def _values(col: Any) -> list[Any]:
    """A column's values; times (durations, timestamps) as integer ns."""
    if pa.types.is_temporal(col.type):
        col = col.cast(pa.int64())
    return col.to_pylist()


def digest(path: str | Path) -> dict[str, dict[str, Any]]:
    """{entity: {"static": rows, "rows": rows, "hash": sha256 of the sorted rows}}."""
    rows: dict[str, list[str]] = defaultdict(list)
    static: dict[str, int] = defaultdict(int)
    for ch in RrdReader(str(path)).stream():
        ent = ch.entity_path
        if ent == "/__properties":
            continue
        b = ch.to_record_batch()
        names = [n for n in b.schema.names if n != "rerun.controls.RowId"]
        cols = [_values(b.column(n)) for n in names]
        for i in range(b.num_rows):
            row = {n: _canon(c[i]) for n, c in zip(names, cols, strict=True)}
            if ent == "/meta":  # a run's random id is no content (fusion.io.rerun_sink run_id, where present)
                row = {n: [_without_run_id(x) for x in v] if isinstance(v, list) else v for n, v in row.items()}
            rows[ent].append(json.dumps(row, sort_keys=True))
        if ch.is_static:
            static[ent] += b.num_rows
    out = {}
    for ent in sorted(rows):
        h = hashlib.sha256("\n".join(sorted(rows[ent])).encode()).hexdigest()
        out[ent] = {"static": static.get(ent, 0), "rows": len(rows[ent]) - static.get(ent, 0), "hash": h}
    return out


def record(name: str, path: Path, *, duration_s: float, flush_rows: int = 300) -> None:
    """The reference scenario `name` through the Pipeline into a RerunSink at `path`
    (tests.io.scenario_run.record_scenario), with record flushes every `flush_rows` pending rows
    and none on the wall clock (so the flushes fall at the same steps in every run)."""
    record_scenario(name, path, duration_s=duration_s, flush_rows=flush_rows, flush_interval_s=1e9,
                    view_interval_s=1e9)


SCENARIOS = {"mix": 20.0, "helix3d": 30.0, "cv1d_a": 8.0}  # name -> seconds of the scenario


if __name__ == "__main__":  # write the reference: python -m tests.io.recording_digest OUT.json
    import sys
    import tempfile

    ref = {}
    with tempfile.TemporaryDirectory() as d:
        for name, secs in SCENARIOS.items():
            p = Path(d) / f"{name}.rrd"
            record(name, p, duration_s=secs)
            ref[name] = digest(p)
    Path(sys.argv[1]).write_text(json.dumps(ref, indent=1, sort_keys=True) + "\n")
