"""Whether rows of two track sets hold the same bits (fusion.tracking.trackset.TrackSet.changed_since),
a column at a time in one compiled pass over the rows still equal: a row's bytes compared in
place (as int64 words where a row is a whole number of them), where the numpy passes made two
gathered copies, a reshape, a comparison and a reduction per column (~10 us a column at the
~70 rows of a partial re-run at 667 targets). Bits, not values: -0.0 and 0.0 differ, a NaN
equals itself."""

from __future__ import annotations

from math import prod

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def _still_same(a: np.ndarray, b: np.ndarray, rows: np.ndarray, at: np.ndarray, same: np.ndarray) -> None:
    """same[k] &= (a[rows[k]] == b[at[k]] in every word), for the k still same."""
    w = a.shape[1]
    for k in range(rows.size):
        if not same[k]:
            continue
        i, j = rows[k], at[k]
        for c in range(w):
            if a[i, c] != b[j, c]:
                same[k] = False
                break


def _words(c: np.ndarray) -> np.ndarray:
    """A column as (rows, words) of its bytes: int64 words where a row's size allows, else bytes."""
    b = (c if c.flags.c_contiguous else np.ascontiguousarray(c)).reshape(c.shape[0], prod(c.shape[1:])).view(np.uint8)
    return b.view(np.int64) if b.shape[1] % 8 == 0 else b


def still_same(a: np.ndarray, b: np.ndarray, rows: np.ndarray, at: np.ndarray, same: np.ndarray) -> None:
    """Clear same[k] where row rows[k] of column `a` differs in any bit from row at[k] of column
    `b` (the same column of another set: same dtype and row shape)."""
    _still_same(_words(a), _words(b), rows, at, same)


def warm() -> None:
    """Compile (or load) both forms of the kernel (words and bytes) before data: a partial re-run
    reaches it only with more than a few changed rows, which a short warm-up scene never has
    (fusion.tracking.warmup)."""
    rows = np.zeros(1, dtype=np.int64)
    for a in (np.zeros((1, 1)), np.zeros(1, dtype=np.int8)):
        still_same(a, a, rows, rows, np.ones(1, dtype=bool))
