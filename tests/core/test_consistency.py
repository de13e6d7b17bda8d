"""Filter consistency over N = 50 Monte Carlo runs (seeds 1000 .. 1049).

Statistics (two-sided 95 %, scipy.stats.chi2.ppf):
- NIS, time-averaged over K steps and N runs: N K mean(NIS) ~ chi2(N K m). The innovations of a
  consistent filter are white, so the K N terms are independent and the interval is exact.
- NEES, averaged over the N runs at each step k: N mean_k(NEES) ~ chi2(N n), exact because the
  runs are independent. Asserted at the final step, and for at least 85 % of the steps (95 %
  expected; steps are correlated so the fraction scatters).
  The time-averaged NEES with chi2(N K n) is only reported: estimation errors are strongly
  correlated in time (radar2d with q = 0.01 forgets almost nothing), so that interval is far
  narrower than the statistic's real spread and rejects consistent filters (measured: radar2d
  with a prior drawn from N(truth0, P0) gives 4.203 against [3.936, 4.064]).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from fusion.scenarios import Reference, reference, run_reference

N_RUNS = 50
SEED0 = 1000


def _prior_from_p0(ref: Reference, seed: int) -> Reference:
    """The same scenario with the filter's start drawn from N(truth0, P0) (a consistent prior)."""
    rng = np.random.default_rng([seed, 1])
    L = np.linalg.cholesky(ref.P0)
    return dataclasses.replace(ref, x0=ref.truth0 + L @ rng.standard_normal(ref.truth0.shape[0]))


def _monte_carlo(name: str, k0: int, modify=None) -> tuple[np.ndarray, np.ndarray, int, int]:
    nees, nis = [], []
    for i in range(N_RUNS):
        seed = SEED0 + i
        ref = reference(name, seed=seed)
        if modify is not None:
            ref = modify(ref, seed)
        run = run_reference(ref)
        nees.append(run.nees[k0:])
        nis.append(run.nis[k0:])
    return np.array(nees), np.array(nis), ref.x0.shape[0], ref.meas.ndim_meas


def _check(nees: np.ndarray, nis: np.ndarray, n: int, m: int, label: str) -> None:
    N, K = nees.shape
    nis_lo, nis_hi = chi2.ppf([0.025, 0.975], N * K * m) / (N * K)
    step_lo, step_hi = chi2.ppf([0.025, 0.975], N * n) / N
    tav_lo, tav_hi = chi2.ppf([0.025, 0.975], N * K * n) / (N * K)
    per_step = nees.mean(axis=0)
    inside = float(np.mean((per_step >= step_lo) & (per_step <= step_hi)))
    report = (
        f"{label} (N={N} runs, seeds {SEED0}..{SEED0 + N - 1}, K={K} steps): "
        f"NIS {nis.mean():.4f} in [{nis_lo:.4f}, {nis_hi:.4f}]; "
        f"final-step NEES {per_step[-1]:.3f} in [{step_lo:.3f}, {step_hi:.3f}]; "
        f"steps inside {inside:.2f}; "
        f"(time-averaged NEES {nees.mean():.4f}, chi2(NKn) interval [{tav_lo:.4f}, {tav_hi:.4f}])"
    )
    assert np.isfinite(nees).all() and np.isfinite(nis).all(), report
    assert nis_lo <= nis.mean() <= nis_hi, report
    assert step_lo <= per_step[-1] <= step_hi, report
    assert inside >= 0.85, report


# Measured (seeds 1000..1049):
#   cv1d_a       NIS 0.9955 in [0.9612, 1.0396]; final NEES 1.869 in [1.484, 2.591]; 100 % steps
#   helix3d_ekf  NIS 2.9583 in [2.9325, 3.0683]; final NEES 4.792 in [4.162, 5.914]; 92 % steps
#   radar2d, prior from N(truth0, P0), after 5 s:
#                NIS 2.0016 in [1.9550, 2.0455]; final NEES 4.401 in [3.255, 4.821]; 95 % steps
CASES = {
    "cv1d_a": ("cv1d_a", 0, None),
    "helix3d_ekf": ("helix3d_ekf", 0, None),
    "radar2d_prior_from_P0_after_5s": ("radar2d", 50, _prior_from_p0),
}


@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_consistent(case: str) -> None:
    name, k0, modify = CASES[case]
    nees, nis, n, m = _monte_carlo(name, k0, modify)
    _check(nees, nis, n, m, case)


@pytest.mark.xfail(
    strict=True,
    reason=(
        "scenario setup, not the core: radar2d starts the filter at [900, 25, 900, -10] against "
        "truth [1000, 20, 1000, -15] with P0 = 100 I, a 100 m = 10 sigma error per position axis "
        "that P0 does not cover. The bad prior acts like a wrong pseudo-measurement at t = 0 and "
        "biases the estimate for the whole run (mean error after 5 s about -1.5 m in position and "
        "-0.5 m/s in velocity per axis). Measured after 5 s: final-step NEES 8.21 vs [3.255, "
        "4.821], time-averaged NEES 10.67, NIS 2.0601 vs [1.9550, 2.0455]. With the start drawn "
        "from N(truth0, P0) the same EKF is consistent (test_consistent[radar2d_prior...])."
    ),
)
def test_radar2d_as_specified_consistent_after_5s() -> None:
    nees, nis, n, m = _monte_carlo("radar2d", 50)
    _check(nees, nis, n, m, "radar2d as specified, after 5 s")
