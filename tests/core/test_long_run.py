"""P stays symmetric positive definite over 100 000 radar2d EKF steps (10 000 s of track).

Every 100th step (1000 checks): smallest eigenvalue (eigvalsh) > 0, P exactly symmetric (the
filter symmetrises), condition number bounded. Truth and measurements are generated up front so
that the loop is only the EKF (about 80 us per predict + update here: 8 s on an idle core).
"""

from __future__ import annotations

import numpy as np

from fusion.scenarios import reference

N_STEPS = 100_000
SEED = 2024


def test_radar2d_ekf_covariance_stays_spd_for_100k_steps() -> None:
    ref = reference("radar2d", seed=SEED)
    rng = np.random.default_rng(SEED)
    motion, meas, dt = ref.motion, ref.meas, ref.dt_s
    F = motion.F(dt)
    L = np.linalg.cholesky(motion.Q_dt(dt))
    w = rng.standard_normal((N_STEPS, 4)) @ L.T
    v = rng.standard_normal((N_STEPS, 2)) * np.array([10.0, 0.01])
    filt = ref.make_filter(check=False)
    st = filt.initial(ref.x0, ref.P0, t_ns=0)
    X = np.empty((N_STEPS, 4))
    x = ref.truth0.copy()
    for k in range(N_STEPS):
        x = F @ x + w[k]
        X[k] = x
    Z = meas.h(X) + v
    min_eig, max_cond, max_asym = np.inf, 0.0, 0.0
    for k in range(N_STEPS):
        st = filt.update(filt.predict(st, (k + 1) * 100_000_000), Z[k], meas).state
        if k % 100 == 99:
            P = st.P
            max_asym = max(max_asym, float(np.max(np.abs(P - P.T))))
            e = np.linalg.eigvalsh(P)
            min_eig = min(min_eig, float(e[0]))
            max_cond = max(max_cond, float(e[-1] / e[0]))
    e_final = np.hypot(*(x - st.x)[[0, 2]])
    msg = (
        f"seed={SEED}: min eigenvalue {min_eig:.3g}, max condition {max_cond:.3g}, "
        f"max asymmetry {max_asym:.3g}, final position error {e_final:.3g} m at range "
        f"{np.hypot(x[0], x[2]):.3g} m"
    )
    assert min_eig > 0.0, msg
    assert max_asym == 0.0, msg
    assert max_cond < 1e8, msg
    assert np.isfinite(st.x).all(), msg
