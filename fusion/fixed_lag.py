"""Fixed-lag smoothing in the service: x_k|k+L of every confirmed track, L estimates behind.

With `[publication] smooth_lag = L` (L >= 1 estimates), once a track has L estimates after its
k-th, the service publishes the RTS smoothing of estimate k over the window k .. k + L (fusion.core
.smoother; predictions as in fusion.smoothing.track_predictions):
    x_k|k+L, P_k|k+L   from the backward pass C_j = P_j|j F_j+1' P_j+1|j^-1, j = k+L-1 .. k
on `fusion/<ns>/smoothed/<track_id>`, as an Estimate message keyed like the filtered one
(track_id, t_ns, sensor_id), status that of the filtered estimate. The windows are built from
the final revision of every estimate. When late data revise, insert or retract estimates, the
outputs whose windows changed are published again with a higher revision, and an output whose
window no longer exists is retracted, so a subscriber keeping the latest revision per key ends
up with x_k|k+L from the final estimates, for any arrival order. Outputs are published for
the estimates that are confirmed (and every later revision of a key once published).

Memory: per track, the estimates still revisable (after the tracker's horizon) and the L + 1
before them; a deleted track is forgotten once its estimates fall behind the horizon.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Iterable

import numpy as np

from fusion import messages as m
from fusion.core.checks import Array
from fusion.core.smoother import rts_smooth
from fusion.smoothing import track_predictions
from fusion.tracking.results import Estimate
from fusion.tracking.tracker import Tracker

Slot = tuple[int, str]  # (t_ns, sensor_id): an estimate of a track, in scan order


def smoothed_key(ns: str, track_id: int) -> str:
    return f"fusion/{m.check_id('namespace', ns)}/smoothed/{int(track_id)}"


class FixedLagSmoother:
    """See the module docstring. `update(estimates)` after every tracker step returns the
    smoothed estimates (and retractions) to publish."""

    def __init__(self, tracker: Tracker, lag: int) -> None:
        if lag < 1:
            raise ValueError(f"the lag must be at least 1 estimate, got {lag}")
        self.tracker = tracker
        self.lag = lag
        self.est: dict[int, dict[Slot, Estimate]] = {}  # final filtered estimates, by track
        self.sent: dict[int, dict[Slot, tuple[int, Array | None, Array | None, str]]] = {}  # revision, x, P, status
        self._pruned_at: int | None = None

    def update(self, estimates: Iterable[Estimate]) -> list[Estimate]:
        changed: dict[int, Slot] = {}  # track -> earliest slot changed in this step
        for e in estimates:
            d = self.est.setdefault(e.track_id, {})
            s = (e.t_ns, e.sensor_id)
            if e.status == "retracted":
                d.pop(s, None)
            else:
                d[s] = e
            changed[e.track_id] = min(s, changed.get(e.track_id, s))
        out: list[Estimate] = []
        for tid in sorted(changed):
            out.extend(self._track(tid, changed[tid]))
        self._prune()
        return out

    def _track(self, tid: int, first_changed: Slot) -> list[Estimate]:
        d = self.est[tid]
        slots = sorted(d)
        L = self.lag
        lo = max(0, bisect_left(slots, first_changed) - L)  # the first output whose window changed
        want: dict[Slot, tuple[Array, Array, Estimate]] = {}
        if len(slots) > L and lo < len(slots) - L:
            hist = [d[s] for s in slots[lo:]]
            x, P, xp, Pp, F = track_predictions(hist, self.tracker)
            for i in range(len(hist) - L):
                xs, Ps = rts_smooth(x[i:i + L + 1], P[i:i + L + 1], xp[i:i + L + 1], Pp[i:i + L + 1], F[i:i + L + 1])
                want[slots[lo + i]] = (xs[0], Ps[0], hist[i])
        sent = self.sent.setdefault(tid, {})
        out = []
        for s, (x, P, e) in want.items():
            prev = sent.get(s)
            if prev is None and e.status != "confirmed":
                continue
            if prev is not None and prev[1] is not None and prev[3] == e.status and np.array_equal(prev[1], x) \
                    and np.array_equal(prev[2], P):
                continue
            rev = 0 if prev is None else prev[0] + 1
            sent[s] = (rev, x, P, e.status)
            out.append(Estimate(tid, s[0], s[1], e.seq, x, P, e.status, rev, None, e.mode_probabilities))
        start = slots[lo] if lo < len(slots) else first_changed
        for s in sorted(k for k in sent if k >= min(start, first_changed) and k not in want):
            rev, x_old, _, _ = sent[s]
            if x_old is not None:  # no longer an output: withdraw it
                sent[s] = (rev + 1, None, None, "retracted")
                out.append(Estimate.retraction((tid, s[0], s[1]), rev + 1))
        return out

    def _prune(self, *, every_ns: int = 1_000_000_000) -> None:
        """Forget what can no longer change (see the module docstring)."""
        h = self.tracker.horizon_ns
        if h is None or (self._pruned_at is not None and h - self._pruned_at < every_ns):
            return
        self._pruned_at = h
        live = {int(i) for i in self.tracker.track_set.ids.tolist()}
        for tid in list(self.est):
            slots = sorted(self.est[tid])
            j = bisect_left(slots, (h, ""))
            if tid not in live and j == len(slots):
                del self.est[tid]
                self.sent.pop(tid, None)
                continue
            keep_from = slots[max(0, j - self.lag - 1)] if slots else (h, "")
            for s in slots:
                if s >= keep_from:
                    break
                del self.est[tid][s]
            sent = self.sent.get(tid, {})
            for s in [k for k in sent if k < keep_from]:
                del sent[s]
