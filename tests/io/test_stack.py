"""fusion.io.columns.stack: the byte-joined fast path (more than SMALL_STACK rows) and np.array
(up to it) give the values np.stack gives, and every input the joined path cannot take (lists,
other dtypes, non-contiguous views) goes the concatenate way."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.io.columns import SMALL_STACK, stack

COUNTS = [7, SMALL_STACK, SMALL_STACK + 1, 100]  # both ways, and their border


@pytest.mark.parametrize("n", COUNTS)
@pytest.mark.parametrize("shape", [(5,), (5, 5), (2, 3, 4), ()])
def test_float64_rows_equal_np_stack(shape: tuple[int, ...], n: int) -> None:
    rng = np.random.default_rng(1)
    rows = [rng.normal(size=shape) for _ in range(n)]
    out = stack(rows)
    assert out.dtype == np.float64 and out.shape == (n, *shape)
    assert np.array_equal(out, np.stack(rows))
    before = rows[0].copy()
    out[0] = 1e9  # writable: callers may fill it in place
    assert np.array_equal(rows[0], before)  # a copy, not the rows' memory


@pytest.mark.parametrize("k", [1, 20])  # rows: 2k, 2k, 2k (up to SMALL_STACK), then 40
def test_rows_of_a_bigger_array_and_views(k: int) -> None:
    X = np.arange(24.0).reshape(4, 6)
    assert np.array_equal(stack([X[1], X[3]] * k), X[[1, 3] * k])  # contiguous rows
    assert np.array_equal(stack([X[0, ::2], X[1, ::2]] * k), np.stack([X[0, ::2], X[1, ::2]] * k))  # strided views
    assert np.array_equal(stack([X.T[:2], X.T[2:4]] * k), np.stack([X.T[:2], X.T[2:4]] * k))  # transposed


@pytest.mark.parametrize("k", [1, 20])
def test_other_inputs_converted(k: int) -> None:
    assert np.array_equal(stack([[1, 2], [3, 4]] * k), np.array([[1.0, 2.0], [3.0, 4.0]] * k))
    ints = stack([np.arange(3), np.arange(3)] * k)
    assert ints.dtype == np.float64 and np.array_equal(ints, [[0, 1, 2], [0, 1, 2]] * k)
    # a float64 first row and an int64 one of the same byte size: not read as float bytes
    mixed = stack([np.zeros(2), np.array([1, 2], dtype=np.int64)] * k)
    assert np.array_equal(mixed, [[0.0, 0.0], [1.0, 2.0]] * k)
    assert np.array_equal(stack([np.ones(2, np.float32), np.ones(2)] * k), np.ones((2 * k, 2)))
    assert np.array_equal(stack([np.ones(2).astype(">f8"), np.ones(2)] * k), np.ones((2 * k, 2)))


@pytest.mark.parametrize("k", [1, 20])
def test_rows_of_different_shapes_refused(k: int) -> None:
    with pytest.raises(ValueError):
        stack([np.zeros(4), np.zeros(6), np.zeros(2)] * k)  # the bytes of rows of 4: still refused
    with pytest.raises(ValueError):
        stack([np.zeros((2, 2)), np.zeros(4)] * k)
    with pytest.raises(ValueError):
        stack([[1.0, 2.0], [1.0]] * k)


def test_none_given_shape() -> None:
    assert stack([], (3, 3)).shape == (0, 3, 3)
