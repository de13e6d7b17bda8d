"""Every tracker step into a Rerun .rrd file, written in columns.

Per-call `log` costs 50-150 us here and so does each `send_columns` call, whatever its size, so
rows are buffered per entity in plain lists and written with one `send_columns` per entity when
`flush_rows` rows are pending or `flush_interval_s` has passed (checked on each call), and at
`close()`; and the layout keeps the number of entities small (one multi-valued Scalars entity per
quantity, one shared entity for all tentative tracks). Nothing the tracker did is dropped.

Entity layout (all positions in metres, world frame; 1-D tracks on the x axis of a 2-D view,
3-D tracks with the 3-D archetypes):
  world/meas/<sensor_id>             measured points (radar returns converted to Cartesian)
  world/tentative                    every estimate of a tentative track (labelled with its id)
  world/tracks/<track_id>            estimated position of a confirmed track (Points)
  world/tracks/<track_id>/cov        2-sigma covariance ellipse (LineStrips2D) or ellipsoid (Ellipsoids3D)
  world/tracks/<track_id>/vel        velocity (Arrows)
  world/tracks/<track_id>/meas       the measurement that updated it: the association
  world/truth/<target_id>            true position
  tracks/<track_id>/state            every state component (Scalars, one series per component)
  tracks/<track_id>/std              sqrt(diag(P))
  tracks/<track_id>/truth            truth of the nearest true target at the same time, if within MATCH_D2
  tracks/<track_id>/error            estimate - truth
  tracks/<track_id>/nis              NIS of the update (degrees of freedom in tracks/<track_id>/nis_dof)
  tracks/<track_id>/nees             NEES against the matched truth
  tracks/<track_id>/mode             IMM model probabilities
  events                             births, confirmations, deletions, retractions, replays, refusals (TextLog)
  counts/<name>                      the tracker's cumulative counters (received, applied, refused_<reason>, ...)
  meta                               static JSON: layout, position indices, sensors (TextDocument)
Timelines: `t` (sensor time, timestamp from integer ns), `step` (tracker call counter),
`arrival` (arrival time of the data that produced the row, where known).
"""

from __future__ import annotations

import json
import time
from collections import defaultdict
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.tracking.results import Estimate, StepResult

MATCH_D2 = 100.0  # squared Mahalanobis distance (position) within which a truth target is matched
_COLOURS = {"tentative": (160, 160, 160), "confirmed": (40, 160, 255)}
_CIRCLE = np.stack([np.cos(np.linspace(0, 2 * np.pi, 33)), np.sin(np.linspace(0, 2 * np.pi, 33))], axis=1)


def ellipse_points(mean: Array, cov: Array, *, n_sigma: float = 2.0) -> Array:
    """Points of the n-sigma ellipse of 2-D Gaussians: mean + n L u for u on the unit circle,
    L L' = cov. mean (..., 2), cov (..., 2, 2) -> (..., 33, 2)."""
    w, V = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    L = V * np.sqrt(np.clip(w, 0.0, None))[..., None, :]
    return mean[..., None, :] + n_sigma * _CIRCLE @ np.swapaxes(L, -1, -2)


class _Column:
    """Pending rows of one entity: times and the archetype's fields."""

    __slots__ = ("arrival_ns", "data", "kind", "step", "t_ns")

    def add(self, t_ns: int, step: int, arrival_ns: int) -> None:
        self.t_ns.append(t_ns)
        self.step.append(step)
        self.arrival_ns.append(arrival_ns)

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.t_ns: list[int] = []
        self.step: list[int] = []
        self.arrival_ns: list[int] = []
        self.data: dict[str, list[Any]] = defaultdict(list)


class RerunSink:
    """Buffers tracker output and writes it to `path` as a Rerun recording."""

    def __init__(
        self, path: str | Path, *, layout: tuple[str, ...], position_indices: tuple[int, ...],
        velocity_indices: tuple[int, ...], recording_id: str = "fusion", application_id: str = "fusion",
        flush_rows: int = 20_000, flush_interval_s: float = 0.5, meta: Mapping[str, Any] | None = None,
        counts: Callable[[], Mapping[str, int]] | None = None,
    ) -> None:
        import rerun as rr

        self._rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self.rec.save(str(self.path))
        self.layout = layout
        self.pi = list(position_indices)
        self.vi = list(velocity_indices)
        self.ndim = len(position_indices)  # 1-D tracks are drawn on the x axis of a 2-D view
        self._cols: dict[str, _Column] = {}
        self._pending = 0
        self.rows_written = 0
        self._flush_rows = flush_rows
        self._interval = flush_interval_s
        self._last_flush = time.monotonic()
        self._step = 0
        self._truth: dict[int, dict[str, Array]] = defaultdict(dict)  # t_ns -> target -> state (layout order)
        self._closed = False
        self._named: set[str] = set()
        self._est: list[tuple[Estimate, int, int]] = []
        self._counts = counts
        self._newest_t = 0
        self._send_blueprint()
        info = {"layout": list(layout), "position_indices": list(position_indices),
                "velocity_indices": list(velocity_indices), **(meta or {})}
        self.rec.log("meta", rr.TextDocument(json.dumps(info, sort_keys=True), media_type="text/plain"), static=True)

    # ---- buffering ---------------------------------------------------------------------------
    def _row(self, entity: str, kind: str, t_ns: int, arrival_ns: int | None, **fields: Any) -> None:
        c = self._cols.get(entity)
        if c is None:
            c = self._cols[entity] = _Column(kind)
        c.t_ns.append(t_ns)
        if t_ns > self._newest_t:
            self._newest_t = t_ns
        c.step.append(self._step)
        c.arrival_ns.append(t_ns if arrival_ns is None else arrival_ns)
        for k, v in fields.items():
            c.data[k].append(v)
        self._pending += 1

    def _scalar(self, entity: str, t_ns: int, value: float, arrival_ns: int | None = None) -> None:
        self._row(entity, "scalar", t_ns, arrival_ns, v=float(value))


    def _world(self, p: Array) -> Array:
        """A point (or points) for the world view: 1-D positions go on the x axis."""
        p = np.asarray(p, dtype=np.float64)
        if p.shape[-1] == 1:
            return np.concatenate([p, np.zeros_like(p)], axis=-1)
        return p

    def log_measurements(self, sensor_id: str, t_ns: int, points: Array, arrival_ns: int | None = None) -> None:
        """Measured points (k, d) of one scan, in Cartesian world coordinates."""
        self._row(f"world/meas/{sensor_id}", "points", t_ns, arrival_ns, p=self._world(points))

    def log_truth(self, target_id: str, t_ns: int, state: Array) -> None:
        """A true state in the tracker's layout; kept to score estimates at the same t_ns."""
        s = np.asarray(state, dtype=np.float64)
        self._truth[t_ns][target_id] = s
        self._row(f"world/truth/{target_id}", "points", t_ns, None, p=self._world(s[self.pi])[None, :])
        if len(self._truth) > 100_000:  # bounded: drop the oldest times
            for k in sorted(self._truth)[:50_000]:
                del self._truth[k]

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        self._row("events", "text", t_ns, None, text=text, level=level)

    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        """One Tracker.process result: estimates, events, replays and refusals."""
        self._step += 1
        scans: dict[tuple[str, int], list[Array]] = {}
        for m in result.measurements:
            scans.setdefault((m.sensor_id, m.t_ns), []).append(m.position)
        for (sensor_id, t_ns), pts in sorted(scans.items()):
            self.log_measurements(sensor_id, t_ns, np.stack(pts), arrival_ns)
        for e in result.estimates:
            self._estimate(e, arrival_ns)
        for ev in result.events:
            why = "" if ev.reason is None else f" {ev.reason.value}"
            if ev.retracted:
                self.log_text(ev.t_ns, f"track {ev.track_id} withdrawn {ev.kind.value}{why} (gone after a replay)")
            else:
                self.log_text(ev.t_ns, f"track {ev.track_id} {ev.kind.value}{why}")
        for rp in result.replays:
            late = ", ".join(f"{s}#{q}" for s, q in rp.trigger)
            self.log_text(rp.from_t_ns, f"replay of {rp.n_scans} scans from late {late}", "WARN")
        for r in result.refused:
            self.log_text(r.t_ns, f"refused {r.sensor_id}#{r.seq}: {r.reason.value}: {r.detail}", "WARN")
        self.maybe_flush()

    def _estimate(self, e: Estimate, arrival_ns: int | None) -> None:
        """Hot path: keep the estimate; everything derived from it is computed at flush time,
        vectorised over each track's rows."""
        if e.status == "retracted":
            self.log_text(e.t_ns, f"track {e.track_id} retracted its estimate from {e.sensor_id} (rev {e.revision})")
            return
        self._est.append((e, e.t_ns if arrival_ns is None else arrival_ns, self._step))
        self._pending += 1
        if e.t_ns > self._newest_t:
            self._newest_t = e.t_ns

    def _derive(self) -> None:
        """Turn the kept estimates into rows, per track, with stacked numpy operations."""
        est, self._est = self._est, []
        if not est:
            return
        by_track: dict[int, list[tuple[Estimate, int, int]]] = defaultdict(list)
        tentative: list[tuple[Estimate, int, int]] = []
        for item in est:
            (tentative if item[0].status == "tentative" else by_track[item[0].track_id]).append(item)
        if tentative:
            c = self._col("world/tentative", "tentative")
            for e, arr, step in tentative:
                c.add(e.t_ns, step, arr)
                c.data["p"].append(self._world(e.x[self.pi]))
                c.data["label"].append(str(e.track_id))
        names = self.layout
        for tid in sorted(by_track):
            rows = by_track[tid]
            base = f"tracks/{tid}"
            t = np.array([r[0].t_ns for r in rows], dtype=np.int64)
            arr = np.array([r[1] for r in rows], dtype=np.int64)
            step = np.array([r[2] for r in rows], dtype=np.int64)
            X = np.stack([r[0].x for r in rows])
            P = np.stack([r[0].P for r in rows])
            pos = X[:, self.pi]
            Pp = P[:, self.pi][:, :, self.pi]
            wpos = self._world(pos)
            self._cols_add(f"world/{base}", "track", t, step, arr, p=list(wpos), status=[r[0].status for r in rows])
            if self.ndim == 1:
                half = 2.0 * np.sqrt(Pp[:, 0, 0])
                seg = np.stack([wpos - np.column_stack([half, 0 * half]), wpos + np.column_stack([half, 0 * half])], 1)
                self._cols_add(f"world/{base}/cov", "strip", t, step, arr, s=list(seg))
            elif self.ndim == 2:
                self._cols_add(f"world/{base}/cov", "strip", t, step, arr, s=list(ellipse_points(pos, Pp)))
            else:
                self._cols_add(f"world/{base}/cov", "ellipsoid", t, step, arr, c=list(pos), cov=list(Pp))
            if self.vi:
                vel = self._world(X[:, self.vi])
                self._cols_add(f"world/{base}/vel", "arrow", t, step, arr, o=list(wpos), v=list(vel))
            mp = [r[0].meas_pos for r in rows]
            if all(p is not None for p in mp):
                self._cols_add(f"world/{base}/meas", "points", t, step, arr,
                               p=[self._world(p)[None, :] for p in mp])  # type: ignore[arg-type]
            self._name(f"{base}/state", names)
            self._cols_add(f"{base}/state", "vector", t, step, arr, v=list(X))
            self._name(f"{base}/std", names)
            self._cols_add(f"{base}/std", "vector", t, step, arr,
                           v=list(np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None))))
            upd = [i for i, r in enumerate(rows) if r[0].nis is not None and r[0].y is not None]
            if upd:
                sel = np.array(upd)
                self._cols_add(f"{base}/nis", "scalar", t[sel], step[sel], arr[sel], v=[rows[i][0].nis for i in upd])
                self._cols_add(f"{base}/nis_dof", "scalar", t[sel], step[sel], arr[sel],
                               v=[float(rows[i][0].y.shape[0]) for i in upd])  # type: ignore[union-attr]
            if rows[0][0].mode_probabilities is not None:
                mu = np.stack([r[0].mode_probabilities for r in rows])
                self._name(f"{base}/mode", tuple(f"model {k}" for k in range(mu.shape[1])))
                self._cols_add(f"{base}/mode", "vector", t, step, arr, v=list(mu))
            self._score(base, rows, t, step, arr, X, P, Pp)

    def _score(self, base: str, rows: list, t: Array, step: Array, arr: Array, X: Array, P: Array, Pp: Array) -> None:
        """Truth, error and NEES rows against the nearest true target at the same time, when it
        lies within MATCH_D2 (a truth sample that has not arrived yet must not pair a track with
        another target)."""
        idx, truths = [], []
        for i, tt in enumerate(t.tolist()):
            T = self._truth.get(tt)
            if not T:
                continue
            cand = np.stack([T[k] for k in sorted(T)])
            if cand.shape[1] != X.shape[1]:
                continue
            k = int(np.argmin(np.sum((cand[:, self.pi] - X[i, self.pi]) ** 2, axis=1)))
            idx.append(i)
            truths.append(cand[k])
        if not idx:
            return
        sel = np.array(idx)
        TX = np.stack(truths)
        E = X[sel] - TX
        dp = E[:, self.pi]
        d2 = np.einsum("ij,ij->i", dp, np.linalg.solve(Pp[sel], dp[..., None])[..., 0])
        ok = d2 < MATCH_D2
        if not ok.any():
            return
        sel, TX, E = sel[ok], TX[ok], E[ok]
        nees = np.einsum("ij,ij->i", E, np.linalg.solve(P[sel], E[..., None])[..., 0])
        self._name(f"{base}/truth", self.layout)
        self._name(f"{base}/error", self.layout)
        self._cols_add(f"{base}/truth", "vector", t[sel], step[sel], arr[sel], v=list(TX))
        self._cols_add(f"{base}/error", "vector", t[sel], step[sel], arr[sel], v=list(E))
        self._cols_add(f"{base}/nees", "scalar", t[sel], step[sel], arr[sel], v=nees.tolist())

    def _name(self, entity: str, names: tuple[str, ...]) -> None:
        if entity not in self._named:
            self._named.add(entity)
            self.rec.log(entity, self._rr.SeriesLines(names=list(names)), static=True)

    def _col(self, entity: str, kind: str) -> _Column:
        c = self._cols.get(entity)
        if c is None:
            c = self._cols[entity] = _Column(kind)
        return c

    def _cols_add(self, entity: str, kind: str, t: Array, step: Array, arr: Array, **fields: list) -> None:
        c = self._col(entity, kind)
        c.t_ns.extend(t.tolist())
        c.step.extend(step.tolist())
        c.arrival_ns.extend(arr.tolist())
        for k, v in fields.items():
            c.data[k].extend(v)

    # ---- writing -------------------------------------------------------------------------------
    def maybe_flush(self) -> None:
        if self._pending >= self._flush_rows or time.monotonic() - self._last_flush >= self._interval:
            self.flush()

    def flush(self) -> None:
        """Write every pending row as columns (and the tracker's counters, when given)."""
        rr = self._rr
        self._derive()
        if self._counts is not None and self._pending:
            for name, v in sorted(self._counts().items()):
                self._scalar(f"counts/{name}", self._newest_t, v)
        cols, self._cols = self._cols, {}
        for entity in sorted(cols):
            c = cols[entity]
            n = len(c.t_ns)
            idx = [
                rr.TimeColumn("t", timestamp=np.array(c.t_ns, dtype="datetime64[ns]")),
                rr.TimeColumn("step", sequence=np.array(c.step, dtype=np.int64)),
                rr.TimeColumn("arrival", timestamp=np.array(c.arrival_ns, dtype="datetime64[ns]")),
            ]
            d = c.data
            if c.kind == "scalar":
                columns = rr.Scalars.columns(scalars=np.array(d["v"]))
            elif c.kind == "vector":
                columns = rr.Scalars.columns(scalars=np.concatenate(d["v"])).partition([len(v) for v in d["v"]])
            elif c.kind == "tentative":
                pts = np.stack(d["p"])
                arch = rr.Points2D if pts.shape[1] == 2 else rr.Points3D
                # ids kept as labels (hover shows them) but not drawn: clutter would bury the view
                columns = arch.columns(positions=pts, labels=d["label"], show_labels=np.zeros(n, dtype=bool),
                                       colors=np.tile(np.array(_COLOURS["tentative"], dtype=np.uint8), (n, 1)))
            elif c.kind == "text":
                columns = rr.TextLog.columns(text=d["text"], level=d["level"])
            elif c.kind == "points":
                lens = [len(p) for p in d["p"]]
                pts = np.concatenate(d["p"]) if n else np.empty((0, max(self.ndim, 2)))
                arch = rr.Points2D if pts.shape[1] == 2 else rr.Points3D
                columns = arch.columns(positions=pts).partition(lens)
            elif c.kind == "track":
                pts = np.stack(d["p"])
                arch = rr.Points2D if pts.shape[1] == 2 else rr.Points3D
                colours = np.array([_COLOURS.get(s, (255, 80, 80)) for s in d["status"]], dtype=np.uint8)
                columns = arch.columns(positions=pts, colors=colours, radii=np.full(n, 0.5))
            elif c.kind == "strip":
                columns = rr.LineStrips2D.columns(strips=d["s"]).partition([1] * n)
            elif c.kind == "ellipsoid":
                half, quat = [], []
                for cov in d["cov"]:
                    w, V = np.linalg.eigh(cov)
                    if np.linalg.det(V) < 0:
                        V[:, 0] = -V[:, 0]
                    half.append(2.0 * np.sqrt(np.clip(w, 0.0, None)))
                    quat.append(_quat_xyzw(V))
                columns = rr.Ellipsoids3D.columns(
                    centers=np.stack(d["c"]), half_sizes=np.stack(half), quaternions=np.stack(quat)
                )
            elif c.kind == "arrow":
                arch = rr.Arrows2D if self.ndim <= 2 else rr.Arrows3D
                columns = arch.columns(origins=np.stack(d["o"]), vectors=np.stack(d["v"]))
            else:  # pragma: no cover - every kind above is produced by this class
                raise AssertionError(c.kind)
            self.rec.send_columns(entity, indexes=idx, columns=columns)
            self.rows_written += n
        self._pending = 0
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Flush everything and finish the file (complete footer: `rerun rrd verify` passes)."""
        if self._closed:
            return
        self.flush()
        self.rec.flush()
        self.rec.disconnect()
        self._closed = True

    def __enter__(self) -> RerunSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- static content ------------------------------------------------------------------------
    def _send_blueprint(self) -> None:
        import rerun.blueprint as rrb

        # Trails: everything up to the time cursor, so the view shows trajectories, not dots.
        history = rrb.VisibleTimeRange("t", start=rrb.TimeRangeBoundary.infinite(),
                                       end=rrb.TimeRangeBoundary.cursor_relative())
        view = rrb.Spatial2DView if self.ndim <= 2 else rrb.Spatial3DView
        world = view(origin="world", name="Trajectories", time_ranges=history)
        bp = rrb.Blueprint(
            rrb.Horizontal(
                rrb.Vertical(world, rrb.TextLogView(origin="events", name="Events"), row_shares=[3, 1]),
                rrb.Vertical(
                    rrb.TimeSeriesView(origin="tracks", contents="$origin/*/state", name="State"),
                    rrb.TimeSeriesView(origin="tracks", contents="$origin/*/std", name="Standard deviations"),
                    rrb.TimeSeriesView(
                        origin="tracks", contents=["$origin/*/nis", "$origin/*/nees"], name="NIS / NEES"
                    ),
                    rrb.TimeSeriesView(origin="tracks", contents="$origin/*/error", name="Error vs truth"),
                ),
                column_shares=[3, 2],
            ),
            collapse_panels=True,
        )
        self.rec.send_blueprint(bp)


def _quat_xyzw(V: Array) -> Array:
    """Quaternion (x, y, z, w) of a proper rotation matrix V."""
    m = V
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        return np.array([(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s])
    i = int(np.argmax(np.diagonal(m)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
    q = np.empty(4)
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    q[3] = (m[k, j] - m[j, k]) / s
    return q

