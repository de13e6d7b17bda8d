"""A scan's assignment in its two stages (`confirmed_first`), and its associations as columns
(fusion.tracking.results.ScanAssociations), built, spliced and counted by compiled loops (numba):
a whole scan's hundreds of measurements, and a partial re-run's few, each in one call instead of
the dozen numpy calls (a few us each) that cost more than the work on a partial re-run's handful
of rows. Outcome and status codes are passed in (indices into fusion.tracking.results.OUTCOMES,
fusion.tracking.trackset.Status), so this module knows only the arrays."""

from __future__ import annotations

import numpy as np
from numba import njit

from fusion.core.association import gnn_positions


@njit(cache=True, fastmath=False)
def confirmed_first(ti: np.ndarray, mj: np.ndarray, cost: np.ndarray, limit: np.ndarray, nis: np.ndarray,
                    status: np.ndarray, confirmed: int, n_tracks: int, n_meas: int) -> np.ndarray:
    """The pairs assigned (positions, increasing) of the gated pairs (ti, mj: intp, sorted by
    (mj, ti); cost, limit, nis: float64; status: each pair's track's): GNN over the pairs of
    tracks whose status is `confirmed` (cost and limit as given: fusion.core.association), then
    GNN over the other tracks' pairs with the measurements the first stage left, by Mahalanobis
    distance: cost sqrt(nis), limit sqrt(limit - cost + nis) (sqrt correctly rounded, as
    numpy's)."""
    taken = np.zeros(n_meas, dtype=np.bool_)
    chosen = np.zeros(ti.size, dtype=np.bool_)
    for stage in range(2):
        n = 0
        sel = np.empty(ti.size, dtype=np.intp)
        for p in range(ti.size):
            if (status[p] == confirmed) == (stage == 0) and not taken[mj[p]]:
                sel[n] = p
                n += 1
        if n == 0:
            continue
        sel = sel[:n]
        c, lim = cost[sel], limit[sel]
        if stage == 1:
            v = nis[sel]
            lim = np.sqrt(lim - c + v)
            c = np.sqrt(v)
        for q in gnn_positions(ti[sel], mj[sel], c, lim, n_tracks, n_meas):
            chosen[sel[q]] = True
            taken[mj[sel[q]]] = True
    return np.flatnonzero(chosen)


@njit(cache=True, fastmath=False)
def built(n_meas: int, pair_mj: np.ndarray, pair_ids: np.ndarray, pair_nis: np.ndarray, taken: np.ndarray,
          room: int, no_track: int, updated: int, born: int, unassigned: int, capacity: int
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int]:
    """The associations of a scan of n_meas measurements from its gated pairs (pair k: measurement
    pair_mj[k], sorted ascending, of track pair_ids[k] at NIS pair_nis[k]) and the pairs `taken`
    (indices of pairs, each measurement at most once): (outcome, track_id, nis, gated_at, births,
    unassigned count, capacity refusals). A measurement no pair took is born while `room` lasts
    (in measurement order: `births`, whose track ids the caller fills in), else refused (outcome
    unassigned when it fell in a gate, capacity when not); unassigned counts every measurement
    in a gate that no pair took, born or refused."""
    at = np.zeros(n_meas + 1, dtype=np.int64)
    for k in range(pair_mj.shape[0]):
        at[pair_mj[k] + 1] += 1
    for j in range(n_meas):
        at[j + 1] += at[j]
    outcome = np.full(n_meas, born, dtype=np.int8)
    track_id = np.full(n_meas, no_track, dtype=np.int64)
    nis = np.full(n_meas, np.nan)
    took = np.zeros(n_meas, dtype=np.bool_)
    for p in taken:
        j = pair_mj[p]
        took[j] = True
        outcome[j] = updated
        track_id[j] = pair_ids[p]
        nis[j] = pair_nis[p]
    births = np.empty(n_meas, dtype=np.intp)
    n_born = n_unassigned = n_refused = 0
    for j in range(n_meas):
        if took[j]:
            continue
        near = at[j + 1] > at[j]
        if near:
            n_unassigned += 1
        if n_born < room:
            births[n_born] = j
            n_born += 1
        else:
            outcome[j] = unassigned if near else capacity
            n_refused += 1
    return outcome, track_id, nis, at, births[:n_born], n_unassigned, n_refused


@njit(cache=True, fastmath=False)
def spliced(n: int, old_j: np.ndarray, js: np.ndarray,
            s_seq: np.ndarray, s_outcome: np.ndarray, s_track: np.ndarray, s_nis: np.ndarray, s_at: np.ndarray,
            s_gated: np.ndarray, p_seq: np.ndarray, p_outcome: np.ndarray, p_track: np.ndarray, p_nis: np.ndarray,
            p_at: np.ndarray, p_gated: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The n rows in their order: stored row k at position old_j[k], then part row i at position
    js[i] in its place (every position is one or the other): (seq, outcome, track_id, nis,
    gated_at, gated)."""
    src = np.empty(n, dtype=np.int64)  # k >= 0: stored row k; k < 0: part row -k - 1
    for k in range(old_j.shape[0]):
        src[old_j[k]] = k
    for i in range(js.shape[0]):
        src[js[i]] = -i - 1
    seq = np.empty(n, dtype=np.int64)
    outcome = np.empty(n, dtype=np.int8)
    track = np.empty(n, dtype=np.int64)
    nis = np.empty(n)
    at = np.zeros(n + 1, dtype=np.int64)
    for j in range(n):
        k = src[j]
        if k >= 0:
            seq[j], outcome[j], track[j], nis[j] = s_seq[k], s_outcome[k], s_track[k], s_nis[k]
            at[j + 1] = at[j] + s_at[k + 1] - s_at[k]
        else:
            i = -k - 1
            seq[j], outcome[j], track[j], nis[j] = p_seq[i], p_outcome[i], p_track[i], p_nis[i]
            at[j + 1] = at[j] + p_at[i + 1] - p_at[i]
    gated = np.empty(at[n], dtype=np.int64)
    for j in range(n):
        k = src[j]
        if k >= 0:
            gated[at[j]:at[j + 1]] = s_gated[s_at[k]:s_at[k + 1]]
        else:
            i = -k - 1
            gated[at[j]:at[j + 1]] = p_gated[p_at[i]:p_at[i + 1]]
    return seq, outcome, track, nis, at, gated


@njit(cache=True, fastmath=False)
def counted(outcome: np.ndarray, at: np.ndarray, rows: np.ndarray, updated: int, born: int
            ) -> tuple[int, int, int]:
    """Of the rows `rows`: (updates, unassigned: in a gate and no update, births)."""
    n_upd = n_una = n_born = 0
    for j in rows:
        if outcome[j] == updated:
            n_upd += 1
        elif at[j + 1] > at[j]:
            n_una += 1
        if outcome[j] == born:
            n_born += 1
    return n_upd, n_una, n_born


@njit(cache=True, fastmath=False)
def changed(old_pos: np.ndarray, s_outcome: np.ndarray, s_track: np.ndarray, s_nis: np.ndarray, s_at: np.ndarray,
            s_gated: np.ndarray, outcome: np.ndarray, track: np.ndarray, nis: np.ndarray, at: np.ndarray,
            gated: np.ndarray) -> np.ndarray:
    """Which rows of a scan's associations (outcome, track, nis, at, gated) differ from the stored
    run's (s_*), whose row k is at position old_pos[k]: another outcome, track, NIS (bits: a NaN
    equals itself) or gated tracks; a row no stored row is at (a new measurement) differs."""
    n = outcome.shape[0]
    diff = np.ones(n, dtype=np.bool_)
    s_bits, bits = s_nis.view(np.int64), nis.view(np.int64)
    for k in range(old_pos.shape[0]):
        j = old_pos[k]
        same = (outcome[j] == s_outcome[k] and track[j] == s_track[k] and bits[j] == s_bits[k]
                and at[j + 1] - at[j] == s_at[k + 1] - s_at[k])
        if same:
            a, b = at[j], s_at[k]
            for g in range(at[j + 1] - a):
                if gated[a + g] != s_gated[b + g]:
                    same = False
                    break
        diff[j] = not same
    return diff


@njit(cache=True, fastmath=False)
def taken(rows: np.ndarray, seq: np.ndarray, outcome: np.ndarray, track: np.ndarray, nis: np.ndarray, at: np.ndarray,
          gated: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows `rows` (ascending) of a scan's associations: (seq, outcome, track_id, nis,
    gated_at, gated)."""
    m = rows.shape[0]
    sub_at = np.zeros(m + 1, dtype=np.int64)
    for i in range(m):
        j = rows[i]
        sub_at[i + 1] = sub_at[i] + at[j + 1] - at[j]
    sub_gated = np.empty(sub_at[m], dtype=np.int64)
    for i in range(m):
        j = rows[i]
        sub_gated[sub_at[i]:sub_at[i + 1]] = gated[at[j]:at[j + 1]]
    return seq[rows], outcome[rows], track[rows], nis[rows], sub_at, sub_gated
