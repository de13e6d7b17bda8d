"""Confirmation and deletion, in one place.

A scan of sensor s is a chance for track i when s could have seen it: i's predicted position
lies in s's declared coverage, or (without one) s has updated i before. Only chances count, so
scans of other sensors, or a burst of returns elsewhere, never wear a track down.
  hit:        hits += 1, chances += 1, misses = 0; a tentative track with hits >= M within its
              first N chances is confirmed;
  no hit:     a chance adds chances += 1, misses += 1;
  coasting:   a confirmed track that misses a chance after a hit (an event; it lives on);
  deletion:   tentative with chances >= N and hits < M ("not confirmed"); confirmed with
              misses > max_misses ("misses"); any track without an update for coast_s
              ("coasted") or with a predicted position std above max_position_std_m
              ("covariance").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.config import LifecycleConfig
from fusion.core.timebase import NS_PER_S
from fusion.tracking.lifecycle_kernel import COASTED, COVARIANCE, MISSES, NOT_CONFIRMED, verdicts
from fusion.tracking.models import SensorModel
from fusion.tracking.results import DeletionReason, EventKind, TrackEvent
from fusion.tracking.trackset import Status, TrackSet


@dataclass(frozen=True)
class Sweep:
    """The lifecycle's verdict on the tracks of one scan."""

    counters: dict[str, np.ndarray]  # chances, misses, seen_by after the scan
    delete: np.ndarray  # rows to delete
    events: list[TrackEvent]


class Lifecycle:
    def __init__(self, cfg: LifecycleConfig, q2: float) -> None:
        self.cfg = cfg
        self.q2 = q2
        self.coast_ns = round(cfg.coast_s * NS_PER_S)

    def confirms(self, status: np.ndarray, hits: np.ndarray, chances: np.ndarray) -> np.ndarray:
        """Which hits, bringing tracks to `hits` in `chances` chances, confirm them."""
        return (status == Status.TENTATIVE.value) & (hits >= self.cfg.confirm_m) & (chances <= self.cfg.confirm_n)

    def born_status(self) -> Status:
        return Status.CONFIRMED if self.cfg.confirm_m <= 1 else Status.TENTATIVE

    def sweep(self, before: TrackSet, after: TrackSet, hit: np.ndarray, sensor: SensorModel, t_ns: int,
              predicted: tuple[np.ndarray, np.ndarray] | None = None) -> Sweep:
        """Counters and deletions after a scan of `sensor` at t_ns. `before` holds the tracks as
        they were gated (their predicted positions decide coverage), `after` the same rows with
        the hit tracks updated; `hit` marks the rows that took a measurement. `predicted`:
        before.predicted_position(t_ns, q2) if the caller has it; after's rows that were not hit
        are before's, so only the hit rows' spread is computed again."""
        cfg = self.cfg
        s = sensor.index
        ppos, bvar = before.predicted_position(t_ns, self.q2) if predicted is None else predicted
        declared = sensor.covers(ppos)
        chance = hit | (before.seen_by[:, s] if declared is None else declared)
        seen_by = after.seen_by
        pvar = bvar
        if hit.any():
            seen_by = seen_by.copy()
            seen_by[hit, s] = True
            pvar = bvar.copy()
            pvar[hit] = after.predicted_position(t_ns, self.q2, np.flatnonzero(hit))[1]
        too_wide = pvar.max(axis=1) > cfg.max_position_std_m**2 if pvar.size else np.zeros(len(after), bool)
        chances, misses, why, coasting = verdicts(
            hit, chance, after.chances, after.misses, after.status == Status.TENTATIVE.value, after.hits, after.t_ns,
            too_wide, t_ns, cfg.confirm_n, cfg.confirm_m, cfg.max_misses, self.coast_ns)
        delete = why != 0
        ids = after.ids
        events = [TrackEvent(EventKind.COASTING, int(ids[i]), t_ns) for i in np.flatnonzero(coasting).tolist()]
        events.extend(TrackEvent(EventKind.DELETED, int(ids[i]), t_ns, _REASONS[w])
                      for i, w in zip(np.flatnonzero(delete).tolist(), why[delete].tolist(), strict=True))
        return Sweep({"chances": chances, "misses": misses, "seen_by": seen_by}, delete, events)


_REASONS = {NOT_CONFIRMED: DeletionReason.NOT_CONFIRMED, MISSES: DeletionReason.MISSES,
            COASTED: DeletionReason.COASTED, COVARIANCE: DeletionReason.COVARIANCE}
