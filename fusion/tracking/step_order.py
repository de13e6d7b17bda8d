"""The order of what a step of the tracker takes and reports (fusion.tracking.tracker): a scan's
detections by seq and epoch, with the ones that arrived merged in; the world points of the measurements
that arrived; a step's events, withdrawals first."""

from __future__ import annotations

from bisect import insort

import numpy as np

from fusion.tracking.detection import SCAN_ORDER, Detection, in_scan_order, seqs_of
from fusion.tracking.history import Entry
from fusion.tracking.id_sets import member, repeats
from fusion.tracking.results import ScanKey, ScanPoints, TrackEvent


def merged(prev: Entry | None, arrived: list[Detection] | None) -> tuple[Detection, ...]:
    """A scan's detections by (seq, epoch): its stored ones (sorted) with those that arrived now,
    as sorted(stored + arrived, key=(seq, epoch)) orders them, each arrived one put in place by
    binary search instead of sorting the whole scan again (a late measurement joins a scan of
    hundreds). No two detections of a scan share both (admission refuses duplicates), so the
    order is the set's, whatever arrived when; by seq alone, a restarted publisher's two epochs
    sending one seq at one time came in their arrival order."""
    if prev is None:
        return tuple(in_scan_order(arrived or ()))
    if not arrived:  # nothing new: the stored scan as it is
        return prev.dets
    out = list(prev.dets)
    for d in in_scan_order(arrived):
        insort(out, d, key=SCAN_ORDER)
    return tuple(out)


def merged_seqs(prev: Entry | None, arrived: list[Detection] | None, dets: tuple[Detection, ...]) -> np.ndarray:
    """The seqs of `dets` (= merged(prev, arrived)), in their order: the stored scan's seqs where
    its gates hold them (Gates.det_seqs) with the arrived ones put in place (an equal seq's value
    is the same wherever `merged` puts it among its equals), instead of every detection of the
    scan read again (a late measurement joins a scan of hundreds, and a partial re-run needs the
    seqs of the whole scan)."""
    base = None if prev is None or prev.gates is None else prev.gates.det_seqs
    if base is None:
        return seqs_of(dets)
    if not arrived:
        return base
    new = np.sort(seqs_of(arrived), kind="stable")
    return np.insert(base, np.searchsorted(base, new, side="right"), new)


def withdrawals_first(events: list[TrackEvent]) -> tuple[TrackEvent, ...]:
    """A step's events with its withdrawals first (each kind in its order). Two scans of the same
    time (two sensors) can hand one event over: a replay runs the first again, which now confirms
    the track, then the second, whose confirmation of it (the same event: kind, track, time,
    reason) vanished. Reported in that order, a consumer that applies them one by one took the
    event back after it came again (in the mix, a track that stayed confirmed lost its
    "confirmed" in every subscriber); withdrawn first, it stands."""
    if not any(ev.retracted for ev in events):
        return tuple(events)
    return tuple([ev for ev in events if ev.retracted] + [ev for ev in events if not ev.retracted])


def new_points(key: ScanKey, dets: tuple[Detection, ...], arrived: list[Detection], again: bool,
               positions: np.ndarray, seqs: np.ndarray | None) -> ScanPoints:
    """The world points (the scan's `positions`, in the order of `dets`) of the measurements that
    arrived in this call: all of the scan's when it runs for the first time, the new ones when it
    runs again with more (a seq is accepted once: admission refuses duplicates). `seqs`: dets'
    seqs where the scan's gates hold them already (Gates.det_seqs), else None."""
    if seqs is None:
        seqs = seqs_of(dets)
    if again:
        if repeats(seqs):  # a seq twice (two epochs): the arrived ones by identity, not by seq
            came = {id(d) for d in arrived}
            new = np.fromiter((id(d) in came for d in dets), dtype=bool, count=len(dets))
        else:
            new = member(seqs, seqs_of(arrived))
        seqs, positions = seqs[new], positions[new]
    return ScanPoints(key[1], key[0], seqs, positions)
