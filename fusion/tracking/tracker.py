"""The multi-target, multi-sensor tracker: measurements in, what happened out. No I/O, no clock.

    process(detections):
        admit each detection, in arrival order            (intake: valid, in the window, new)
        group the admitted ones into scans (t_ns, sensor_id)
        rewind to the checkpoint before the earliest scan they touch        (history)
        for each scan from there, in (t_ns, sensor_id) order, old detections merged with new:
            outcome = run_scan(track set, scan)                             (scan)
                      a scan run before is run again only where the late data reach:
                      the coarse-gate components of changed tracks and new detections;
                      the rest keeps its stored results, bit for bit      (replay)
            report its estimates and events as revisions of what it reported before
                      (a step's withdrawals before its new events: withdrawals_first)
        commit the scans that fell behind the window                        (history, intake)

Processing order is total: scans by (t_ns, sensor_id), detections of a scan by seq and epoch. So the
tracks, and what a consumer holds after applying revisions and withdrawals, depend only on the
set of accepted measurements, never on their arrival order or batching.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from scipy.special import chdtri

from fusion.config import TrackerConfig
from fusion.errors import ConfigError
from fusion.tracking.batched_gating import make_gater
from fusion.tracking.checkpoint import TrackerState, restore, state_of
from fusion.tracking.controls import InputTimeline
from fusion.tracking.detection import ControlInput, Detection, Reason, Refusal
from fusion.tracking.history import Entry, History, Rewind, revise, revise_associations, revise_events
from fusion.tracking.intake import Intake
from fusion.tracking.lifecycle import Lifecycle
from fusion.tracking.models import initial_covariance_diag, layout, make_filter, motion_model, sensor_models
from fusion.tracking.replay import Hint, Partial, Stored, gates_of_run, rerun
from fusion.tracking.results import (
    Counts,
    DeletionReason,
    Estimate,
    Replay,
    ScanKey,
    ScanPoints,
    StepResult,
    TrackEvent,
)
from fusion.tracking.scan import ScanContext, Tally, run_scan
from fusion.tracking.step_order import merged, merged_seqs, new_points, withdrawals_first
from fusion.tracking.trackset import Layout, Rows, Status, Track, TrackSet

_NO_IDS = np.empty(0, dtype=np.int64)  # no tracks kept: a scan run whole


class Tracker:
    """Tracks many targets from many sensors; see the module docstring for the algorithm."""

    def __init__(self, config: TrackerConfig, *, selective_replay: bool = True) -> None:
        """selective_replay: replay late data only where it reaches (fusion.tracking.replay);
        False replays every scan whole (the reference it is tested against)."""
        if not config.sensors:
            raise ConfigError("a tracker needs at least one sensor")
        self.config = config
        self.selective = selective_replay
        control = config.control is not None
        self.motion = motion_model(config.motion, control=control)
        self.filter = make_filter(config.motion, self.motion)
        self.inputs = InputTimeline(self.motion, config.motion.ndim) if control else None  # type: ignore[arg-type]
        self.layout = layout(config.motion, self.motion)
        self.model_name = config.motion.model
        self.sensors = sensor_models(config, self.motion)
        self.position_indices = tuple(self.motion.position_indices)
        self.velocity_indices = tuple(self.motion.velocity_indices)
        gate = {m: float(chdtri(m, 1.0 - config.gate.probability)) for m in range(1, 7)}
        # the coarse gate's noise density; for "ca" its jerk density, as before the field was named so
        mc = config.motion
        q2 = max([(mc.jerk_psd_m2s5 or 0.0) if mc.model == "ca" else mc.accel_psd_m2s3]
                 + [x.accel_psd_m2s3 for x in mc.modes])
        self.ctx = ScanContext(
            sensors=self.sensors, filter=self.filter, gater=make_gater(self.filter, gate, self.inputs),
            lifecycle=Lifecycle(config.lifecycle, q2),
            init_diag=initial_covariance_diag(config, self.motion.ndim_state, self.motion),
            pos_idx=self.position_indices, coarse_k=config.gate.coarse_margin * float(np.sqrt(max(gate.values()))),
            q2=q2, max_tracks=config.lifecycle.max_tracks,
        )
        source = config.control.source_id if config.control is not None else None
        self.intake = Intake(self.sensors, config.time, control_source=source, control_dim=config.motion.ndim)
        self.history = History()
        self._ts = TrackSet.start(Layout(self.position_indices, self.velocity_indices, tuple(sorted(self.sensors)),
                                         self.motion.ndim_state, len(getattr(self.filter, "filters", ()))))
        # the counters behind `counts` (and a checkpoint): intake, refusals, arrivals
        self.intake_counts = {"received": 0, "applied": 0, "inputs": 0, "inputs_refused": 0}
        self.refused_counts: dict[Reason, int] = {}
        self.arrival_counts = {"replays": 0, "replayed_scans": 0, "rescans": 0, "late_applied": 0}

    # ---- checkpoints ------------------------------------------------------------------------
    def state(self) -> TrackerState:
        """Everything needed to resume (fusion.tracking.checkpoint)."""
        return state_of(self)

    @classmethod
    def resume(cls, config: TrackerConfig, state: TrackerState) -> Tracker:
        """The tracker that wrote `state`; ConfigError if `state` is not of this configuration."""
        tr = cls(config)
        restore(tr, state)
        return tr

    def restore_rows(self, rows: Rows) -> None:
        self._ts = TrackSet(rows, self._ts.layout)

    # ---- views ------------------------------------------------------------------------------
    @property
    def tracks(self) -> tuple[Track, ...]:
        """The live tracks, in a deterministic order."""
        return self._ts.tracks

    @property
    def track_set(self) -> TrackSet:
        return self._ts

    def confirmed(self) -> tuple[Track, ...]:
        ts = self._ts
        return tuple(ts.track(i) for i in range(len(ts)) if ts.status[i] == Status.CONFIRMED)

    @property
    def newest_scan(self) -> ScanKey | None:
        """The newest scan run, (t_ns, sensor_id): a measurement of an earlier scan is late (its
        arrival replays the scans from its own)."""
        return self.history.newest or self.intake.committed

    @property
    def now_ns(self) -> int | None:
        """The stream's clock (sensor time) at the last admission; see fusion.tracking.intake."""
        return self.intake.now_ns

    @property
    def horizon_ns(self) -> int | None:
        """Sensor time before which nothing can change any more (the window's start)."""
        return self.intake.horizon_ns

    @property
    def counts(self) -> Counts:
        t = self.history.tally()
        return Counts(
            received=self.intake_counts["received"], applied=self.intake_counts["applied"],
            inputs=self.intake_counts["inputs"], inputs_refused=self.intake_counts["inputs_refused"],
            refused=dict(sorted(self.refused_counts.items())), updates=t[Tally.UPDATES], births=t[Tally.BIRTHS],
            births_refused_capacity=t[Tally.BIRTHS_REFUSED_CAPACITY], unassigned=t[Tally.UNASSIGNED],
            confirmations=t[Tally.CONFIRMATIONS], numerical_skips=t[Tally.NUMERICAL_SKIPS],
            deletions={r: t[r] for r in DeletionReason if t[r]}, **self.arrival_counts,
        )

    def predict(self, t_ns: int) -> list[Estimate]:
        """Every confirmed track predicted to t_ns, with its covariance (status "predicted";
        sensor and seq of its last update). A track updated after t_ns is not predicted
        backwards: it is given at its last update (status "confirmed")."""
        ts = self._ts
        conf = np.flatnonzero(ts.status == Status.CONFIRMED.value)
        ahead = conf[ts.t_ns[conf] <= t_ns]
        X, P, mu = self.ctx.gater.predict(ts, t_ns, ahead)
        names = ts.layout.sensors
        out = [Estimate(int(ts.ids[i]), t_ns, names[int(ts.last_sensor[i])], int(ts.last_seq[i]), X[k], P[k],
                        "predicted", 0, None, None if mu is None else mu[k])
               for k, i in enumerate(ahead.tolist())]
        for i in conf[ts.t_ns[conf] > t_ns].tolist():
            st = ts.state(i)
            out.append(Estimate(int(ts.ids[i]), st.t_ns, names[int(ts.last_sensor[i])], int(ts.last_seq[i]), st.x,
                                st.P, "confirmed", 0, None, getattr(st, "mu", None)))
        return sorted(out, key=lambda e: e.track_id)

    # ---- the algorithm ----------------------------------------------------------------------
    def process(self, items: Iterable[Detection | ControlInput]) -> StepResult:
        """Take measurements and control inputs (any order, any mix of sensors); return what
        changed."""
        accepted, inputs, refused = self._admit(items)
        if not accepted and not inputs:
            return StepResult((), (), tuple(refused), 0, (), (), horizon_ns=self.horizon_ns)
        scans: dict[ScanKey, list[Detection]] = {}
        for d in accepted:
            scans.setdefault((d.t_ns, d.sensor_id), []).append(d)
        for c in inputs:
            self.inputs.add(c.t_ns, c.seq, c.u)  # type: ignore[union-attr]
        newest = self.history.newest
        rw = self.history.rewind(set(scans), self._ts, touched={(c.t_ns, c.source_id) for c in inputs})
        replays = self._count_arrival(accepted, inputs, newest, rw)

        estimates: list[Estimate] = []
        events: list[TrackEvent] = []
        assoc = []
        points: list[ScanPoints] = []
        ts = rw.start
        hint = None
        for key in rw.keys:
            prev = rw.old.get(key)
            arrived = scans.get(key)
            dets = merged(prev, arrived)
            seqs = merged_seqs(prev, arrived, dets)
            part = self._rerun(ts, key, dets, seqs, prev, rw.after.get(key), hint)
            out = part.outcome if part is not None else run_scan(ts, key, dets, self.ctx, det_seqs=seqs)
            kept = part.kept if part is not None else _NO_IDS
            hint = part.hint if part is not None else None
            gates = part.gates if part is not None else gates_of_run(ts, seqs, out)
            if arrived:
                points.append(new_points(key, dets, arrived, prev is not None, out.positions,
                                         None if gates is None else gates.det_seqs))
            entry = Entry(key, dets, ts, tally=out.tally, associations=out.associations, gates=gates)
            estimates.extend(revise(entry, prev, out.estimates, kept, out.signatures))
            events.extend(revise_events(entry, prev, out.events, kept))
            assoc.append(revise_associations(prev, out.associations))
            self.history.append(entry)
            ts = out.after
        self._ts = ts
        self._commit()
        return StepResult(tuple(estimates), withdrawals_first(events), tuple(refused), len(accepted), replays,
                          tuple(assoc), tuple(points), self.horizon_ns)

    def _rerun(self, ts: TrackSet, key: ScanKey, dets: tuple[Detection, ...], seqs: np.ndarray, prev: Entry | None,
               after: TrackSet | None, hint: Hint | None) -> Partial | None:
        """A scan run before, run again in part (fusion.tracking.replay), or None: run it whole
        (a new scan; full replay chosen; control inputs, which move every track's prediction)."""
        if prev is None or after is None or not self.selective or self.inputs is not None:
            return None
        old = Stored(prev.before, after, prev.dets, prev.associations, prev.tally, prev.gates)
        return rerun(ts, key, dets, self.ctx, old, list(prev.events.values()), hint, seqs)

    def _admit(self, items: Iterable[Detection | ControlInput]
               ) -> tuple[list[Detection], list[ControlInput], list[Refusal]]:
        items = list(items)
        inputs: list[ControlInput] = []
        if not any(isinstance(d, ControlInput) for d in items):
            accepted, refused = self.intake.admit_many(items)  # type: ignore[arg-type]
        else:
            accepted, refused = [], []
            for d in items:
                if isinstance(d, ControlInput):
                    c, bad = self.intake.admit_input(d)
                    if c is not None:
                        inputs.append(c)
                    else:
                        self.intake_counts["inputs_refused"] += 1
                else:
                    ok, bad = self.intake.admit(d)
                    if ok is not None:
                        accepted.append(ok)
                if bad is not None:
                    refused.append(bad)
        for bad in refused:
            self.refused_counts[bad.reason] = self.refused_counts.get(bad.reason, 0) + 1
        self.intake_counts["received"] += len(items)
        self.intake_counts["applied"] += len(accepted)
        self.intake_counts["inputs"] += len(inputs)
        return accepted, inputs, refused

    def _count_arrival(self, accepted: list[Detection], inputs: list[ControlInput], newest: ScanKey | None,
                       rw: Rewind) -> tuple[Replay, ...]:
        late = sorted([(d.sensor_id, d.seq) for d in accepted if newest is not None and (d.t_ns, d.sensor_id) < newest]
                      + [(c.source_id, c.seq) for c in inputs if newest is not None and (c.t_ns, c.source_id) < newest])
        if late:  # a true replay: scans before the newest one are run again
            self.arrival_counts["replays"] += 1
            self.arrival_counts["replayed_scans"] += len(rw.old)
            self.arrival_counts["late_applied"] += len(late)
            return (Replay(rw.keys[0][0], len(rw.keys), tuple(late)),)
        if rw.old:  # more measurements of the newest scan: that scan alone is run again
            self.arrival_counts["rescans"] += 1
        return ()

    def _commit(self) -> None:
        """Drop the scans behind the window: their results are final."""
        h = self.intake.horizon_ns
        gone = self.history.prune(h if h is not None else -(2**63), self.config.time.max_lag_scans)
        for e in gone:
            self.intake.forget(e.dets)
        if gone:
            self.intake.commit(gone[-1].key)
        if self.inputs is not None and h is not None:
            self.intake.forget_inputs(self.inputs.forget_before(h))
