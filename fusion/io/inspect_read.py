"""What `fusion inspect` reads from the chunks of a recording's files, per run (no verdicts here).

A run is what one tracker produced: the files of a rotated set are pieces of one run and carry the
same run id (meta "run_id", written by fusion.io.rerun_sink); independent runs (another seed,
another process, another replay) carry different ones. `run_key` decides which run a file
belongs to: by its run id ("id", the default; files without one, from before run ids, are taken
as pieces of one run), every file one run ("files"), or all files one run ("one").

From the data of record (`record/estimates`, `record/associations`, `record/events`, columns,
no text is parsed), `world/truth`, `world/meas/*`, `counts/*` and `meta`.
"""

from __future__ import annotations

import json
from collections import defaultdict

import numpy as np

RUNS_BY = ("id", "files", "one")
_EST_FIELDS = ("track", "label", "sensor", "status", "revision", "nis", "nis_dof", "nees", "nees_dof")


def file_meta(chunks: list) -> dict[str, object]:
    """The static JSON of `meta` in a file's chunks ({} when absent)."""
    meta: dict[str, object] = {}
    for ch in chunks:
        if ch.entity_path == "/meta":
            b = ch.to_record_batch()
            if "TextDocument:text" in b.schema.names:
                meta = json.loads(b.column("TextDocument:text").to_pylist()[0][0])
    return meta


def run_key(meta: dict[str, object], index: int, runs_by: str) -> str:
    """The run a file belongs to (see the module docstring); index: the file's place in the set."""
    if runs_by not in RUNS_BY:
        raise ValueError(f"runs_by must be one of {', '.join(RUNS_BY)}, not {runs_by!r}")
    if runs_by == "one":
        return ""
    if runs_by == "files":
        return f"file {index}"
    return str(meta.get("run_id", ""))


class RunRecord:
    """What the summary needs from the chunks of the files of one run."""

    def __init__(self) -> None:
        self.est: dict[str, list] = defaultdict(list)
        self.sensors: dict[str, int] = defaultdict(int)
        self.events: dict[str, int] = defaultdict(int)
        self.counts: dict[str, tuple[int, int]] = {}  # name -> (t, value)
        self.truth: dict[int, list[list[float]]] = defaultdict(list)  # t -> true states (record/truth)
        self.truth_world: dict[int, list[list[float]]] = defaultdict(list)  # t -> world/truth (float32)
        self.scan_t: set[int] = set()  # times of accepted measurements
        self.meta: dict[str, object] = {}
        self.t: list[int] = []

    def add(self, chunks: list) -> None:
        self.meta = file_meta(chunks) or self.meta
        for ch in chunks:
            ent: str = ch.entity_path
            b = ch.to_record_batch()
            names = b.schema.names
            if "t" not in names or not b.num_rows:
                continue
            t = b.column("t").cast("int64").to_numpy()
            self.t.extend((int(t.min()), int(t.max())))
            if ent == "/record/estimates":
                self.est["t"].extend(t.tolist())
                for k in _EST_FIELDS:
                    self.est[k].extend(v[0] if v else None for v in b.column(k).to_pylist())
                self.est["x"].extend(b.column("x").to_pylist())  # a vector per row (the batch itself)
                self.est["error"].extend(b.column("error").to_pylist())
            elif ent == "/record/associations":
                self.scan_t.update(t.tolist())
            elif ent == "/record/events":
                for kind, retracted in zip(b.column("kind").to_pylist(), b.column("retracted").to_pylist(),
                                           strict=True):
                    self.events[("withdrawn " if retracted[0] else "") + kind[0]] += 1
            elif ent == "/record/truth":
                for tt, x in zip(t.tolist(), b.column("x").to_pylist(), strict=True):
                    self.truth[tt].append(x)
            elif ent == "/world/truth" and "Points3D:positions" in names:
                for tt, pts in zip(t.tolist(), b.column("Points3D:positions").to_pylist(), strict=True):
                    self.truth_world[tt].extend(pts)
            elif ent.startswith("/world/meas/") and "Points3D:positions" in names:
                self.sensors[ent.rsplit("/", 1)[1]] += sum(len(x) for x in b.column("Points3D:positions").to_pylist())
            elif ent.startswith("/counts/") and "Scalars:scalars" in names:
                v = b.column("Scalars:scalars").to_pylist()
                i = len(t) - 1 - int(np.argmax(t[::-1]))  # the last row written at the newest time
                name = ent[len("/counts/"):]
                if name not in self.counts or int(t[i]) >= self.counts[name][0]:
                    self.counts[name] = (int(t[i]), int(v[i][0]))

    def truth_points(self, pos_idx: list[int]) -> dict[int, np.ndarray]:
        """True positions per time as world points (3-D): from record/truth (float64), or from
        world/truth (float32) in recordings from before record/truth."""
        from fusion.io.derive import world

        if self.truth:
            return {t: world(np.asarray(x, dtype=np.float64)[:, pos_idx]) for t, x in self.truth.items()}
        return {t: np.asarray(p, dtype=np.float64) for t, p in self.truth_world.items()}

    def latest(self) -> list[int]:
        """Row indices of the latest revision of each estimate (track, time, sensor), retractions
        removed, sorted by (track, time, sensor)."""
        est = self.est
        best: dict[tuple[int, int, str], int] = {}
        for i, key in enumerate(zip(est["track"], est["t"], est["sensor"], strict=True)):
            j = best.get(key)
            if j is None or est["revision"][i] >= est["revision"][j]:
                best[key] = i
        return [i for _, i in sorted(best.items()) if est["status"][i] != "retracted"]
