"""The compiled and shortened parts of the scan (issue 11) give what the numpy formulations they
replace gave, bit for bit: the IMM predict's distinct steps and its per-step F, Q kept across
scans, the innovation per mode indexed in place, the lifecycle's per-row rules, id membership and
a re-run's pairs, reach and part (rerun_sets), the predicted positions, a one-dimension scan's stacks
the assignment's two stages (confirmed_first) and the births' mode combination (combine_each)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.association import gnn_assign
from fusion.core.compiled_imm import distinct, innovate_modes
from fusion.core.compiled_stack import innovate_many
from fusion.core.imm import combine, combine_each
from fusion.core.imm_stack import StepCache, predict_imm
from fusion.core.modes import Mode, build_imm
from fusion.tracking.association_kernels import confirmed_first
from fusion.tracking.gating import Measured
from fusion.tracking.id_sets import member, repeats, rerun_sets
from fusion.tracking.lifecycle_kernel import COASTED, COVARIANCE, MISSES, NOT_CONFIRMED, verdicts
from fusion.tracking.trackset import Layout, Rows, Status, TrackSet


def _bits(*arrays: np.ndarray) -> list[bytes]:
    return [a.dtype.str.encode() + str(a.shape).encode() + np.ascontiguousarray(a).tobytes() for a in arrays]


def _spd(rng: np.random.Generator, n: int, *lead: int) -> np.ndarray:
    A = rng.standard_normal((*lead, n, n))
    return A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(n)


def _imm():
    return build_imm([Mode("cv", 0.05, 120.0, 0.001), Mode("ct", 0.05, 10.0, 0.001)])


@pytest.mark.parametrize("seed", range(4))
def test_distinct_is_numpys_unique_with_inverse(seed: int) -> None:
    rng = np.random.default_rng(seed)
    dt = rng.choice([0.0, 0.05, 0.1, 0.15, 0.1 + 1e-17, 2.5], size=int(rng.integers(1, 60)))
    du, inv = distinct(dt)
    ru, rinv = np.unique(dt, return_inverse=True)
    assert _bits(du) == _bits(ru)
    np.testing.assert_array_equal(inv, rinv)
    assert inv.dtype == np.intp


def test_predict_with_kept_steps_is_the_predict_without() -> None:
    rng = np.random.default_rng(3)
    imm = _imm()
    N, M, n = 40, 2, 5
    steps = StepCache(size=2)
    for rep in range(5):  # steps repeat, and more kinds than the cache holds: kept, forgotten, rebuilt
        xs = rng.normal(size=(N, M, n)) * [100.0, 10.0, 100.0, 10.0, 0.05]
        Ps = _spd(rng, n, N, M)
        mu = rng.dirichlet([1.0, 1.0], size=N)
        dt = rng.choice([0.0, 0.05, 0.1, 0.2 * (rep % 3 + 1)], size=N)
        a = predict_imm(imm, xs, Ps, mu, dt)
        b = predict_imm(imm, xs, Ps, mu, dt, steps)
        assert _bits(a.xs, a.Ps, a.c, a.x, a.P) == _bits(b.xs, b.Ps, b.c, b.x, b.P)


def test_kept_steps_are_the_models_matrices() -> None:
    imm = _imm()
    du = np.array([0.05, 0.1, 0.3])
    got = StepCache().of(imm, du)
    for (F, Q), f in zip(got, imm.filters, strict=True):
        m = f.motion
        if F is not None:
            assert _bits(F) == _bits(np.asarray(m.F(du)))
        assert Q is not None and _bits(Q) == _bits(np.asarray(m.Q(np.zeros((3, 5)), du)))
    steps = StepCache()
    for _ in range(2):  # made, then kept
        assert _bits(steps.transitions(imm, du)) == _bits(np.stack([imm.transition(d) for d in du.tolist()]))


@pytest.mark.parametrize(("n", "m"), [(5, 2), (4, 1), (6, 3)])
def test_innovation_per_mode_in_place_is_the_stacked_innovation(n: int, m: int) -> None:
    rng = np.random.default_rng(n + m)
    K, M, N = 30, 3, 50
    Ps = _spd(rng, n, K, M)
    rows = rng.integers(0, K, N).astype(np.intp)
    Y = rng.normal(size=(N, M, m))
    H = rng.normal(size=(N, M, m, n))
    R = _spd(rng, m, N) * 0.1
    ok, Ss, ll = innovate_modes(Ps, rows, Y, H, R)
    assert ok
    for j in range(M):
        okj, S, _, lj = innovate_many(np.ascontiguousarray(Ps[rows, j]), np.ascontiguousarray(Y[:, j]),
                                      np.ascontiguousarray(H[:, j]), R)
        assert okj.all()
        assert _bits(Ss[:, j], ll[:, j]) == _bits(S, lj)
    R[5] = -1e6 * np.eye(m)  # one S not positive definite: the whole stack is refused
    assert not innovate_modes(Ps, rows, Y, H, R)[0]


@pytest.mark.parametrize("seed", range(5))
def test_lifecycle_rules_are_the_numpy_rules(seed: int) -> None:
    rng = np.random.default_rng(seed)
    K = 400
    hit = rng.random(K) < 0.5
    chance = hit | (rng.random(K) < 0.5)
    chances = rng.integers(0, 9, K).astype(np.int64)
    misses = rng.integers(0, 4, K).astype(np.int64)
    tent = rng.random(K) < 0.4
    hits = rng.integers(0, 6, K).astype(np.int64)
    t_ns = 10**10
    t = t_ns - rng.integers(0, 3 * 10**9, K).astype(np.int64)
    too_wide = rng.random(K) < 0.05
    confirm_n, confirm_m, max_misses, coast_ns = 6, 4, 2, 2 * 10**9
    c, m, why, coasting = verdicts(hit, chance, chances, misses, tent, hits, t, too_wide, t_ns, confirm_n,
                                   confirm_m, max_misses, coast_ns)
    rc = chances + chance
    rm = np.where(hit, 0, misses + chance)
    not_confirmed = tent & (rc >= confirm_n) & (hits < confirm_m)
    missed = ~tent & (rm > max_misses)
    coasted = (t_ns - t) > coast_ns
    delete = not_confirmed | missed | coasted | too_wide
    rcoasting = ~tent & ~delete & (rm == 1) & (misses == 0)
    rwhy = np.select([not_confirmed, missed, coasted, too_wide], [NOT_CONFIRMED, MISSES, COASTED, COVARIANCE], 0)
    assert _bits(c, m) == _bits(rc, rm)
    np.testing.assert_array_equal(why, rwhy)
    np.testing.assert_array_equal(why != 0, delete)
    np.testing.assert_array_equal(coasting, rcoasting)
    assert delete.any() and rcoasting.any() and len(set(rwhy.tolist())) == 5


@pytest.mark.parametrize("seed", range(4))
def test_member_is_isin(seed: int) -> None:
    rng = np.random.default_rng(seed)
    of = rng.integers(-(2**62), 2**62, int(rng.integers(1, 50)))
    values = np.concatenate([of[rng.integers(0, of.size, 20)], rng.integers(-(2**62), 2**62, 20)])
    rng.shuffle(values)
    np.testing.assert_array_equal(member(values, of), np.isin(values, of))
    assert member(values, of[:0]).shape == values.shape and not member(values, of[:0]).any()
    assert member(values[:0], of).shape == (0,)



@pytest.mark.parametrize("seed", range(4))
def test_repeats_is_a_sorted_array_with_fewer_unique_values(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for n in (0, 1, 2, 3, 50):
        a = np.sort(rng.integers(0, max(n, 1) * 2, n))
        assert repeats(a) == (np.unique(a).size < a.size), a
        u = np.unique(a)
        assert not repeats(u)
        if u.size:
            k = int(rng.integers(u.size))
            assert repeats(np.insert(u, k, u[k]))  # one value twice, anywhere

def _grown_reference(e_ids, e_seqs, seed_ids, seed_seqs):
    """The growth loop fusion.tracking.replay ran before (np.isin, np.union1d)."""
    hot_ids, hot_seqs = np.unique(seed_ids), np.unique(seed_seqs)
    while True:
        m = np.isin(e_ids, hot_ids) | np.isin(e_seqs, hot_seqs)
        more_ids, more_seqs = np.union1d(hot_ids, e_ids[m]), np.union1d(hot_seqs, e_seqs[m])
        if more_ids.size == hot_ids.size and more_seqs.size == hot_seqs.size:
            return hot_ids, hot_seqs
        hot_ids, hot_seqs = more_ids, more_seqs


def _rerun_sets_reference(old_ids, old_seqs, ts_ids, changed, gone, add_ids, add_seqs, new_seqs, seqs, via=None):
    """The steps fusion.tracking.replay took before rerun_sets, one numpy call at a time: the new
    pairs (_new_gates), the reach over the stored pairs `via` (default: the old coarse ones) and
    the added ones (_reach), its rows and detections, and the coarse gate of the part (_sub_coarse:
    the new pairs with both ends in the reach)."""
    keep = np.isin(old_ids, ts_ids[~changed])
    new_ids, nseqs = np.concatenate([old_ids[keep], add_ids]), np.concatenate([old_seqs[keep], add_seqs])
    via_ids, via_seqs = (old_ids, old_seqs) if via is None else via
    hot_ids, hot_seqs = _grown_reference(np.concatenate([add_ids, via_ids]), np.concatenate([add_seqs, via_seqs]),
                                         np.concatenate([ts_ids[changed], gone]), new_seqs)
    rows, js = np.flatnonzero(np.isin(ts_ids, hot_ids)), np.flatnonzero(np.isin(seqs, hot_seqs))
    sub = ts_ids[rows]
    inside = np.isin(new_ids, sub) & np.isin(nseqs, seqs[js])
    i = np.array([int(np.flatnonzero(sub == x)[0]) for x in new_ids[inside]], dtype=np.int64)
    j = np.searchsorted(seqs[js], nseqs[inside])
    o = np.lexsort((i, j))
    return new_ids, nseqs, rows, js, i[o], j[o]


@pytest.mark.parametrize("equal", [False, True], ids=["unique-seqs", "equal-seqs"])
@pytest.mark.parametrize("fine", [False, True], ids=["via-coarse", "via-fine"])
@pytest.mark.parametrize("size", [(40, 50, 70, 8), (700, 800, 1500, 60)], ids=["few-pairs", "many-pairs"])
@pytest.mark.parametrize("seed", range(12))
def test_rerun_sets_are_the_steps_they_replaced(seed: int, size: tuple[int, int, int, int], fine: bool,
                                                equal: bool) -> None:
    """A stored run's pairs over T tracks and D detections (up to E pairs; the 5 last detections
    new), some tracks changed, some gone, new detections, up to A added pairs of the changed
    tracks and new detections: few pairs (a partial re-run at 100 targets) and many (at ~700).
    The reach follows the stored coarse pairs, or
    (`fine`) a subset of them, as the stored run's fine pairs are: then some new pairs of
    reached tracks end outside the reach, and are not the part's. `equal`: some seqs twice and a
    track id on two rows (a sensor restarted: another epoch's measurements with the same seqs, and
    the tracks they start at the same times, whose ids are those of the first epoch's)."""
    T, D, E_max, A_max = size
    rng = np.random.default_rng(seed)
    before = rng.choice(2**62, T, replace=False).astype(np.int64)
    seqs = np.sort(rng.choice(10**6, D, replace=False)).astype(np.int64)
    if equal:
        seqs = np.sort(np.concatenate([seqs[: D - D // 4], seqs[: D // 4]]))
    E = int(rng.integers(E_max // 2 if T > 100 else 0, E_max))
    old_ids, old_seqs = before[rng.integers(0, T, E)], seqs[rng.integers(0, D - 5, E)]  # the last 5 detections new
    pairs = np.unique(np.stack([old_ids, old_seqs], axis=1), axis=0)
    old_ids, old_seqs = pairs[:, 0].copy(), pairs[:, 1].copy()
    gone_mask = rng.random(T) < 0.1
    ts_ids = np.concatenate([before[~gone_mask], rng.choice(2**62, 2).astype(np.int64)])  # two born since
    if equal:
        ts_ids[-1] = ts_ids[0]  # one of them with the id of another row
    changed = rng.random(ts_ids.size) < 0.15
    changed[-2:] = True  # tracks the stored run did not have are changed
    if equal:
        changed[0] = True  # and the row whose id the last one shares (the seeds are ids)
    new = np.zeros(D, dtype=bool)
    new[D - 5:] = rng.random(5) < 0.6
    A = int(rng.integers(0, A_max))
    add = np.unique(np.stack([ts_ids[changed][rng.integers(0, changed.sum(), A)], seqs[rng.integers(0, D, A)]],
                             axis=1), axis=0)
    add_ids, add_seqs = add[:, 0].copy(), add[:, 1].copy()
    drop = np.concatenate([ts_ids[changed], before[gone_mask]])
    via = None
    if fine:
        sel = rng.random(old_ids.size) < 0.4
        via = (old_ids[sel], old_seqs[sel])
    got = rerun_sets(old_ids, old_seqs, drop, add_ids, add_seqs, seqs[new], ts_ids, seqs, via=via)
    want = _rerun_sets_reference(old_ids, old_seqs, ts_ids, changed, before[gone_mask], add_ids, add_seqs, seqs[new],
                                 seqs, via)
    assert _bits(*got) == _bits(*(np.asarray(w).astype(np.int64) for w in want))


def test_the_reach_follows_the_fine_pairs_and_the_part_keeps_its_pairs_inside() -> None:
    """Track 10 changed (a seed, no new pairs), track 20 not; detections 1 and 2. Coarse pairs of
    the stored run: (10, 1), (20, 1), (20, 2); its fine pairs: (10, 1), (20, 1). Over the fine
    pairs the reach is tracks 10 and 20 and detection 1, and the part's pairs are (20, 1) alone:
    track 20's coarse pair with detection 2 (not in its fine gate, so it cannot change the
    detection's fate nor the track's) stays out. Over the coarse pairs detection 2 is reached too."""
    old_ids, old_seqs = np.array([10, 20, 20]), np.array([1, 1, 2])
    ts_ids, seqs, none = np.array([10, 20]), np.array([1, 2]), np.zeros(0, np.int64)
    fine = rerun_sets(old_ids, old_seqs, np.array([10]), none, none, none, ts_ids, seqs,
                      via=(np.array([10, 20]), np.array([1, 1])))
    assert [a.tolist() for a in fine] == [[20, 20], [1, 2], [0, 1], [0], [1], [0]]
    coarse = rerun_sets(old_ids, old_seqs, np.array([10]), none, none, none, ts_ids, seqs)
    assert [a.tolist() for a in coarse[2:]] == [[0, 1], [0, 1], [1, 1], [0, 1]]


@pytest.mark.parametrize("vel", [True, False], ids=["pos-vel", "pos-only"])
def test_predicted_position_is_the_fancy_indexed_formula(vel: bool) -> None:
    rng = np.random.default_rng(11)
    K, n = 25, 5
    pi, vi = ((0, 2), (1, 3)) if vel else ((0, 2), ())
    L = Layout(pi, vi, ("a",), n)
    rows = Rows.empty(L)
    ts = TrackSet(Rows(*(np.resize(getattr(rows, f), (K, *getattr(rows, f).shape[1:]))
                         for f in ("ids", "status", "hits", "birth_t_ns")),
                       rng.integers(0, 10**9, K).astype(np.int64),
                       *(np.resize(getattr(rows, f), (K, *getattr(rows, f).shape[1:]))
                         for f in ("chances", "misses", "seen_by", "origin_sensor", "origin_seq", "last_sensor",
                                   "last_seq")),
                       rng.normal(size=(K, n)), _spd(rng, n, K) * (np.arange(K) % 3 != 0)[:, None, None]), L)
    t, q2 = 2 * 10**9, 0.3  # every third P zero: the variance is the noise term alone, to its last bit
    pos, var = ts.predicted_position(t, q2)
    X, P = ts.X, ts.P
    dt = ((t - ts.t_ns) * 1e-9)[:, None]
    p, v = list(pi), list(vi)
    if vel:
        rvar = np.maximum(P[:, p, p] + 2.0 * dt * P[:, p, v] + dt * dt * P[:, v, v] + q2 * dt**3 / 3.0, 0.0)
        rpos = X[:, p] + X[:, v] * dt
    else:
        rvar, rpos = P[:, p, p] + q2 * np.abs(dt), X[:, p]
    assert _bits(pos, var) == _bits(rpos, rvar)


def test_one_dimension_scan_is_stacked_as_the_grouped_one() -> None:
    rng = np.random.default_rng(5)
    z = tuple(rng.normal(size=2) for _ in range(7))
    R = tuple(_spd(rng, 2) for _ in range(7))
    one = Measured.of(z, R, (None,) * 7)  # type: ignore[arg-type]
    mixed = Measured.of((*z, rng.normal(size=3)), (*R, _spd(rng, 3)), (None,) * 8)  # type: ignore[arg-type]
    assert list(one.Z) == [2] and _bits(one.Z[2], one.Rs[2], one.at) == _bits(mixed.Z[2], mixed.Rs[2], mixed.at[:7])
    np.testing.assert_array_equal(one.dims, mixed.dims[:7])


def test_rerun_sets_refuses_pairs_outside_its_tracks_and_detections() -> None:
    """A pair whose track is neither in ts_ids nor a seed, or whose detection is not in seqs,
    has no dense index: refused, not given another's."""
    ts_ids, seqs, none = np.array([10, 20]), np.array([1, 2]), np.zeros(0, np.int64)
    ok = rerun_sets(np.array([10, 30]), np.array([1, 2]), np.array([30]), none, none, none, ts_ids, seqs)
    assert ok[2].tolist() == [] and ok[3].tolist() == [1]  # gone track 30 (a seed) reaches detection 2 alone
    with pytest.raises(ValueError, match="track"):
        rerun_sets(np.array([10, 40]), np.array([1, 2]), np.array([10]), none, none, none, ts_ids, seqs)
    with pytest.raises(ValueError, match="detection"):
        rerun_sets(np.array([10, 20]), np.array([1, 5]), np.array([10]), none, none, none, ts_ids, seqs)


def _two_stages(ti: np.ndarray, mj: np.ndarray, cost: np.ndarray, limit: np.ndarray, nis: np.ndarray,
                conf: np.ndarray, n_tracks: int, n_meas: int) -> list[int]:
    """The scan's assignment as numpy and gnn_assign calls, before confirmed_first."""
    out: list[np.ndarray] = []
    taken = np.zeros(n_meas, dtype=bool)
    for stage, likelihood in ((conf, True), (~conf, False)):
        sel = np.flatnonzero(stage & ~taken[mj])
        if sel.size == 0:
            continue
        c, lim = cost[sel], limit[sel]
        if not likelihood:
            c, lim = np.sqrt(nis[sel]), np.sqrt(lim - c + nis[sel])
        chosen = sel[gnn_assign(ti[sel], mj[sel], c, lim, n_tracks=n_tracks, n_meas=n_meas)]
        out.append(chosen)
        taken[mj[chosen]] = True
    return np.sort(np.concatenate(out)).tolist() if out else []


@pytest.mark.parametrize("seed", range(300))
def test_confirmed_first_is_the_two_stages_it_replaced(seed: int) -> None:
    """Random gated pairs of confirmed and tentative tracks, NIS and gate as the batched gate
    gives them (cost = NIS + ln det S, limit = cost - NIS + g), some at equal costs."""
    rng = np.random.default_rng(seed)
    nt, nm = int(rng.integers(1, 10)), int(rng.integers(1, 10))
    mj, ti = np.nonzero((rng.random((nt, nm)) < rng.random()).T)
    ti, mj = ti.astype(np.intp), mj.astype(np.intp)
    nis = rng.choice([0.5, 1.0, 2.0], size=ti.size) if seed % 3 == 0 else rng.exponential(3.0, size=ti.size)
    cost = nis + rng.normal(size=ti.size)
    limit = cost - nis + 9.21
    status = np.where(rng.random(nt) < 0.5, Status.CONFIRMED.value, Status.TENTATIVE.value).astype(np.int8)[ti]
    want = _two_stages(ti, mj, cost, limit, nis, status == Status.CONFIRMED.value, nt, nm)
    if ti.size:
        assert confirmed_first(ti, mj, cost, limit, nis, status, Status.CONFIRMED.value, nt, nm).tolist() == want


@pytest.mark.parametrize("seed", range(60))
def test_combine_each_is_combine_row_by_row(seed: int) -> None:
    """The births' combination of their modes (scan._born_rows: every mode at (x, P), equally
    likely) and any stack of mixtures, against IMM.combine row by row: bit for bit."""
    rng = np.random.default_rng(seed)
    k, M, n = int(rng.integers(1, 12)), int(rng.integers(1, 5)), int(rng.integers(2, 7))
    if seed % 2:  # births: equal modes, equal probabilities
        X, P = rng.normal(size=(k, n)) * 1e3, _spd(rng, n, k)
        MX, MP, MU = np.repeat(X[:, None], M, axis=1), np.repeat(P[:, None], M, axis=1), np.full((k, M), 1.0 / M)
    else:
        MX, MP = rng.normal(size=(k, M, n)) * 1e3, _spd(rng, n, k, M)
        MU = rng.dirichlet(np.ones(M), size=k)
    x, P = combine_each(MX, MP, MU)
    rows = [combine(MX[b], MP[b], MU[b]) for b in range(k)]
    assert _bits(x, P) == _bits(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]))
