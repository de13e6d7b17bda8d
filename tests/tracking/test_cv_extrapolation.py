"""fusion.tracking.cv_extrapolation against the numpy array expressions it replaced in
TrackSet.predicted_position: the same bits, for any rows, steps (forward, backward, zero), with
and without velocity components, negative and NaN variances."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.tracking.cv_extrapolation import extrapolated


def numpy_reference(X, P, t, rows, t_ns, q2, pos_idx, vel_idx):
    """TrackSet.predicted_position as it was: gathers and array arithmetic."""
    X, P, t = X[rows], P[rows], t[rows]
    n = X.shape[1]
    dt = ((t_ns - t) * 1e-9)[:, None]
    flat = P.reshape(P.shape[0], n * n)
    pos, vpp = X.take(pos_idx, axis=1), flat.take([p * (n + 1) for p in pos_idx], axis=1)
    if not vel_idx:
        return pos, vpp + q2 * np.abs(dt)
    pv = [p * n + v for p, v in zip(pos_idx, vel_idx, strict=True)]
    vv = [v * (n + 1) for v in vel_idx]
    var = vpp + 2.0 * dt * flat.take(pv, axis=1) + dt * dt * flat.take(vv, axis=1) + q2 * dt**3 / 3.0
    return pos + X.take(vel_idx, axis=1) * dt, np.maximum(var, 0.0)


AXES = [((0, 2), (1, 3)), ((0, 1, 2), (3, 4, 5)), ((0, 1), ())]  # (position, velocity) components


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 12), st.sampled_from(AXES),
       st.floats(0.0, 50.0), st.sampled_from([0, 1, 10**6, 123_456_789, 3 * 10**9, -(10**8)]))
def test_the_same_bits_as_the_array_expressions(seed, n_tracks, axes, q2, span_ns):
    pos_idx, vel_idx = axes
    rng = np.random.default_rng(seed)
    n = 6
    X = rng.normal(0, 1e3, (n_tracks, n))
    A = rng.normal(0, 3, (n_tracks, n, n))
    P = A @ A.transpose(0, 2, 1) - (rng.random((n_tracks, 1, 1)) < 0.2) * 50.0  # some negative variances
    P[rng.random(n_tracks) < 0.3] = 0.0  # the variance is the process noise's term alone
    if n_tracks:
        P[0, 0, 0] = np.nan if seed % 3 == 0 else P[0, 0, 0]
    t = rng.integers(10**9, 10**9 + abs(span_ns) + 1, n_tracks).astype(np.int64)
    t_ns = 10**9 + span_ns
    rows = rng.permutation(n_tracks)[: rng.integers(0, n_tracks + 1)].astype(np.intp)
    for r in (rows, np.arange(n_tracks)):
        dt = (t_ns - t[r]) * 1e-9
        noise = q2 * dt**3 / 3.0 if vel_idx else np.full(r.size, q2)  # as TrackSet.predicted_position
        got = extrapolated(X, P, r, dt, noise, np.array(pos_idx, np.intp), np.array(vel_idx, np.intp))
        want = numpy_reference(X, P, t, r, t_ns, q2, list(pos_idx), list(vel_idx))
        for g, w in zip(got, want, strict=True):
            assert g.shape == w.shape
            assert g.view(np.int64).tolist() == np.ascontiguousarray(w).view(np.int64).tolist()
