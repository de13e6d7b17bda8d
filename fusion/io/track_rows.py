"""The rows a flush derives from the kept estimates (see fusion.io.rerun_sink for the layout and
fusion.io.derive for the math): `score`, at every record flush, the all-track data of record;
with the trails and OSPA/GOSPA; `views`, at every view flush, the time series of the viewed
tracks from their rows of the record flushes since the last one. Stacked numpy over all estimates of a
flush; the per-track work is bounded by the number of viewed tracks (MAX_VIEWED) and done once
per view flush, however many record flushes came before it."""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Callable
from itertools import repeat
from operator import eq
from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.io import derive, gain_groups, trail
from fusion.io.labels import short_id
from fusion.io.palette import colour, series_colours
from fusion.io.truth_table import TruthTable
from fusion.io.view_rows import EstimateColumns, ReviewBlocks, Stacked
from fusion.io.viewed import ViewedTracks
from fusion.tracking.results import Estimate

OSPA_EVERY_NS = 1_000_000_000  # OSPA / GOSPA at most once per second of sensor time
OSPA_MAX_POINTS = 300  # and for scenes of at most this many tracks and targets (the assignment is cubic)
MAX_VIEWED = 6  # tracks with views of their own: the first confirmed ones (fusion.io.viewed)
# measurements in the position panels: the role's colour, translucent and small. Rerun draws a
# plot's points after all of its lines whatever the entity order (seen in screenshots, 0.41), so
# the estimate line (wider, opaque) can only show through them: at alpha 255 they hid it; at 64
# it shows, tinted orange where several points per pixel lie on it (a minute zoomed out)
_MEAS_UNDER_LINE = (*colour("associated")[:3], 64)


class Rows:
    """State that outlives one flush: truth, the viewed tracks, the scene's extent."""

    def __init__(self, layout: tuple[str, ...], pi: list[int], vi: list[int]) -> None:
        self.layout = layout
        self.pi = pi
        self.ki = sorted(set(pi) | set(vi))  # kinematic components: what NEES is computed over
        self.axes = [layout[i] for i in pi]
        self.truth = TruthTable()  # at most truth_table.KEPT times; before the horizon dropped at each flush
        self.choice = ViewedTracks(MAX_VIEWED)
        self._held: list[Stacked] = []  # the candidates' rows, until the choice is settled
        self._last: dict[int, tuple[int, int, int, Array]] = {}  # viewed track -> newest (t, step, arrival, world)
        self._trail: dict[int, tuple[int, Array, float]] = {}  # viewed track -> last trail ellipse (fusion.io.trail)
        self._lo = np.full(3, np.inf)
        self._hi = np.full(3, -np.inf)
        self._next_ospa = -(2**62)

    @property
    def newest_truth_ns(self) -> int | None:
        return self.truth.newest_ns

    def continue_from(self, other: Rows) -> None:
        self.truth.continue_from(other.truth)
        self.choice.continue_from(other.choice)
        self._held = list(other._held)
        self._last = dict(other._last)
        self._trail = dict(other._trail)
        self._lo, self._hi, self._next_ospa = other._lo.copy(), other._hi.copy(), other._next_ospa

    @property
    def viewed(self) -> dict[int, str]:
        """Track id -> label of the viewed tracks, in order of (first confirmed t_ns, id)."""
        return self.choice.labels

    def viewed_labels(self) -> list[str]:
        return list(self.viewed.values())

    def scene(self) -> tuple[list[float], float]:
        """Centre and half extent (m) of what was seen so far (origin and 10 m before any data)."""
        if not np.all(np.isfinite(self._lo)):
            return [0.0, 0.0, 0.0], 10.0
        return list((self._lo + self._hi) / 2), float(max(np.max(self._hi - self._lo) / 2, 1.0))

    def add_truths(self, target_ids: list[str], t_ns: list[int], S: Array) -> None:
        """True states in the tracker's layout: target_ids[i] at t_ns[i] in S[i] ((n, d)
        float64), kept to score estimates at the same times (fusion.io.truth_table)."""
        self.truth.add(target_ids, t_ns, S)

    def forget_truth_before(self, t_ns: int) -> None:
        """Drop the truth of times before t_ns: no estimate to score is before it any more (the
        sink passes the tracker's horizon, or the oldest estimate still waiting if older). Kept
        until fusion.io.truth_table.KEPT times, truth at 667 targets and 10 Hz held ~1.1 MB more
        every second (~170 bytes a sample in the dict it was then), 11 GB before the first drop."""
        self.truth.forget_before(t_ns)

    # ---- one flush -------------------------------------------------------------------------------
    def score(self, E: list[Estimate], t: Array, arr: Array, step: Array, sink: Any, *,
              horizon_ns: int | None) -> Stacked | None:
        """The record/estimates rows of a record flush's estimates (E, with their times t, arrival
        times and steps, int64 arrays), scored against the truth at
        their times (retractions as NaN rows), the trails (world/estimates, world/tentative) and
        OSPA/GOSPA; notes the candidates for views of their own and settles the choice up to
        `horizon_ns` (fusion.io.viewed: nothing before it can change any more), and widens the
        scene's extent. Returns the confirmed rows of the viewed tracks and of the candidates,
        stacked, for `views` (None if none): what is kept until the view flush is bounded by
        the viewed tracks (and, until the choice is settled, the candidates), not by the number
        of tracks."""
        self.choice.note(E)
        self.choice.settle(horizon_ns)
        if not E:
            return None
        rec = sink.col("record/estimates", "record")
        d = len(self.layout)
        status = [e.status for e in E]
        ret = np.fromiter(map(eq, status, repeat("retracted")), dtype=bool, count=len(E))
        if ret.any():  # x, std, error: NaN rows
            r = np.flatnonzero(ret).tolist()
            E_r = [E[i] for i in r]
            nan = np.full((len(E_r), d), np.nan)
            ids_r = [e.track_id for e in E_r]
            rec.extend(t[ret], step[ret], arr[ret],
                       blocks={"x": nan, "std": nan, "error": nan}, track=ids_r, label=[short_id(i) for i in ids_r],
                       sensor=[e.sensor_id for e in E_r], seq=[e.seq for e in E_r], status=[status[i] for i in r],
                       revision=[e.revision for e in E_r], nis=[np.nan] * len(E_r), nis_dof=[0] * len(E_r),
                       nees=[np.nan] * len(E_r), nees_dof=[0] * len(E_r), target=[""] * len(E_r))
            if ret.all():
                return None
            k = np.flatnonzero(~ret).tolist()
            E_, status = [E[i] for i in k], [status[i] for i in k]
            t, arr, step = t[~ret], arr[~ret], step[~ret]
        else:
            E_ = E
        rv = ReviewBlocks.of(E_)  # the estimates' posteriors and review arrays, block by block
        X = rv.rows_of("X", E_, "x")
        P = rv.rows_of("P", E_, "P")
        std = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None))
        n = len(E_)
        m_idx, TX, targets = derive.match_truth(t, X, P, self.truth, self.pi)
        err = np.full(X.shape, np.nan)
        err[m_idx] = X[m_idx] - TX
        nees = np.full(n, np.nan)
        if m_idx.size:
            nees[m_idx] = derive.nees(err[m_idx], P[m_idx], self.ki)
        target = np.full(n, "", dtype=object)
        target[m_idx] = targets
        matched = np.zeros(n, dtype=bool)
        matched[m_idx] = True
        cols = EstimateColumns.of(E_)
        nis_dof = rv.width("y")
        rec.extend(t, step, arr, track=cols.ids, label=list(map(short_id, cols.ids.tolist())),
                   sensor=cols.sensor.tolist(), seq=cols.seq, status=status, revision=cols.revision,
                   blocks={"x": X, "std": std, "error": err}, nis=cols.nis, nis_dof=nis_dof,
                   nees=nees, nees_dof=np.where(matched, len(self.ki), 0), target=target.tolist())
        W = derive.world(X[:, self.pi])
        conf = np.fromiter(map(eq, status, repeat("confirmed")), dtype=bool, count=len(status))
        if conf.any():
            self._lo = np.minimum(self._lo, W[conf].min(axis=0))
            self._hi = np.maximum(self._hi, W[conf].max(axis=0))
        for mask, entity, role, radius in ((conf, "world/estimates", "estimate", -2.0),
                                           (~conf, "world/tentative", "tentative", -1.5)):
            if mask.any():
                sink.col(entity, "points", rgba=colour(role), radius=radius).extend(
                    t[mask], step[mask], arr[mask], p=W[mask][:, None, :])
        self._set_distances(sink, t, step, arr, W, conf, cols.ids.tolist())
        kept = self.choice.kept_ids()
        sel = np.flatnonzero(conf & np.isin(cols.ids, kept)) if kept else np.empty(0, np.int64)
        if not sel.size:
            return None
        return Stacked.of([E_[i] for i in sel.tolist()], t[sel], step[sel], arr[sel], X[sel],
                          P[sel][:, self.pi][:, :, self.pi], std[sel], err[sel], matched[sel], nees[sel],  # Pp: _cursor
                          TX_full(TX, m_idx, X.shape)[sel], W[sel], conf=conf[sel], n_pos=len(self.pi),
                          blocks=rv.subset(sel), columns=cols.take(sel))

    def views(self, batches: list[Stacked], sink: Any, *, pause: Callable[[], None]) -> None:
        """The viewed tracks' time series and cursor marks, from their rows of the record flushes
        since the last view flush (in their order), and from the rows held for them while they
        were candidates; the rows of the candidates still undecided are held for the next.
        `pause` is called between tracks (the recording's thread may stop there for the loop)."""
        parts = self._held + batches
        self._held = []
        if not parts:
            return
        c = parts[0] if len(parts) == 1 else Stacked.concat(parts)
        present = set(c.ids.tolist())
        for tid in [tid for tid in self.viewed if tid in present]:  # in their order
            pause()
            self._track(sink, tid, np.flatnonzero(c.ids == tid), c)
        undecided = self.choice.candidates()
        if undecided:
            rows = np.flatnonzero(np.isin(c.ids, np.fromiter(undecided, dtype=np.int64, count=len(undecided))))
            if rows.size:
                self._held = [c.take(rows)]

    def _set_distances(self, sink: Any, t: Array, step: Array, arr: Array, W: Array, conf: Array,
                       ids: list[int]) -> None:
        """OSPA and GOSPA at the first scan time with truth in each OSPA_EVERY_NS."""
        times = np.unique(t[conf]).tolist()
        k = bisect_left(times, self._next_ospa)
        while k < len(times):
            tt = times[k]
            k += 1
            T = self.truth.at(tt)
            if T is None or len(T.ids) > OSPA_MAX_POINTS:
                continue
            self._next_ospa = tt + OSPA_EVERY_NS
            k = bisect_left(times, self._next_ospa, k)
            at = np.flatnonzero(conf & (t == tt))
            last = {ids[i]: i for i in at.tolist()}  # the newest row of each track at that time
            pts = W[sorted(last.values())][:, : len(self.pi)]
            truth_pts = T.S[:, self.pi]  # in the order of the targets' ids
            o, g = derive.set_distances(pts, truth_pts)
            i0 = int(at[0])
            for name, v in (("ospa", o), ("gospa", g)):
                sink.col(f"metrics/{name}", "scalars", width=1, names=[name.upper()],
                         colors=[colour("nees" if name == "ospa" else "nis")]).add(
                    int(t[i0]), int(step[i0]), int(arr[i0]), v=[v])

    def _track(self, sink: Any, tid: int, rows: Array, c: Stacked) -> None:
        """The time series and cursor entities of one viewed track (its `rows` of `c`)."""
        lab = self.viewed[tid]
        base = f"tracks/{lab}"
        t, step, arr = c.t[rows], c.step[rows], c.arr[rows]
        prior = c.prior[rows]
        mt = c.matched[rows]
        meas = c.meas[rows]
        meas_pos = c.meas_pos[rows][meas]
        for a, i in enumerate(self.pi):
            ax = self.axes[a]
            # the prediction first: a plot draws its series in order, the estimate goes on top
            sink.col(f"{base}/position/{ax}/estimate", "scalars", width=2, names=["prediction", "estimate"],
                     colors=[colour("prediction"), colour("estimate")], widths=[1.0, 2.5]).extend(
                t, step, arr, v=np.column_stack([prior[:, i], c.X[rows, i]]))
            if mt.any():
                sink.col(f"{base}/position/{ax}/truth", "scalars", width=1, names=["truth"],  # thin: drawn after
                         colors=[colour("truth")], widths=[1.0]).extend(
                    t[mt], step[mt], arr[mt], v=c.TX[rows][mt][:, i:i + 1])
                e_ = c.err[rows][mt][:, i]
                s_ = 2.0 * c.std[rows][mt][:, i]
                sink.col(f"{base}/error/{ax}", "scalars", width=3, names=["error", "+2 sigma", "-2 sigma"],
                         colors=[colour("estimate"), colour("bound"), colour("bound")]).extend(
                    t[mt], step[mt], arr[mt], v=np.column_stack([e_, s_, -s_]))
            if meas.any():
                sink.col(f"{base}/position/{ax}/measurement", "scalars", width=1, names=["associated measurement"],
                         colors=[_MEAS_UNDER_LINE], points=True, marker_size=0.75).extend(
                    t[meas], step[meas], arr[meas], v=meas_pos[:, a:a + 1])
        if mt.any():
            lo, hi = derive.chi2_bounds(len(self.ki))
            nv = c.nees[rows][mt]
            sink.col(f"{base}/nees", "scalars", width=3, names=[f"NEES (n={len(self.ki)})", "2.5 %", "97.5 %"],
                     colors=[colour("nees"), colour("bound"), colour("bound")]).extend(
                t[mt], step[mt], arr[mt], v=np.column_stack([nv, np.full_like(nv, lo), np.full_like(nv, hi)]))
        d = len(self.layout)
        sink.col(f"{base}/std", "scalars", width=d, names=[f"sigma {x}" for x in self.layout],
                 colors=series_colours(d)).extend(t, step, arr, v=c.std[rows])
        self._update_parts(sink, base, tid, c)
        self._cursor(sink, tid, lab, rows, c)

    def _update_parts(self, sink: Any, base: str, tid: int, c: Stacked) -> None:
        """NIS with its bounds, innovation with +-2 sqrt(diag S) and Kalman gain (Updates.K), per
        sensor, and IMM mode probabilities, of track `tid`."""
        d = len(self.layout)
        for sensor, u in sorted(c.updates.items()):
            g = np.flatnonzero(c.ids[u.rows] == tid)  # the track's rows of this sensor, in order
            if not g.size:
                continue
            r = u.rows[g]
            t, step, arr = c.t[r], c.step[r], c.arr[r]
            Y, S, nis = u.Y[g], u.S[g], u.nis[g]
            m = Y.shape[1]
            lo, hi = derive.chi2_bounds(m)
            sink.col(f"{base}/nis", "scalars", width=3, names=[f"NIS (m={m})", "2.5 %", "97.5 %"],
                     colors=[colour("nis"), colour("bound"), colour("bound")]).extend(
                t, step, arr, v=np.column_stack([nis, np.full_like(nis, lo), np.full_like(nis, hi)]))
            s2 = 2.0 * np.sqrt(np.clip(np.diagonal(S, axis1=1, axis2=2), 0.0, None))
            names = [f"y{j}" for j in range(m)] + [f"+2 sqrt S{j}{j}" for j in range(m)] + \
                    [f"-2 sqrt S{j}{j}" for j in range(m)]
            sink.col(f"{base}/innovation/{sensor}", "scalars", width=3 * m, names=names,
                     colors=series_colours(m) + [colour("bound")] * 2 * m).extend(
                t, step, arr, v=np.concatenate([Y, s2, -s2], axis=1))
            has_k = u.gain[g]
            if has_k.any():
                K = u.K[g][has_k]
                # one scale per unit; a sink without the description (bench/recording_cost.py loads
                # main's sink beside this module) gets the unsplit gain
                measured = getattr(sink, "measured", {})
                for group, cols, comp in gain_groups.split(measured, sensor, m):
                    w = d * len(cols)
                    sink.col(f"{base}/gain/{group}/{sensor}", "scalars", width=w,
                             names=[f"K[{x},{c_}]" for x in self.layout for c_ in comp],
                             colors=series_colours(w)).extend(t[has_k], step[has_k], arr[has_k],
                                                              v=K[:, :, cols].reshape(len(K), -1))
        if c.mu is not None:
            rows = np.flatnonzero((c.ids == tid) & c.mode)
            if rows.size:
                mu = c.mu[rows]
                sink.col(f"{base}/mode", "scalars", width=mu.shape[1],
                         names=_mode_names(sink.mode_names, mu.shape[1]), colors=series_colours(mu.shape[1])).extend(
                    c.t[rows], c.step[rows], c.arr[rows], v=mu)

    def _cursor(self, sink: Any, tid: int, lab: str, rows: Array, c: Stacked) -> None:
        """Labelled point and 2-sigma ellipse at the cursor, the faint trail of earlier ellipses
        (fusion.io.trail picks them); a start marker at the first row."""
        t, step, arr = c.t[rows], c.step[rows], c.arr[rows]
        W = c.W[rows]
        w = f"world/tracks/{lab}"
        if tid not in self._last:
            sink.col(f"{w}/start", "points", rgba=colour("start"), radius=-6.0).add(
                int(t[0]), int(step[0]), int(arr[0]), p=W[:1])  # green: the colour says start, no text to clutter
        self._last[tid] = (int(t[-1]), int(step[-1]), int(arr[-1]), W[-1].copy())
        sink.col(f"{w}/now", "points", rgba=colour("estimate"), radius=-5.0, show_labels=True).extend(
            t, step, arr, p=W[:, None, :], label=[[lab]] * len(rows))
        Pp = c.Pp[rows]
        pos = c.X[rows][:, self.pi]
        keep: list[int] = []
        if len(self.pi) > 1:
            keep, self._trail[tid] = trail.pick(t, pos, trail.radii(Pp), self._trail.get(tid))
        k = np.array(keep, dtype=np.int64)
        if len(self.pi) == 3:
            half, quat = derive.ellipsoid_axes(Pp)
            sink.col(f"{w}/cov", "ellipsoids", rgba=colour("covariance")).extend(
                t, step, arr, c=pos, h=half, q=quat)
            if keep:
                sink.col(f"{w}/trail", "ellipsoids", rgba=colour("trail"), radius=-0.5).extend(
                    t[k], step[k], arr[k], c=pos[k], h=half[k], q=quat[k])
            return
        if len(self.pi) == 2:
            strips = derive.ellipse_points(pos, Pp, dims=3, dtype=np.float32)  # world points, as recorded
            if keep:
                sink.col(f"{w}/trail", "strips", rgba=colour("trail"), radius=-0.5).extend(
                    t[k], step[k], arr[k], s=strips[k])
        else:
            half = 2.0 * np.sqrt(Pp[:, 0, 0])
            strips = derive.world(np.stack([pos - half[:, None], pos + half[:, None]], axis=1))
        sink.col(f"{w}/cov", "strips", rgba=colour("covariance")).extend(t, step, arr, s=strips)

    def mark_ends(self, sink: Any) -> None:
        """An end marker at the newest position of every viewed track (at close)."""
        for tid, (t, step, arr, w) in sorted(self._last.items()):
            lab = self.viewed[tid]
            sink.col(f"world/tracks/{lab}/end", "points", rgba=colour("end"), radius=-6.0).add(
                t, step, arr, p=w[None, :])


def TX_full(TX: Array, idx: Array, shape: tuple[int, ...]) -> Array:
    """Matched true states scattered to the rows they belong to (NaN elsewhere)."""
    out = np.full(shape, np.nan)
    out[idx] = TX
    return out


def _mode_names(names: tuple[str, ...], k: int) -> list[str]:
    """The IMM's mode names for its k probability series ("mode j" where none are given)."""
    return list(names) if len(names) == k else [f"mode {j}" for j in range(k)]
