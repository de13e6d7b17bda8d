"""A scan's associations as columns (ScanAssociations, fusion.tracking.association_kernels):
built, spliced and counted as the record-per-measurement code they replace did it, kept here
as the reference (random scans: measurements in no gate, in several, taken or not, with room
for some births and not others)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.tracking.association_kernels import built, counted, spliced
from fusion.tracking.results import NO_TRACK, OUTCOME_CODE, Association, Outcome, ScanAssociations
from fusion.tracking.splice import spliced as spliced_block

CODES = tuple(OUTCOME_CODE[o] for o in (Outcome.UPDATED, Outcome.BORN, Outcome.UNASSIGNED, Outcome.CAPACITY))


def _scan(rng: np.random.Generator) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """(measurements, pairs' measurements (sorted), their track ids, NIS, taken pairs, room)."""
    M = int(rng.integers(0, 12))
    mj = np.sort(rng.integers(0, max(M, 1), size=int(rng.integers(0, 3 * M + 1)))) if M else np.zeros(0, np.int64)
    ids = rng.integers(1, 2**62, size=mj.size)
    nis = rng.random(mj.size) * 9
    firsts = np.unique(mj, return_index=True)[1]  # at most one taken pair per measurement
    taken = np.sort(rng.choice(firsts, size=int(rng.integers(0, firsts.size + 1)), replace=False)) if firsts.size \
        else np.zeros(0, np.intp)
    return M, mj.astype(np.int64), ids.astype(np.int64), nis, taken.astype(np.intp), int(rng.integers(0, M + 2))


def _reference(M: int, mj: np.ndarray, ids: np.ndarray, nis: np.ndarray, taken: np.ndarray, room: int
               ) -> tuple[list[tuple], list[int], int, int]:
    """The records loop of fusion.tracking.scan before the columns: (outcome, track id or None,
    NIS or None, gated ids) per measurement, the births, unassigned and capacity counts."""
    bounds = np.searchsorted(mj, np.arange(M + 1)).tolist()
    by_j = {int(mj[p]): int(p) for p in taken.tolist()}
    rows, births, unassigned, refused = [], [], 0, 0
    for j in range(M):
        near = tuple(ids[bounds[j]:bounds[j + 1]].tolist())
        p = by_j.get(j)
        if p is not None:
            rows.append((Outcome.UPDATED, int(ids[p]), float(nis[p]), near))
            continue
        unassigned += bool(near)
        if len(births) >= room:
            rows.append((Outcome.UNASSIGNED if near else Outcome.CAPACITY, None, None, near))
            refused += 1
        else:
            births.append(j)
            rows.append((Outcome.BORN, -(j + 100), None, near))  # the born track's id: filled in below
    return rows, births, unassigned, refused


def _block(M: int, out: tuple, ids_born: list[int], mj: np.ndarray, ids: np.ndarray) -> ScanAssociations:
    outcome, track, nis, at, births, _, _ = out
    track[births] = ids_born
    return ScanAssociations("s", 7, np.arange(M, dtype=np.int64) * 3, outcome, track, nis, at, ids)


@pytest.mark.parametrize("seed", range(40))
def test_built_is_the_record_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    M, mj, ids, nis, taken, room = _scan(rng)
    out = built(M, mj, ids, nis, taken, room, NO_TRACK, *CODES)
    rows, births, unassigned, refused = _reference(M, mj, ids, nis, taken, room)
    assert out[4].tolist() == births and (out[5], out[6]) == (unassigned, refused)
    block = _block(M, out, [-(j + 100) for j in births], mj, ids)
    got = [(a.outcome, a.track_id, a.nis, a.gated) for a in block.rows()]
    assert got == rows
    assert all(a.seq == 3 * j and a.sensor_id == "s" and a.t_ns == 7 for j, a in enumerate(block.rows()))


@pytest.mark.parametrize("seed", range(40))
def test_spliced_puts_each_row_in_its_place(seed: int) -> None:
    rng = np.random.default_rng(seed)
    blocks = []
    for _ in range(2):
        M, mj, ids, nis, taken, room = _scan(rng)
        out = built(M, mj, ids, nis, taken, room, NO_TRACK, *CODES)
        blocks.append(_block(M, out, [int(x) for x in rng.integers(1, 2**62, size=out[4].size)], mj, ids))
    stored, part = blocks
    n = len(stored) + len(part)
    order = rng.permutation(n)
    old_j, js = np.sort(order[:len(stored)]), np.sort(order[len(stored):])
    got = spliced_block(stored, old_j, n, part, js)
    want: list[Association | None] = [None] * n
    for k, j in enumerate(old_j.tolist()):
        want[j] = stored.rows()[k]
    for i, j in enumerate(js.tolist()):
        want[j] = part.rows()[i]
    assert got.rows() == want
    assert [a.dtype for a in (got.seq, got.outcome, got.track_id, got.nis, got.gated_at, got.gated)] == \
        [np.int64, np.int8, np.int64, np.float64, np.int64, np.int64]


def test_spliced_part_replaces_stored_rows() -> None:
    """A partial re-run of the same detections: the part's rows replace the stored ones at js."""
    rng = np.random.default_rng(3)
    M, mj, ids, nis, taken, room = 9, np.array([0, 0, 2, 5, 5, 5, 8]), rng.integers(1, 2**62, 7), rng.random(7), \
        np.array([0, 3], dtype=np.intp), 3
    stored = _block(M, built(M, mj, ids, nis, taken, room, NO_TRACK, *CODES), [11, 12, 13], mj, ids)
    js = np.array([2, 5])
    part = ScanAssociations("s", 7, stored.seq[js], np.array([CODES[0], CODES[3]], np.int8), np.array([99, NO_TRACK]),
                            np.array([1.5, np.nan]), np.array([0, 1, 1]), np.array([99]))
    got = spliced(M, np.arange(M), js, *(getattr(b, f) for b in (stored, part)
                                         for f in ("seq", "outcome", "track_id", "nis", "gated_at", "gated")))
    rows = ScanAssociations("s", 7, *got).rows()
    assert rows[2] == Association("s", 7, 6, Outcome.UPDATED, 99, 1.5, (99,))
    assert rows[5] == Association("s", 7, 15, Outcome.CAPACITY, None, None, ())
    keep = [j for j in range(M) if j not in (2, 5)]
    assert [rows[j] for j in keep] == [stored.rows()[j] for j in keep]


@pytest.mark.parametrize("seed", range(20))
def test_counted_is_the_record_count(seed: int) -> None:
    rng = np.random.default_rng(seed)
    M, mj, ids, nis, taken, room = _scan(rng)
    out = built(M, mj, ids, nis, taken, room, NO_TRACK, *CODES)
    b = _block(M, out, [int(x) for x in rng.integers(1, 2**62, size=out[4].size)], mj, ids)
    rows = np.flatnonzero(rng.random(M) < 0.6)
    recs = [b.rows()[j] for j in rows.tolist()]
    want = (sum(a.outcome == Outcome.UPDATED for a in recs),
            sum(a.outcome != Outcome.UPDATED and bool(a.gated) for a in recs),
            sum(a.outcome == Outcome.BORN for a in recs))
    assert counted(b.outcome, b.gated_at, rows, CODES[0], CODES[1]) == want
