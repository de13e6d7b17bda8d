"""The compiled GNN assignment (fusion.core.association.gnn_assign: union-find components, the
dense problem per component solved by fusion.core.lsap.solve_dense) against the formulation it
replaced, kept here as the reference: scipy's connected components and linear_sum_assignment per
component. The same chosen pairs, in the same order, on random gated-pair graphs: float costs,
and small integer costs and limits (many equal costs and pairs at the gate's edge: the ties,
where only the same algorithm with the same tie rules agrees). And solve_dense alone against
linear_sum_assignment on square matrices with a finite assignment."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fusion.core.association import gnn_assign
from fusion.core.lsap import solve_dense

BIG = 1e18


def reference(ti: np.ndarray, mj: np.ndarray, cost: np.ndarray, limit: np.ndarray, *, n_tracks: int,
              n_meas: int) -> np.ndarray:
    """gnn_assign as it was before 2026-12-07 (scipy per component)."""
    if ti.size == 0:
        return np.zeros(0, dtype=np.intp)
    g = coo_matrix((np.ones(ti.size), (ti, n_tracks + mj)), shape=(n_tracks + n_meas,) * 2)
    _, labels = connected_components(g, directed=False)
    comp = labels[ti]
    sizes = np.bincount(comp, minlength=labels.max() + 1)
    single = sizes[comp] == 1
    out = [np.flatnonzero(single & (cost < limit))]
    rest = np.flatnonzero(~single)
    if rest.size:
        order = rest[np.argsort(comp[rest], kind="stable")]
        for sel in np.split(order, np.flatnonzero(np.diff(comp[order])) + 1):
            miss_cost = 0.5 * float(limit[sel].max())
            ut, it = np.unique(ti[sel], return_inverse=True)
            um, im = np.unique(mj[sel], return_inverse=True)
            a, b = ut.size, um.size
            C = np.full((a + b, b + a), BIG)
            C[it, im] = cost[sel]
            C[np.arange(a), b + np.arange(a)] = miss_cost
            C[a + np.arange(b), np.arange(b)] = miss_cost
            C[a:, b:] = 0.0
            where = np.full((a, b), -1, dtype=np.intp)
            where[it, im] = sel
            r, k = linear_sum_assignment(C)
            real = (r < a) & (k < b)
            r, k = r[real], k[real]
            out.append(where[r, k][C[r, k] < BIG])
    p = np.concatenate(out)
    return p[np.lexsort((ti[p], mj[p]))].astype(np.intp)


def _graph(seed: int, integer: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int]:
    """A random gated-pair graph, pairs sorted by (measurement, track) as a scan gives them."""
    rng = np.random.default_rng(seed)
    nt, nm = int(rng.integers(1, 9)), int(rng.integers(1, 9))
    mask = rng.random((nt, nm)) < rng.random()
    mj, ti = np.nonzero(mask.T)
    if integer:
        cost = rng.integers(-3, 3, size=ti.size).astype(np.float64)
        limit = cost + rng.integers(-1, 4, size=ti.size)
    else:
        cost = rng.normal(size=ti.size) * 3.0
        limit = cost + rng.exponential(3.0, size=ti.size) - 0.5
    return ti.astype(np.intp), mj.astype(np.intp), cost, limit, nt, nm


@settings(max_examples=600, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), integer=st.booleans())
def test_the_same_pairs_as_scipy_per_component(seed: int, integer: bool) -> None:
    ti, mj, cost, limit, nt, nm = _graph(seed, integer)
    got = gnn_assign(ti, mj, cost, limit, n_tracks=nt, n_meas=nm)
    want = reference(ti, mj, cost, limit, n_tracks=nt, n_meas=nm)
    assert got.dtype == np.intp
    assert got.tolist() == want.tolist()


def test_many_graphs_with_ties() -> None:
    """A broad sweep besides hypothesis's: 3000 graphs, half with integer costs."""
    for seed in range(3000):
        ti, mj, cost, limit, nt, nm = _graph(seed, seed % 2 == 0)
        got = gnn_assign(ti, mj, cost, limit, n_tracks=nt, n_meas=nm)
        assert got.tolist() == reference(ti, mj, cost, limit, n_tracks=nt, n_meas=nm).tolist(), seed


def test_edge_cases() -> None:
    e = np.zeros(0, dtype=np.intp)
    assert gnn_assign(e, e, np.zeros(0), np.zeros(0), n_tracks=0, n_meas=0).size == 0
    one = np.array([0])
    assert gnn_assign(one, one, np.array([1.0]), np.array([2.0]), n_tracks=1, n_meas=1).tolist() == [0]
    assert gnn_assign(one, one, np.array([2.0]), np.array([2.0]), n_tracks=1, n_meas=1).tolist() == []
    # a track between two measurements: the cheaper one, unless leaving both free wins
    ti, mj = np.array([0, 0]), np.array([0, 1])
    assert gnn_assign(ti, mj, np.array([3.0, 1.0]), np.array([9.0, 9.0]), n_tracks=1, n_meas=2).tolist() == [1]
    # two tracks, two measurements, crossing: the sum decides (1 + 1 against 0 + 5)
    ti, mj = np.array([0, 1, 0, 1]), np.array([0, 0, 1, 1])
    got = gnn_assign(ti, mj, np.array([0.0, 1.0, 1.0, 5.0]), np.full(4, 20.0), n_tracks=2, n_meas=2)
    assert got.tolist() == [1, 2]


@settings(max_examples=400, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["normal", "integer", "sparse"]))
def test_solve_dense_is_linear_sum_assignment(seed: int, kind: str) -> None:
    """Square matrices with a finite assignment (the identity's diagonal finite where entries are
    missing, as gnn_assign's matrices have their "left free" entries)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 10))
    if kind == "normal":
        C = rng.normal(size=(n, n))
    elif kind == "integer":
        C = rng.integers(0, 3, size=(n, n)).astype(np.float64)
    else:
        C = np.where(rng.random((n, n)) < 0.5, rng.integers(-2, 3, size=(n, n)).astype(np.float64), BIG)
        C[np.arange(n), rng.permutation(n)] = rng.integers(-2, 3, size=n)
    _, col = linear_sum_assignment(C)
    assert solve_dense(C).tolist() == col.tolist()
