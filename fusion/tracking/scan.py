"""One scan (all measurements of one sensor at one time): a pure function from a track set and
the scan's detections to the new track set and what happened.

  1. gate: constant-velocity coarse gate (fusion.core.association.coarse_pairs), then the fine
     gate of fusion.tracking.gating (NIS <= chi2_m(probability)), cost = NIS + ln det S;
  2. assign, confirmed tracks first: GNN over the confirmed tracks' pairs, then GNN over the
     tentative tracks' pairs with the measurements left (the initiator gets leftovers, as in
     Stone Soup's tracker), so a tentative track never takes a confirmed one's measurement;
  3. assigned tracks take their posterior (and may be confirmed); a measurement in no gate
     starts a tentative track, up to max_tracks;
  4. lifecycle: chances, misses and deletions (fusion.tracking.lifecycle).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from fusion.core.association import coarse_pairs, gnn_assign
from fusion.core.checks import Array
from fusion.core.gaussian import GaussianState
from fusion.core.imm import IMM, Filter, IMMState
from fusion.tracking.detection import Detection
from fusion.tracking.gating import Gated, Gater, Measured
from fusion.tracking.lifecycle import Lifecycle
from fusion.tracking.models import SensorModel
from fusion.tracking.results import (
    Association,
    DeletionReason,
    Estimate,
    EventKind,
    Outcome,
    ScanKey,
    TrackEvent,
)
from fusion.tracking.trackset import Status, Track, TrackSet, track_id_for


class Tally(StrEnum):
    """What a scan counts (deletions are counted by their DeletionReason)."""

    UPDATES = "updates"
    BIRTHS = "births"
    BIRTHS_REFUSED_CAPACITY = "births_refused_capacity"
    UNASSIGNED = "unassigned"
    CONFIRMATIONS = "confirmations"
    NUMERICAL_SKIPS = "numerical_skips"


@dataclass(frozen=True)
class ScanContext:
    """Everything a scan needs besides its data; built once by the tracker."""

    sensors: dict[str, SensorModel]
    filter: Filter
    gater: Gater
    lifecycle: Lifecycle
    init_diag: Array  # prior variances of the unmeasured state components
    pos_idx: tuple[int, ...]
    coarse_k: float  # the coarse gate's half-width in standard deviations
    q2: float  # the coarse gate's process noise (the largest of the model's)
    max_tracks: int


@dataclass(frozen=True)
class ScanOutcome:
    after: TrackSet
    estimates: list[Estimate]  # sorted by track id
    events: list[TrackEvent]
    associations: list[Association]
    tally: Counter[Tally | DeletionReason]


def run_scan(ts: TrackSet, key: ScanKey, dets: tuple[Detection, ...], ctx: ScanContext) -> ScanOutcome:
    """The scan `key` (see the module docstring); `dets` sorted by seq, R resolved."""
    t_ns, sensor_id = key
    sm = ctx.sensors[sensor_id]
    meas = Measured(tuple(d.z for d in dets), tuple(sm.by_dim[d.z.shape[0]] for d in dets),
                    tuple(d.R for d in dets))  # type: ignore[misc]
    mpos, mvar = _measured_points(sm, dets)
    tpos, tvar = ts.predicted_position(t_ns, ctx.q2)
    ci, cj = coarse_pairs(tpos, tvar, mpos, mvar, k=ctx.coarse_k)
    gated = ctx.gater.gate(ts, t_ns, ci, cj, meas)
    pairs = _assign_confirmed_first(gated, ts, len(dets))

    tally: Counter[Tally | DeletionReason] = Counter()
    tally[Tally.NUMERICAL_SKIPS] += gated.numerical_skips
    estimates: list[Estimate] = []
    events: list[TrackEvent] = []
    assoc: list[Association] = []
    replace: dict[int, Track] = {}
    taken: dict[int, int] = {}  # measurement -> pair
    for p in pairs:
        i, j = int(gated.ti[p]), int(gated.mj[p])
        tr, up, d = ts.tracks[i], gated.update(p), dets[j]
        hits = tr.hits + 1
        status = tr.status
        if ctx.lifecycle.confirms(status, hits, int(ts.chances[i]) + 1):
            status = Status.CONFIRMED
            events.append(TrackEvent(EventKind.CONFIRMED, tr.id, t_ns))
            tally[Tally.CONFIRMATIONS] += 1
        replace[i] = Track(tr.id, up.state, status, hits, tr.birth_t_ns, tr.origin, (d.sensor_id, d.seq))
        taken[j] = p
        estimates.append(Estimate(
            tr.id, t_ns, sensor_id, d.seq, up.state.x, up.state.P, status.label, 0, up.nis, up.y, up.S,
            _mu(up.state), mpos[j].copy(), up.prior_x, up.prior_P, up.H))
    tally[Tally.UPDATES] += len(pairs)

    gated_by: dict[int, list[int]] = {}
    for i, j in zip(gated.ti.tolist(), gated.mj.tolist(), strict=True):
        gated_by.setdefault(j, []).append(int(ts.ids[i]))
    born: list[Track] = []
    room = ctx.max_tracks - len(ts)
    for j, d in enumerate(dets):
        near = tuple(gated_by.get(j, ()))
        if j in taken:
            p = taken[j]
            assoc.append(Association(sensor_id, t_ns, d.seq, Outcome.UPDATED, int(ts.ids[gated.ti[p]]),
                                     float(gated.nis[p]), near))
        elif near:
            assoc.append(Association(sensor_id, t_ns, d.seq, Outcome.UNASSIGNED, None, None, near))
            tally[Tally.UNASSIGNED] += 1
        elif len(born) >= room:
            assoc.append(Association(sensor_id, t_ns, d.seq, Outcome.CAPACITY, None, None, ()))
            tally[Tally.BIRTHS_REFUSED_CAPACITY] += 1
        else:
            nt = _birth(d, sm, ctx)
            born.append(nt)
            events.append(TrackEvent(EventKind.BORN, nt.id, t_ns))
            tally[Tally.BIRTHS] += 1
            if nt.status == Status.CONFIRMED:  # confirm_m == 1: the first hit confirms
                events.append(TrackEvent(EventKind.CONFIRMED, nt.id, t_ns))
                tally[Tally.CONFIRMATIONS] += 1
            assoc.append(Association(sensor_id, t_ns, d.seq, Outcome.BORN, nt.id, None, ()))
            estimates.append(Estimate(nt.id, t_ns, sensor_id, d.seq, nt.state.x, nt.state.P, nt.status.label, 0,
                                      None, None, None, _mu(nt.state), mpos[j].copy()))

    updated = ts.derive(replace=replace)
    hit = np.zeros(len(ts), dtype=bool)
    hit[list(replace)] = True
    sweep = ctx.lifecycle.sweep(ts, updated, hit, sm, t_ns)
    for ev in sweep.events:
        tally[ev.reason] += 1  # type: ignore[index]
    events.extend(sweep.events)
    after = updated.derive(counters=sweep.counters, delete=sweep.delete, born=tuple(born), born_sensor=sm.index)
    estimates.sort(key=lambda e: e.track_id)
    return ScanOutcome(after, estimates, events, assoc, tally)


def _assign_confirmed_first(g: Gated, ts: TrackSet, n_meas: int) -> list[int]:
    """Pair indices assigned: GNN over confirmed tracks, then over tentative tracks and the
    measurements the first stage left."""
    if g.ti.size == 0:
        return []
    conf = ts.status[g.ti] == Status.CONFIRMED
    out: list[int] = []
    taken = np.zeros(n_meas, dtype=bool)
    for stage in (conf, ~conf):
        sel = np.flatnonzero(stage & ~taken[g.mj])
        if sel.size == 0:
            continue
        chosen = gnn_assign(g.ti[sel], g.mj[sel], g.cost[sel], g.limit[sel], n_tracks=len(ts), n_meas=n_meas)
        index = {(int(g.ti[p]), int(g.mj[p])): int(p) for p in sel.tolist()}
        for i, j in chosen:
            out.append(index[(i, j)])
            taken[j] = True
    return sorted(out, key=lambda p: (int(g.mj[p]), int(g.ti[p])))


def _measured_points(sm: SensorModel, dets: tuple[Detection, ...]) -> tuple[Array, Array]:
    mpos = np.empty((len(dets), sm.ndim))
    mvar = np.empty((len(dets), sm.ndim))
    for j, d in enumerate(dets):
        mpos[j], mvar[j] = sm.position_and_var(d.z, d.R)  # type: ignore[arg-type]
    return mpos, mvar


def _birth(d: Detection, sm: SensorModel, ctx: ScanContext) -> Track:
    """Single-point initiation: position and its covariance from the measurement, the rest from
    the configured prior (zero mean)."""
    pi = list(ctx.pos_idx)
    x = np.zeros(ctx.init_diag.shape[0])
    x[pi] = sm.by_dim[d.z.shape[0]].position(d.z)
    P = np.diag(ctx.init_diag)
    P[np.ix_(pi, pi)] = sm.position_cov(d.z, d.R)  # type: ignore[arg-type]
    P = 0.5 * (P + P.T)
    # x and P are built from validated input: a plain state needs no further checks
    state: GaussianState | IMMState = (ctx.filter.initial(x, P, t_ns=d.t_ns) if isinstance(ctx.filter, IMM)
                                       else GaussianState(x, P, d.t_ns))
    tid = track_id_for(d.sensor_id, d.seq, d.t_ns)
    origin = (d.sensor_id, d.seq)
    return Track(tid, state, ctx.lifecycle.born_status(), 1, d.t_ns, origin, origin)


def _mu(state: GaussianState | IMMState) -> Array | None:
    return state.mu if isinstance(state, IMMState) else None
