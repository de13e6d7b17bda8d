"""The multi-target, multi-sensor tracker: measurements in, what happened out. No I/O, no clock.

Processing order is total: scans keyed by (t_ns, sensor_id), measurements of a scan by seq.
The result of a stream depends only on the set of measurements accepted, never on the order
they arrived in: a measurement that lands before the newest processed scan (but inside the lag
window) rewinds to the checkpoint before its scan and replays every later scan, association,
births and deletions included. Estimates that a replay changes are emitted again with a higher
revision; estimates it no longer produces are emitted once more as retracted.

One scan (all measurements of one sensor at one time):
  1. coarse gate: constant-velocity extrapolation of every track, per-axis bound (vectorised);
  2. fine gate: filter predict + update of each candidate pair, NIS <= chi2_m(probability);
  3. GNN assignment over gated pairs (fusion.core.association);
  4. assigned tracks take their posterior; measurements in no gate start tentative tracks;
  5. lifecycle: M-of-N confirmation, deletion after misses, coasting time or a large covariance.
"""

from __future__ import annotations

import bisect
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy.special import chdtri

from fusion.config import TrackerConfig
from fusion.core.association import coarse_pairs, gnn_assign
from fusion.core.gaussian import GaussianState, Update
from fusion.core.imm import IMM, IMMState
from fusion.core.kalman import ExtendedKalmanFilter, predict_arrays, update_arrays
from fusion.core.motion import ConstantAcceleration, ConstantVelocity, CoordinatedTurn
from fusion.core.timebase import NS_PER_S
from fusion.errors import ConfigError, NumericalError
from fusion.tracking.detection import Detection, Reason, Refusal
from fusion.tracking.models import (
    SensorModel,
    initial_covariance_diag,
    layout,
    make_filter,
    motion_model,
    sensor_models,
)
from fusion.tracking.trackset import Status, Track, TrackSet, track_id_for

ScanKey = tuple[int, str]


@dataclass(frozen=True, slots=True)
class Estimate:
    """A track's posterior after a scan (or its retraction, status "retracted")."""

    track_id: int
    t_ns: int
    sensor_id: str
    seq: int  # the measurement that updated (or started) the track
    x: np.ndarray
    P: np.ndarray
    status: str  # "tentative" | "confirmed" | "retracted"
    revision: int
    nis: float | None
    y: np.ndarray | None
    S: np.ndarray | None
    mode_probabilities: np.ndarray | None = None
    meas_pos: np.ndarray | None = None  # world position of the measurement used (the association)


@dataclass(frozen=True, slots=True)
class MeasuredPoint:
    """A newly accepted measurement, in world Cartesian coordinates (for recordings)."""

    sensor_id: str
    t_ns: int
    seq: int
    position: np.ndarray


@dataclass(frozen=True, slots=True)
class TrackEvent:
    """born | confirmed | deleted (with the reason) | retracted (vanished after a replay)."""

    kind: str
    track_id: int
    t_ns: int
    detail: str = ""
    replayed: bool = False


@dataclass(frozen=True, slots=True)
class Association:
    """What became of one accepted measurement in its scan."""

    sensor_id: str
    t_ns: int
    seq: int
    outcome: str  # "updated" | "born" | "unassigned" (gated but lost) | "capacity" (no room)
    track_id: int | None
    nis: float | None
    gated: tuple[int, ...]  # tracks in whose gate it fell


@dataclass(frozen=True, slots=True)
class Replay:
    """A late measurement (or several) rewound the tracker to from_t_ns and replayed n_scans."""

    from_t_ns: int
    n_scans: int
    trigger: tuple[tuple[str, int], ...]  # (sensor_id, seq) of the late measurements


@dataclass(frozen=True)
class StepResult:
    """Everything one call to Tracker.process did."""

    estimates: tuple[Estimate, ...]
    events: tuple[TrackEvent, ...]
    refused: tuple[Refusal, ...]
    applied: int
    replays: tuple[Replay, ...]
    associations: tuple[Association, ...]
    measurements: tuple[MeasuredPoint, ...] = ()


@dataclass
class _Entry:
    key: ScanKey
    dets: tuple[Detection, ...]
    before: TrackSet
    scan_idx: int
    emitted: dict[int, tuple[int, bytes, bool]] = field(default_factory=dict)  # id -> (revision, signature, alive)
    events: frozenset[tuple[str, int]] = frozenset()  # (kind, track id) of the events this scan produced


@dataclass(frozen=True, slots=True)
class _ScanOut:
    after: TrackSet
    estimates: list[Estimate]
    events: list[TrackEvent]
    associations: list[Association]


class Tracker:
    """Tracks many targets from many sensors; see the module docstring for the algorithm."""

    def __init__(self, config: TrackerConfig) -> None:
        if not config.sensors:
            raise ConfigError("a tracker needs at least one sensor")
        self.config = config
        self.motion = motion_model(config.motion)
        self.filter = make_filter(config.motion)
        self.layout = layout(config.motion)
        self.model_name = config.motion.model
        self.sensors: dict[str, SensorModel] = sensor_models(config, self.motion)
        self._pos_idx = tuple(self.motion.position_indices)
        self._vel_idx = tuple(self.motion.velocity_indices)
        self._n = self.motion.ndim_state
        self._init_diag = initial_covariance_diag(config, self._n, self.motion)
        self._gate = {m: float(chdtri(m, 1.0 - config.gate.probability)) for m in range(1, 7)}
        self._k = config.gate.coarse_margin * np.sqrt(max(self._gate.values()))
        q = config.motion.q_high_mps2 if config.motion.model == "imm_cv" else config.motion.q_mps2
        self._q2 = float(q) ** 2
        lc, tc = config.lifecycle, config.time
        self._lag_ns = round(tc.lag_s * NS_PER_S)
        self._future_ns = round(tc.future_s * NS_PER_S)
        self._coast_ns = round(lc.coast_s * NS_PER_S)
        self._ts = TrackSet((), None, pos_idx=self._pos_idx, vel_idx=self._vel_idx)
        self._hist: list[_Entry] = []
        self._keys: list[ScanKey] = []
        self._base: ScanKey | None = None  # key of the newest scan dropped from the history
        self._next_scan = 0
        self._newest_ns: int | None = None
        self._seen: dict[tuple[str, int], int] = {}  # (sensor_id, seq) -> t_ns, inside the window
        self.counts: Counter[str] = Counter()
        # Built-in motion models broadcast over a stack of tracks: gate every candidate pair of a
        # scan in one vectorised predict + update instead of one filter call per pair.
        self._batched = isinstance(self.filter, ExtendedKalmanFilter) and isinstance(
            self.motion, ConstantVelocity | ConstantAcceleration | CoordinatedTurn)

    # ---- public views -------------------------------------------------------------------
    @property
    def tracks(self) -> tuple[Track, ...]:
        """The live tracks, in a deterministic order."""
        return self._ts.tracks

    @property
    def newest_t_ns(self) -> int | None:
        return self._newest_ns

    @property
    def history_len(self) -> int:
        return len(self._hist)

    def confirmed(self) -> tuple[Track, ...]:
        return tuple(t for t in self._ts.tracks if t.status == Status.CONFIRMED)

    # ---- intake -------------------------------------------------------------------------
    def _validate(self, d: Detection) -> Refusal | None:
        def no(reason: Reason, detail: str) -> Refusal:
            return Refusal(d.sensor_id, d.t_ns, d.seq, reason, detail)

        sm = self.sensors.get(d.sensor_id)
        if sm is None:
            return no(Reason.UNKNOWN_SENSOR, f"sensor {d.sensor_id!r} is not configured")
        if not isinstance(d.t_ns, int) or not isinstance(d.seq, int) or d.seq < 0:
            return no(Reason.INVALID, "t_ns and seq must be integers, seq >= 0")
        z = d.z
        if z.ndim != 1 or sm.model(z.shape[0]) is None:
            return no(Reason.INVALID, f"z has shape {z.shape}; sensor {d.sensor_id} takes lengths {sorted(sm.by_dim)}")
        if not np.isfinite(z).all():
            return no(Reason.INVALID, "z holds NaN or inf")
        if sm.config.kind == "radar" and not z[0] > 0:
            return no(Reason.INVALID, f"range must be > 0, got {z[0]}")
        if d.R is not None:
            R = d.R
            m = z.shape[0]
            if R.shape != (m, m) or not np.isfinite(R).all():
                return no(Reason.BAD_COVARIANCE, f"R must be a finite {m}x{m} matrix, got shape {R.shape}")
            if np.abs(R - R.T).max() > 1e-9 * max(np.abs(R).max(), 1e-300):
                return no(Reason.BAD_COVARIANCE, "R is not symmetric")
            try:
                np.linalg.cholesky(R)
            except np.linalg.LinAlgError:
                return no(Reason.BAD_COVARIANCE, "R is not positive definite")
        return None

    def _admit(self, d: Detection) -> Refusal | None:
        bad = self._validate(d)
        if bad is not None:
            return bad
        if (d.sensor_id, d.seq) in self._seen:
            return Refusal(d.sensor_id, d.t_ns, d.seq, Reason.DUPLICATE, f"seq {d.seq} of {d.sensor_id} seen before")
        if self._newest_ns is not None:
            if d.t_ns > self._newest_ns + self._future_ns:
                return Refusal(d.sensor_id, d.t_ns, d.seq, Reason.FUTURE,
                               f"{(d.t_ns - self._newest_ns) / 1e9:.3f} s ahead of the newest time")
            behind_base = self._base is not None and (d.t_ns, d.sensor_id) <= self._base
            if d.t_ns < self._newest_ns - self._lag_ns or behind_base:
                return Refusal(d.sensor_id, d.t_ns, d.seq, Reason.TOO_LATE,
                               f"{(self._newest_ns - d.t_ns) / 1e9:.3f} s behind the newest time, "
                               "outside the out-of-order window")
        return None

    def process(self, detections: Iterable[Detection]) -> StepResult:
        """Take measurements (any order, any mix of sensors); return what changed."""
        refused: list[Refusal] = []
        accepted: list[Detection] = []
        for d in detections:
            self.counts["received"] += 1
            r = self._admit(d)
            if r is not None:
                refused.append(r)
                self.counts[f"refused_{r.reason.value}"] += 1
                continue
            accepted.append(d)
            self._seen[(d.sensor_id, d.seq)] = d.t_ns
            if self._newest_ns is None or d.t_ns > self._newest_ns:
                self._newest_ns = d.t_ns
        self.counts["applied"] += len(accepted)
        if not accepted:
            return StepResult((), (), tuple(refused), 0, (), ())

        by_key: dict[ScanKey, list[Detection]] = {}
        for d in accepted:
            by_key.setdefault((d.t_ns, d.sensor_id), []).append(d)
        start = min(bisect.bisect_left(self._keys, k) for k in by_key)
        newest_key = self._keys[-1] if self._keys else None
        late = tuple(sorted((d.sensor_id, d.seq) for d in accepted
                            if newest_key is not None and (d.t_ns, d.sensor_id) < newest_key))

        # The scans to (re)run from `start`: old ones merged with the new measurements.
        old = self._hist[start:]
        old_by_key = {e.key: e for e in old}
        keys = sorted(set(self._keys[start:]) | set(by_key))
        ts = old[0].before if old else self._ts
        scan_idx = old[0].scan_idx if old else self._next_scan
        replays: list[Replay] = []
        if late:  # a true replay: scans before the newest one are run again
            replays.append(Replay(keys[0][0], len(keys), late))
            self.counts["replays"] += 1
            self.counts["replayed_scans"] += len(old)
            self.counts["late_applied"] += len(late)
        elif old:  # more measurements of the newest scan: that scan alone is run again
            self.counts["rescans"] += 1
        before_ids = set(self._ts.ids.tolist())
        del self._hist[start:]
        del self._keys[start:]

        estimates: list[Estimate] = []
        events: list[TrackEvent] = []
        assoc: list[Association] = []
        deleted_ids: set[int] = set()
        for key in keys:
            prev = old_by_key.get(key)
            dets = list(prev.dets) if prev else []
            dets.extend(by_key.get(key, ()))
            dets.sort(key=lambda d: d.seq)
            entry = _Entry(key, tuple(dets), ts, scan_idx)
            out = self._scan(ts, scan_idx, key, entry.dets)
            replayed = prev is not None
            estimates.extend(self._revise(entry, prev, out.estimates))
            entry.events = frozenset((ev.kind, ev.track_id) for ev in out.events)
            for ev in out.events:
                if ev.kind == "deleted":
                    deleted_ids.add(ev.track_id)
                if prev is not None and (ev.kind, ev.track_id) in prev.events:
                    continue  # reported when the scan first ran
                events.append(TrackEvent(ev.kind, ev.track_id, ev.t_ns, ev.detail, replayed) if replayed else ev)
            assoc.extend(out.associations)
            self._hist.append(entry)
            self._keys.append(key)
            ts = out.after
            scan_idx += 1
        self._ts = ts
        self._next_scan = scan_idx
        if old:
            after_ids = set(ts.ids.tolist())
            for tid in sorted(before_ids - after_ids - deleted_ids):
                events.append(TrackEvent("retracted", tid, keys[0][0], "gone after a replay", True))
        self._prune()
        points = tuple(
            MeasuredPoint(d.sensor_id, d.t_ns, d.seq, self.sensors[d.sensor_id].by_dim[d.z.shape[0]].position(d.z))
            for d in accepted
        )
        return StepResult(tuple(estimates), tuple(events), tuple(refused), len(accepted), tuple(replays), tuple(assoc),
                          points)

    # ---- revisions ----------------------------------------------------------------------
    @staticmethod
    def _signature(e: Estimate) -> bytes:
        return e.x.tobytes() + e.P.tobytes() + e.status.encode()

    def _revise(self, entry: _Entry, prev: _Entry | None, new: list[Estimate]) -> list[Estimate]:
        """Revision numbers: 0 the first time; +1 each time a replay changes or retracts it."""
        old = prev.emitted if prev else {}
        out: list[Estimate] = []
        seen: set[int] = set()
        for e in new:
            sig = self._signature(e)
            seen.add(e.track_id)
            o = old.get(e.track_id)
            if o is None:
                rev = 0
            elif o[2] and o[1] == sig:
                entry.emitted[e.track_id] = o
                continue
            else:
                rev = o[0] + 1
            entry.emitted[e.track_id] = (rev, sig, True)
            out.append(_with_revision(e, rev))
        for tid in sorted(old):
            if tid in seen:
                continue
            rev, sig, alive = old[tid]
            if alive:
                rev += 1
                out.append(Estimate(tid, entry.key[0], entry.key[1], -1, np.empty(0), np.empty((0, 0)),
                                    "retracted", rev, None, None, None))
            entry.emitted[tid] = (rev, sig, False)
        return out

    # ---- one scan ------------------------------------------------------------------------
    def _scan(self, ts: TrackSet, scan_idx: int, key: ScanKey, dets: tuple[Detection, ...]) -> _ScanOut:
        t_ns, sensor_id = key
        sm = self.sensors[sensor_id]
        M = len(dets)
        models = [sm.by_dim[d.z.shape[0]] for d in dets]
        Rs = [m.R if d.R is None else d.R for d, m in zip(dets, models, strict=True)]
        mpos = np.empty((M, sm.ndim))
        mvar = np.empty((M, sm.ndim))
        for j, (d, R) in enumerate(zip(dets, Rs, strict=True)):
            mpos[j], mvar[j] = sm.position_and_var(d.z, R)

        # 1-2. coarse then fine gate
        tpos, tvar = ts.predicted_position(t_ns, self._q2)
        ci, cj = coarse_pairs(tpos, tvar, mpos, mvar, k=self._k)
        if self._batched:
            ti, mj, cost, ups = self._gate_batched(ts, t_ns, ci, cj, dets, models, Rs)
        else:
            ti, mj, cost, ups = self._gate_each(ts, t_ns, ci, cj, dets, models, Rs)
        ti_a, mj_a = np.array(ti, dtype=np.intp), np.array(mj, dtype=np.intp)
        # 3. assignment (miss cost: half the largest gate, so a pair wins when NIS < gate)
        miss = 0.5 * self._gate[max(m.ndim_meas for m in models)]
        pairs = gnn_assign(ti_a, mj_a, np.array(cost), n_tracks=len(ts), n_meas=M, miss_cost=miss)
        pair_up = {(i, j): u for i, j, u in zip(ti, mj, ups, strict=True)}
        gated: dict[int, list[int]] = {}
        for i, j in zip(ti, mj, strict=True):
            gated.setdefault(j, []).append(int(ts.ids[i]))

        # 4. updates and births
        estimates: list[Estimate] = []
        events: list[TrackEvent] = []
        assoc: list[Association] = []
        replace: dict[int, Track] = {}
        lc = self.config.lifecycle
        assigned_meas: dict[int, int] = {}
        for i, j in pairs:
            tr = ts.tracks[i]
            up = pair_up[(i, j)]
            hits = tr.hits + 1
            status = tr.status
            if status == Status.TENTATIVE and hits >= lc.confirm_m and scan_idx - tr.birth_scan < lc.confirm_n:
                status = Status.CONFIRMED
                events.append(TrackEvent("confirmed", tr.id, t_ns))
            nt = Track(tr.id, up.state, status, hits, tr.birth_scan, scan_idx, tr.birth_t_ns, tr.origin)
            replace[i] = nt
            assigned_meas[j] = i
            estimates.append(self._estimate(nt, dets[j], up, mpos[j]))
        born: list[Track] = []
        capacity = lc.max_tracks - len(ts)
        for j, d in enumerate(dets):
            if j in assigned_meas:
                i = assigned_meas[j]
                assoc.append(Association(d.sensor_id, d.t_ns, d.seq, "updated", int(ts.ids[i]),
                                         pair_up[(i, j)].nis, tuple(gated.get(j, ()))))
                continue
            if j in gated:
                assoc.append(Association(d.sensor_id, d.t_ns, d.seq, "unassigned", None, None, tuple(gated[j])))
                continue
            if len(born) >= capacity:
                self.counts["births_refused_capacity"] += 1
                assoc.append(Association(d.sensor_id, d.t_ns, d.seq, "capacity", None, None, ()))
                continue
            nt = self._birth(d, models[j], Rs[j], sm, scan_idx)
            born.append(nt)
            events.append(TrackEvent("born", nt.id, t_ns))
            if nt.status == Status.CONFIRMED:  # confirm_m == 1: the first hit confirms
                events.append(TrackEvent("confirmed", nt.id, t_ns))
            assoc.append(Association(d.sensor_id, d.t_ns, d.seq, "born", nt.id, None, ()))
            estimates.append(self._estimate(nt, d, None, mpos[j]))

        # 5. lifecycle sweep over the tracks that existed before this scan (vectorised)
        after = ts.derive(replace, [], None, pos_idx=self._pos_idx, vel_idx=self._vel_idx)
        delete = None
        if len(after):
            scans_seen = scan_idx - after.birth_scan + 1
            tent = after.status == Status.TENTATIVE
            conf = ~tent
            _, pvar = after.predicted_position(t_ns, self._q2)
            too_wide = pvar.max(axis=1) > lc.max_position_std_m**2
            missed = (scan_idx - after.last_hit_scan) > lc.max_misses
            coasted = (t_ns - after.t_ns) > self._coast_ns
            drop_tent = tent & (scans_seen >= lc.confirm_n) & (after.hits < lc.confirm_m)
            drop_conf = conf & (missed | coasted | too_wide)
            delete = drop_tent | drop_conf | (tent & (coasted | too_wide))
            for i in np.flatnonzero(delete):
                why = ("not confirmed" if drop_tent[i] else "misses" if missed[i] else "coasted" if coasted[i]
                       else "covariance")
                events.append(TrackEvent("deleted", int(after.ids[i]), t_ns, why))
        after = after.derive({}, born, delete, pos_idx=self._pos_idx, vel_idx=self._vel_idx)
        estimates.sort(key=lambda e: e.track_id)
        return _ScanOut(after, estimates, events, assoc)

    def _gate_each(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, dets: tuple[Detection, ...],
                   models: list, Rs: list) -> tuple[list[int], list[int], list[float], list[Update]]:
        """Fine gate, one filter predict + update per candidate pair (any filter, IMM included)."""
        preds: dict[int, GaussianState | IMMState] = {}
        ti: list[int] = []
        mj: list[int] = []
        cost: list[float] = []
        ups: list[Update] = []
        for i, j in zip(ci.tolist(), cj.tolist(), strict=True):
            pred = preds.get(i)
            if pred is None:
                pred = preds[i] = self.filter.predict(ts.tracks[i].state, t_ns)  # type: ignore[arg-type]
            try:
                up = self.filter.update(pred, dets[j].z, models[j], R=Rs[j])  # type: ignore[arg-type]
            except NumericalError:
                self.counts["numerical_skips"] += 1
                continue
            if up.nis <= self._gate[models[j].ndim_meas]:
                ti.append(i)
                mj.append(j)
                cost.append(up.nis)
                ups.append(up)
        return ti, mj, cost, ups

    def _gate_batched(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, dets: tuple[Detection, ...],
                      models: list, Rs: list) -> tuple[list[int], list[int], list[float], list[Update]]:
        """Fine gate for every candidate pair at once: the EKF equations of fusion.core.kalman on
        stacks, grouped by measurement dimension. Same math as `_gate_each`."""
        ti: list[int] = []
        mj: list[int] = []
        cost: list[float] = []
        ups: list[Update] = []
        if ci.size == 0:
            return ti, mj, cost, ups
        m = self.motion
        X = np.stack([ts.tracks[i].state.x for i in ci.tolist()])
        P = np.stack([ts.tracks[i].state.P for i in ci.tolist()])
        dt = (t_ns - ts.t_ns[ci]) * 1e-9
        F = m.jacobian(X, dt)
        Xp, Pp = predict_arrays(X, P, F, m.Q(X, dt), None if m.is_linear else m.f(X, dt))
        dims = np.array([models[j].ndim_meas for j in cj.tolist()])
        keep: list[tuple[int, int, float, Update]] = []
        for dim in np.unique(dims):
            sel = np.flatnonzero(dims == dim)
            js = cj[sel]
            # One model of this dimension per sensor: models differ only by R, given per pair.
            model = models[int(js[0])]
            Z = np.stack([dets[j].z for j in js.tolist()])
            R = np.stack([Rs[j] for j in js.tolist()])
            Xs, Ps = Xp[sel], Pp[sel]
            Y = model.residual(Z, model.h(Xs))
            H = model.jacobian(Xs)
            try:
                Xn, Pn, S, nis, ll = update_arrays(Xs, Ps, Y, H, R)
            except NumericalError:  # one bad pair: fall back to pair by pair for this group
                sub_ti, sub_mj, sub_c, sub_u = self._gate_each(ts, t_ns, ci[sel], js, dets, models, Rs)
                keep.extend(zip(sub_ti, sub_mj, sub_c, sub_u, strict=True))
                continue
            ok = np.flatnonzero(nis <= self._gate[int(dim)])
            for k in ok.tolist():
                p = sel[k]
                up = Update(GaussianState(Xn[k].copy(), Pn[k].copy(), t_ns), Y[k].copy(), S[k].copy(),
                            float(nis[k]), float(ll[k]))
                keep.append((int(ci[p]), int(cj[p]), float(nis[k]), up))
        keep.sort(key=lambda r: (r[1], r[0]))
        for i, j, c, up in keep:
            ti.append(i)
            mj.append(j)
            cost.append(c)
            ups.append(up)
        return ti, mj, cost, ups

    def _birth(self, d: Detection, model: object, R: np.ndarray, sm: SensorModel, scan_idx: int) -> Track:
        p = sm.by_dim[d.z.shape[0]].position(d.z)
        Ppos = sm.position_cov(d.z, R)
        x = np.zeros(self._n)
        pi = list(self._pos_idx)
        x[pi] = p
        P = np.diag(self._init_diag)
        P[np.ix_(pi, pi)] = Ppos
        tid = track_id_for(d.sensor_id, d.seq, d.t_ns)
        if isinstance(self.filter, IMM):
            state: GaussianState | IMMState = self.filter.initial(x, P, t_ns=d.t_ns)
        else:  # x and P are built from validated input: no need to check them again
            state = GaussianState(x, 0.5 * (P + P.T), d.t_ns)
        status = Status.CONFIRMED if self.config.lifecycle.confirm_m <= 1 else Status.TENTATIVE
        return Track(tid, state, status, 1, scan_idx, scan_idx, d.t_ns, (d.sensor_id, d.seq))

    def _estimate(self, tr: Track, d: Detection, up: Update | None, meas_pos: np.ndarray) -> Estimate:
        st = tr.state
        mu = st.mu if isinstance(st, IMMState) else None
        return Estimate(
            tr.id, st.t_ns, d.sensor_id, d.seq, st.x, st.P, tr.status.label, 0,
            None if up is None else up.nis, None if up is None else up.y, None if up is None else up.S, mu,
            meas_pos.copy(),
        )

    # ---- bounded memory ----------------------------------------------------------------
    def _prune(self) -> None:
        if self._newest_ns is None:
            return
        horizon = self._newest_ns - self._lag_ns
        cap = self.config.time.max_lag_scans
        drop = 0
        while drop < len(self._hist) and (self._keys[drop][0] < horizon or len(self._hist) - drop > cap):
            drop += 1
        if drop:
            self._base = self._keys[drop - 1]
            for e in self._hist[:drop]:  # their (sensor, seq) now fall under too_late
                for d in e.dets:
                    self._seen.pop((d.sensor_id, d.seq), None)
            del self._hist[:drop]
            del self._keys[:drop]


def _with_revision(e: Estimate, rev: int) -> Estimate:
    if e.revision == rev:
        return e
    return Estimate(e.track_id, e.t_ns, e.sensor_id, e.seq, e.x, e.P, e.status, rev, e.nis, e.y, e.S,
                    e.mode_probabilities, e.meas_pos)
