"""The intake's clocks and window for many detections at once, as one compiled loop (numba).

`steps` is `Intake._window` without the duplicate set, applied to detections i = 0, 1, ... in
order, each with its arrival time a_i known (fusion.tracking.clock, fusion.tracking.intake):
    ref_i = a_i + offset_s                        (source s settled)
          = max over the other settled sources of a_i + offset, else a_i + offset_s
                                                  (None while there is none);
    observed unless ref_i is known and t_i > ref_i + future: offset t_i - a_i into the source's
        last `samples` (ring and sorted copy), offset_s = the rank-th largest (rank =
        outliers + 1; the smallest while fewer), settled once it holds rank of them;
    now = max(now, ref_i); future (code 1) when t_i > ref_i + future;
    the watermark: a_i + the smallest offset of the sources heard within idle of a_i (none
        while a source not yet heard may still start: a_i - first arrival < idle); the horizon
        = max(horizon, watermark - lag);
    too late when t_i < horizon (code 2) or (t_i, s) <= the committed scan (code 3).
Without arrival times (a batch with none: `timed` False; fusion.tracking.clock: the offset is
t_i itself, a source's clock its offset) each detection is observed first (it always counts, and
its source's last arrival becomes unknown), then
    ref_i = offset_s (s settled), else the largest offset of the other settled sources, else offset_s;
    now and future as above; the watermark: the smallest clock within idle of the most advanced
        one; the horizon and too late as above (the first arrival is left as it is).
The same integer arithmetic in the same order as the Python, on int64: `window_steps` takes
the detections only when every time, offset and bound is within the limits below, so that no
sum overflows (otherwise Intake.admit_many takes them one at a time, in Python's integers).
Sources are indexed in sorted order of their ids, so comparing (t, source) with the committed
key is comparing (t, index).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from fusion.tracking.clock import Clocks

PASSED, FUTURE, HORIZON, COMMITTED = 0, 1, 2, 3


@njit(cache=True, fastmath=False)
def steps(src: np.ndarray, t: np.ndarray, a: np.ndarray, ring: np.ndarray, start: np.ndarray, count: np.ndarray,
          srt: np.ndarray, last: np.ndarray, has_last: np.ndarray, offset: np.ndarray, has_offset: np.ndarray,
          rank: int, idle: int, future: int, lag: int, scalars: np.ndarray, flags: np.ndarray, timed: bool
          ) -> tuple[np.ndarray, np.ndarray]:
    """(code, value) of every detection (module docstring; value: ref for code 1, the horizon
    for code 2), updating the clock arrays (per source: ring (S, samples) from `start`, `count`
    of them, srt[:count] sorted, last arrival, offset, each with its flag) and `scalars` =
    [first arrival, now, horizon, committed t, committed source] with `flags` saying which
    are known, in place. `timed`: with the arrival times `a`; else none (a all 0), as the
    module docstring says for detections without them (one kernel for both: the loop's shared
    parts written once, where helper calls cost the timed loop half its speed)."""
    n = t.shape[0]
    S = ring.shape[0]
    cap = ring.shape[1]
    code = np.zeros(n, dtype=np.int64)
    value = np.zeros(n, dtype=np.int64)
    for i in range(n):
        s, ti, ai = src[i], t[i], a[i]
        # the reference: the source's own clock once settled, else the most advanced other settled one
        # (untimed: taken after observing, below)
        has_ref = False
        ref = 0
        if timed:
            if count[s] >= rank:
                ref, has_ref = ai + offset[s], True
            else:
                for k in range(S):
                    if k != s and count[k] >= rank and (not has_ref or ai + offset[k] > ref):
                        ref, has_ref = ai + offset[k], True
                if not has_ref and has_offset[s]:
                    ref, has_ref = ai + offset[s], True
        if not has_ref or ti <= ref + future:  # observe (untimed: always)
            if timed and not flags[0]:
                scalars[0], flags[0] = ai, True
            o = ti - ai
            c = count[s]
            if c == cap:  # the oldest leaves the ring and its sorted copy
                old = ring[s, start[s]]
                j = 0
                while srt[s, j] < old:
                    j += 1
                for k in range(j, c - 1):
                    srt[s, k] = srt[s, k + 1]
                ring[s, start[s]] = o
                start[s] = (start[s] + 1) % cap
                c -= 1
            else:
                ring[s, (start[s] + c) % cap] = o
            j = c  # insort: after the equal ones
            while j > 0 and srt[s, j - 1] > o:
                srt[s, j] = srt[s, j - 1]
                j -= 1
            srt[s, j] = o
            c += 1
            count[s] = c
            last[s], has_last[s] = ai, timed  # untimed: its last arrival unknown
            offset[s], has_offset[s] = srt[s, max(c - rank, 0)], True
        if not timed:  # its own clock once settled, else the most advanced other settled one, else its own
            ref, has_ref = offset[s], True
            if count[s] < rank:
                other = False
                for k in range(S):
                    if k != s and count[k] >= rank and (not other or offset[k] > ref):
                        ref, other = offset[k], True
        if has_ref:
            if not flags[1] or ref > scalars[1]:
                scalars[1], flags[1] = ref, True
            if ti > ref + future:
                code[i], value[i] = FUTURE, ref
                continue
        # the watermark (timed: at this arrival; untimed: the smallest clock within idle of the newest)
        has_low, low, wait = False, 0, False
        if timed:
            for k in range(S):
                if not has_last[k]:
                    if flags[0] and ai - scalars[0] < idle:
                        wait = True
                        break
                    continue
                if ai - last[k] > idle:
                    continue
                if not has_low or offset[k] < low:
                    low, has_low = offset[k], True
        else:
            newest = offset[s]
            for k in range(S):
                if has_offset[k] and offset[k] > newest:
                    newest = offset[k]
            low, has_low = newest, True
            for k in range(S):
                if has_offset[k] and offset[k] >= newest - idle and offset[k] < low:
                    low = offset[k]
        if not wait and has_low:
            w = ai + low - lag
            if not flags[2] or w > scalars[2]:
                scalars[2], flags[2] = w, True
        if flags[2]:
            if ti < scalars[2]:
                code[i], value[i] = HORIZON, scalars[2]
                continue
            if flags[3] and (ti < scalars[3] or (ti == scalars[3] and s <= scalars[4])):
                code[i] = COMMITTED
    return code, value


LIMIT_T = 2**61  # |t|, |arrival| and |last arrival| at most this, |offsets| at most 2^62, bounds at most 2^60:
LIMIT_OFFSET = 2**62  # then every sum in `steps` stays within int64 (module docstring)
LIMIT_BOUND = 2**60


class Window(NamedTuple):
    """What `window_steps` found: per detection its code and value (`steps`), and the intake's
    newest reference time and horizon after them."""

    code: np.ndarray
    value: np.ndarray
    now_ns: int | None
    horizon_ns: int | None


def window_steps(clocks: Clocks, source: list[str], t_ns: list[int], arrival_ns: list[int | None], *,
                 future_ns: int, lag_ns: int, now_ns: int | None, horizon_ns: int | None,
                 committed: tuple[int, str] | None) -> Window | None:
    """`steps` over detections (source, t_ns, arrival_ns), from and back into `clocks` (through
    their public state and restore), untimed when no detection has an arrival time;
    None, with nothing changed, when some have one and others not, or a value is beyond the
    limits above (the caller then takes them one at a time)."""
    names = list(clocks.sources)  # sorted ids: index order is the ids' order
    index = {s: k for k, s in enumerate(names)}
    n = len(t_ns)
    if committed is not None and committed[1] not in index:
        return None
    untimed = n > 0 and all(a is None for a in arrival_ns)  # else a None among them: TypeError below
    try:
        src = np.fromiter(map(index.__getitem__, source), np.int64, n)
        t = np.fromiter(t_ns, np.int64, n)
        a = np.zeros(n, np.int64) if untimed else np.fromiter(arrival_ns, np.int64, n)
    except (TypeError, OverflowError, KeyError):
        return None
    if n and (t.min() < -LIMIT_T or t.max() > LIMIT_T or a.min() < -LIMIT_T or a.max() > LIMIT_T):
        return None
    if not (0 <= future_ns <= LIMIT_BOUND and 0 <= lag_ns <= LIMIT_BOUND and 0 <= clocks.idle_ns <= LIMIT_BOUND):
        return None
    S, cap = len(names), clocks.samples
    ring = np.zeros((S, cap), np.int64)
    srt = np.zeros((S, cap), np.int64)
    count = np.zeros(S, np.int64)
    last = np.zeros(S, np.int64)
    has_last = np.zeros(S, np.bool_)
    offset = np.zeros(S, np.int64)
    has_offset = np.zeros(S, np.bool_)
    for k, name in enumerate(names):
        clock = clocks.sources[name]
        offsets, last_k = clock.state()
        if any(not -LIMIT_OFFSET <= o <= LIMIT_OFFSET for o in offsets):
            return None
        c = len(offsets)
        ring[k, :c] = offsets
        srt[k, :c] = sorted(offsets)
        count[k] = c
        if clock.offset is not None:  # the clock's own (outliers + 1)-th largest
            offset[k], has_offset[k] = clock.offset, True
        if last_k is not None:
            if not -LIMIT_T <= last_k <= LIMIT_T or not c:
                return None
            last[k], has_last[k] = last_k, True
    first = clocks.first_arrival_ns
    if first is not None and not -LIMIT_T <= first <= LIMIT_T:
        return None
    ct, cs = (committed[0], index[committed[1]]) if committed is not None else (None, None)
    known = (first, now_ns, horizon_ns, ct, cs)
    if any(v is not None and not -(2**63) <= v < 2**63 for v in known):
        return None
    scalars = np.array([0 if v is None else v for v in known], np.int64)
    flags = np.array([v is not None for v in known], np.bool_)
    start = np.zeros(S, np.int64)
    code, value = steps(src, t, a, ring, start, count, srt, last, has_last, offset, has_offset,
                        clocks.outliers + 1, clocks.idle_ns, future_ns, lag_ns, scalars, flags, not untimed)
    for k, name in enumerate(names):
        c, s0 = int(count[k]), int(start[k])
        clocks.sources[name].restore([int(ring[k, (s0 + j) % cap]) for j in range(c)],
                                     int(last[k]) if has_last[k] else None)
    if flags[0]:
        clocks.restore_first_arrival(int(scalars[0]))
    return Window(code, value, int(scalars[1]) if flags[1] else None, int(scalars[2]) if flags[2] else None)
