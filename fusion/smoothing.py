"""Fixed-interval smoothing of a replay's tracks, for review (`fusion replay --smooth`).

`Histories` is a pipeline sink (fusion.pipeline.Sink) that forwards everything to the sink it
wraps and keeps, per track, the final revision of every estimate (a higher revision replaces a
lower one of the same (track_id, t_ns, sensor_id); a retraction removes it), and the truth
samples. Only final revisions are kept, so what is smoothed does not depend on arrival order.

`smooth(histories, tracker)` runs the Rauch-Tung-Striebel smoother (fusion.core.smoother) over
each track that was ever confirmed, from its birth to its last estimate, in the scan order
(t_ns, sensor_id):
    C_k   = P_k|k F_k+1' P_k+1|k^-1
    x_k|N = x_k|k + C_k (x_k+1|N - x_k+1|k),   P_k|N = P_k|k + C_k (P_k+1|N - P_k+1|k) C_k'
with the predictions recomputed from the motion model between consecutive estimates
(`smoother.predictions`; for an IMM the moment-matched mixture of its modes weighted by the
estimate's mode probabilities, `smoother.imm_predictions`). With a control input the filter's
own prediction x_k+1|k (the estimate's prior_x, which holds B u of the inputs in force) is used
for the mean. UKF tracks are smoothed with the EKF's linearisation (see fusion.core.smoother).
Rows are reported at the track's confirmed estimates, beside the filtered ones, with the truth
matched the way the recording matches it: the nearest true target at the same time whose
position lies within a squared Mahalanobis distance MATCH_D2 of the filtered estimate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fusion.core.checks import Array
from fusion.core.smoother import imm_predictions, predictions, rts_smooth
from fusion.errors import NumericalError
from fusion.pipeline import Sink
from fusion.tracking.results import Estimate, EstimateKey, StepResult
from fusion.tracking.tracker import Tracker

MATCH_D2 = 100.0  # as the recording's truth matching (fusion.io.rerun_sink)


class Histories:
    """A sink that keeps every track's final estimates and the truth; see the module docstring."""

    def __init__(self, inner: Sink | None = None) -> None:
        self.inner = inner
        self.latest: dict[EstimateKey, Estimate] = {}
        self.truth: dict[int, dict[str, Array]] = {}  # t_ns -> target id -> state (the tracker's layout)

    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        for e in result.estimates:
            if e.status == "retracted":
                self.latest.pop(e.key, None)
            else:
                self.latest[e.key] = e
        if self.inner is not None:
            self.inner.log_step(result, arrival_ns=arrival_ns)

    def log_truths(self, truths: Sequence[tuple[str, int, Array]]) -> None:
        for target_id, t_ns, state in truths:
            self.truth.setdefault(t_ns, {})[target_id] = np.asarray(state, dtype=np.float64)
        if self.inner is not None:
            self.inner.log_truths(truths)

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        if self.inner is not None:
            self.inner.log_text(t_ns, text, level)

    def tracks(self) -> dict[int, list[Estimate]]:
        """Final estimates by track id (sorted), each track's in scan order (t_ns, sensor_id)."""
        out: dict[int, list[Estimate]] = {}
        for k in sorted(self.latest):
            out.setdefault(k[0], []).append(self.latest[k])
        return out


@dataclass(frozen=True)
class SmoothedTrack:
    """One track at its confirmed estimates: filtered and smoothed state and covariance, and the
    matched truth (NaN rows where none)."""

    track_id: int
    t_ns: Array  # (K,) int64
    x_filt: Array  # (K, n)
    P_filt: Array  # (K, n, n)
    x_smooth: Array
    P_smooth: Array
    truth: Array  # (K, n)


@dataclass(frozen=True)
class Smoothed:
    tracks: tuple[SmoothedTrack, ...]
    failed: tuple[tuple[int, str], ...]  # (track id, why) of tracks the smoother could not run on


def track_predictions(hist: Sequence[Estimate], tracker: Tracker) -> tuple[Array, Array, Array, Array, Array]:
    """x_filt, P_filt and the smoother's x_pred, P_pred, F of one track's estimates (in scan
    order) under the tracker's motion model (see the module docstring)."""
    x = np.stack([e.x for e in hist])
    P = np.stack([e.P for e in hist])
    filters = getattr(tracker.filter, "filters", None)
    if filters is not None:
        mu = np.stack([np.asarray(e.mode_probabilities, dtype=np.float64) for e in hist])
        x_pred, P_pred, F = imm_predictions(hist, [f.motion for f in filters], mu)
    else:
        x_pred, P_pred, F = predictions(hist, tracker.motion)
        if tracker.inputs is not None:  # the filter's own predicted mean, with B u
            for k, e in enumerate(hist[1:], start=1):
                if e.prior_x is not None:
                    x_pred[k] = e.prior_x
    return x, P, x_pred, P_pred, F


def _smooth_one(hist: list[Estimate], tracker: Tracker) -> tuple[Array, Array]:
    if len(hist) == 1:
        return hist[0].x[None], hist[0].P[None]
    return rts_smooth(*track_predictions(hist, tracker))


def _match(truth: dict[int, dict[str, Array]], t_ns: int, x: Array, P: Array, pi: list[int]) -> Array | None:
    cands = truth.get(t_ns)
    if not cands:
        return None
    T = np.stack([cands[k] for k in sorted(cands)])
    k = int(np.argmin(np.sum((T[:, pi] - x[pi]) ** 2, axis=1)))
    d = T[k, pi] - x[pi]
    return T[k] if float(d @ np.linalg.solve(P[np.ix_(pi, pi)], d)) < MATCH_D2 else None


def smooth(histories: Histories, tracker: Tracker) -> Smoothed:
    """Smooth every track that was ever confirmed (see the module docstring)."""
    pi = list(tracker.position_indices)
    out, failed = [], []
    for tid, hist in histories.tracks().items():
        rows = [k for k, e in enumerate(hist) if e.status == "confirmed"]
        if not rows:
            continue
        try:
            xs, Ps = _smooth_one(hist, tracker)
        except NumericalError as e:
            failed.append((tid, str(e)))
            continue
        n = xs.shape[1]
        truth = np.full((len(rows), n), np.nan)
        for i, k in enumerate(rows):
            m = _match(histories.truth, hist[k].t_ns, hist[k].x, hist[k].P, pi)
            if m is not None:
                truth[i] = m
        out.append(SmoothedTrack(tid, np.array([hist[k].t_ns for k in rows], dtype=np.int64),
                                 np.stack([hist[k].x for k in rows]), np.stack([hist[k].P for k in rows]),
                                 xs[rows], Ps[rows], truth))
    return Smoothed(tuple(out), tuple(failed))


def position_rmse(tracks: tuple[SmoothedTrack, ...], pos_idx: tuple[int, ...]) -> tuple[float | None, float | None]:
    """Position RMSE against the matched truth, filtered and smoothed, over the same rows:
    sqrt(mean_k |p_k - p_true,k|^2). None when no row has a truth."""
    ef, es = [], []
    pi = list(pos_idx)
    for t in tracks:
        ok = ~np.isnan(t.truth[:, 0])
        ef.append(t.x_filt[ok][:, pi] - t.truth[ok][:, pi])
        es.append(t.x_smooth[ok][:, pi] - t.truth[ok][:, pi])
    if not ef or sum(len(e) for e in ef) == 0:
        return None, None
    f, s = np.concatenate(ef), np.concatenate(es)
    return float(np.sqrt(np.mean(np.sum(f**2, axis=1)))), float(np.sqrt(np.mean(np.sum(s**2, axis=1))))
