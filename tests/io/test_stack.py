"""fusion.io.columns.stack: the byte-joined fast path gives the values np.stack gives, and every
input it cannot take (lists, other dtypes, non-contiguous views) goes the concatenate way."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.io.columns import stack


@pytest.mark.parametrize("shape", [(5,), (5, 5), (2, 3, 4), ()])
def test_float64_rows_equal_np_stack(shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(1)
    rows = [rng.normal(size=shape) for _ in range(7)]
    out = stack(rows)
    assert out.dtype == np.float64 and out.shape == (7, *shape)
    assert np.array_equal(out, np.stack(rows))
    before = rows[0].copy()
    out[0] = 1e9  # writable: callers may fill it in place
    assert np.array_equal(rows[0], before)  # a copy, not the rows' memory


def test_rows_of_a_bigger_array_and_views() -> None:
    X = np.arange(24.0).reshape(4, 6)
    assert np.array_equal(stack([X[1], X[3]]), X[[1, 3]])  # contiguous rows
    assert np.array_equal(stack([X[0, ::2], X[1, ::2]]), X[:2, ::2])  # strided views
    assert np.array_equal(stack([X.T[:2], X.T[2:4]]), np.stack([X.T[:2], X.T[2:4]]))  # transposed


def test_other_inputs_converted() -> None:
    assert np.array_equal(stack([[1, 2], [3, 4]]), np.array([[1.0, 2.0], [3.0, 4.0]]))
    ints = stack([np.arange(3), np.arange(3)])
    assert ints.dtype == np.float64 and np.array_equal(ints, [[0, 1, 2], [0, 1, 2]])
    # a float64 first row and an int64 one of the same byte size: not read as float bytes
    mixed = stack([np.zeros(2), np.array([1, 2], dtype=np.int64)])
    assert np.array_equal(mixed, [[0.0, 0.0], [1.0, 2.0]])
    assert np.array_equal(stack([np.ones(2, np.float32), np.ones(2)]), np.ones((2, 2)))
    assert np.array_equal(stack([np.ones(2).astype(">f8"), np.ones(2)]), np.ones((2, 2)))


def test_rows_of_different_shapes_refused() -> None:
    with pytest.raises(ValueError):
        stack([np.zeros(4), np.zeros(6), np.zeros(2)])  # the bytes of three rows of 4: still refused
    with pytest.raises(ValueError):
        stack([np.zeros((2, 2)), np.zeros(4)])
    with pytest.raises(ValueError):
        stack([[1.0, 2.0], [1.0]])


def test_none_given_shape() -> None:
    assert stack([], (3, 3)).shape == (0, 3, 3)
