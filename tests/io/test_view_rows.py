"""fusion.io.view_rows.Stacked: what the views read of the viewed estimates, stacked once when
they are scored, is each estimate's own field, row for row (the prediction x where there is none,
NaN where a field is absent), per sensor for the innovation, through concat too."""

from __future__ import annotations

import msgspec
import numpy as np

from fusion.io.view_rows import Stacked
from fusion.tracking.results import Estimate, Review


def _estimates(n: int, seed: int) -> list[Estimate]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        born = k % 4 == 0  # a birth: no prior, innovation or gain
        # each its own one-row Review block (in the tracker a scan's estimates share theirs), or none
        x, P = rng.normal(size=(1, 5)), np.eye(5)[None] * rng.random()
        review = None if k % 7 == 3 else Review(x, P, rng.normal(size=(1, 3))) if born else Review(
            x, P, rng.normal(size=(1, 3)), rng.normal(size=(1, 5)), np.eye(5)[None], rng.normal(size=(1, 2)),
            np.eye(2)[None], None if k % 5 == 1 else rng.normal(size=(1, 2, 5)))
        out.append(Estimate(k, 10 * k, "radar1" if k % 2 else "cam1", k, x[0], P[0], "confirmed", 0,
                            None if born else float(rng.random()), None if k % 3 else rng.random(2), review))
    return out


def _of(es: list[Estimate]) -> Stacked:
    n = len(es)
    X = np.stack([e.x for e in es])
    z = np.zeros(n, dtype=np.int64)
    return Stacked.of(es, z, z, z, X, np.stack([e.P for e in es]), X, X, np.zeros(n, bool), np.zeros(n), X, X,
                      conf=np.ones(n, bool), n_pos=2)


def _same(s: Stacked, es: list[Estimate]) -> None:
    assert s.ids.tolist() == [e.track_id for e in es]
    for i, e in enumerate(es):
        assert np.array_equal(s.prior[i], e.x if e.prior_x is None else e.prior_x)
        assert s.meas[i] == (e.meas_pos is not None)
        if e.meas_pos is not None:
            assert np.array_equal(s.meas_pos[i], e.meas_pos[:2])
        assert s.mode[i] == (e.mode_probabilities is not None)
        if e.mode_probabilities is not None:
            assert np.array_equal(s.mu[i], e.mode_probabilities)
    for sensor, u in s.updates.items():
        want = [i for i, e in enumerate(es) if e.sensor_id == sensor and e.y is not None]
        assert u.rows.tolist() == want
        for j, i in enumerate(want):
            e = es[i]
            assert np.array_equal(u.Y[j], e.y) and np.array_equal(u.S[j], e.S) and u.nis[j] == e.nis
            assert u.gain[j] == (e.H is not None)
            if e.H is not None:  # the gain P- H' S^-1, as one row of the batched solve
                assert np.array_equal(u.K[j], _gain(e))
    assert sorted(s.updates) == sorted({e.sensor_id for e in es if e.y is not None})


def _gain(e: Estimate) -> np.ndarray:
    """K = P- H' S^-1 of one estimate, computed as the batched one is (a stack of one)."""
    return np.swapaxes(np.linalg.solve(e.S[None], e.H[None] @ e.prior_P[None]), 1, 2)[0]


def test_stacked_of_and_concat() -> None:
    a, b = _estimates(9, 1), _estimates(5, 2)
    _same(_of(a), a)
    _same(Stacked.concat([_of(a), _of(b)]), a + b)
    no_modes = [e for e in b if e.mode_probabilities is None]
    _same(Stacked.concat([_of(no_modes), _of(a)]), no_modes + a)


def test_measured_positions_of_different_lengths_are_cut_to_the_position_space() -> None:
    """A flush whose measured positions are not all of one length (the stacked fast path cannot
    take them) gives each one's first n_pos components all the same."""
    es = _estimates(8, 3)
    es = [e if e.meas_pos is None or k % 2 else
          msgspec.structs.replace(e, review=msgspec.structs.replace(e.review, meas_pos=e.review.meas_pos[:, :2]))
          for k, e in enumerate(es)]
    assert len({e.meas_pos.shape for e in es if e.meas_pos is not None}) == 2
    _same(_of(es), es)


def _with_block_modes(es: list[Estimate]) -> list[Estimate]:
    """The estimates with their mode probabilities in their Review blocks too (Review.MU), as the
    tracker gives them, for those that have both."""
    return [e if e.review is None or e.mode_probabilities is None else
            msgspec.structs.replace(e, review=msgspec.structs.replace(e.review, MU=e.mode_probabilities[None]))
            for e in es]


def test_mode_probabilities_read_from_the_blocks_or_from_each_estimate() -> None:
    """Where every estimate's block holds its mode probabilities they are read block by block;
    where some do not (no block, one model), each estimate's own: the same rows either way."""
    modes = [e for e in _estimates(30, 4) if e.mode_probabilities is not None and e.review is not None]
    assert len(modes) > 3
    every = _with_block_modes(modes)
    assert all(e.review.MU is not None for e in every)  # the block path
    _same(_of(every), every)
    mixed = _with_block_modes(_estimates(30, 5))
    assert any(e.review is None or e.review.MU is None for e in mixed)  # each estimate's own
    _same(_of(mixed), mixed)

