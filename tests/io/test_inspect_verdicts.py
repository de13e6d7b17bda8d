"""`fusion inspect`'s NIS/NEES verdicts (fusion.io.inspect.verdict: chi-square over the effectively
independent samples of time-correlated ones) say "consistent" at about the nominal 95 % rate for
well-matched filters, where the independent-samples chi-square rule it replaced did not (NEES of cv1d_a: 14 of 40 seeds)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from fusion.io.inspect import verdict
from fusion.scenarios import reference, run_reference

SEEDS = range(2000, 2040)


def _prior_from_p0(ref, seed: int):
    """The filter's start drawn from N(truth0, P0): a consistent prior."""
    rng = np.random.default_rng([seed, 1])
    L = np.linalg.cholesky(ref.P0)
    return dataclasses.replace(ref, x0=ref.truth0 + L @ rng.standard_normal(ref.truth0.shape[0]))


def _independent(values: np.ndarray, dof: int) -> bool:
    lo, hi = chi2.ppf([0.025, 0.975], dof * values.size)
    return bool(lo <= values.sum() <= hi)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cv1d_a", "radar2d"], ids=["cv1d_a", "radar2d-prior-start"])
def test_consistent_at_about_the_nominal_rate(name: str) -> None:
    ok = {"NIS": 0, "NEES": 0}
    old_nees = 0
    for seed in SEEDS:
        ref = _prior_from_p0(reference(name, seed=seed), seed)
        run = run_reference(ref)
        n, m = ref.x0.shape[0], ref.meas.ndim_meas
        ok["NIS"] += verdict(run.nis, np.full(run.nis.size, m)).verdict == "consistent"
        v = verdict(run.nees, np.full(run.nees.size, n))
        ok["NEES"] += v.verdict == "consistent"
        old_nees += _independent(run.nees, n)
    rates = {k: v / len(SEEDS) for k, v in ok.items()}
    msg = f"{name}: consistent in {rates} of {len(SEEDS)} seeds (independent-samples rule, NEES: {old_nees})"
    assert 0.85 <= rates["NIS"] <= 1.0, msg
    if name == "cv1d_a":
        assert 0.80 <= rates["NEES"] <= 1.0, msg
    else:  # radar2d forgets almost nothing: one run holds few independent NEES samples, and the
        # autocorrelation estimated from that run stays short of them (measured 29 of 40): better
        # than the independent rule by far, below nominal; several runs are the way to tell
        assert rates["NEES"] >= 0.6 and ok["NEES"] >= 3 * old_nees, msg


def test_verdict_detects_a_mismatch_and_says_what_it_assumes() -> None:
    rng = np.random.default_rng(7)
    x = rng.chisquare(2, 2000)
    good = verdict(x, np.full(x.size, 2))
    assert good.verdict == "consistent" and "autocorrelation time" in good.assumes
    assert verdict(1.3 * x, np.full(x.size, 2)).verdict == "too high"
    assert verdict(0.7 * x, np.full(x.size, 2)).verdict == "too low"
    walk = np.repeat(x[:100], 20)  # each value held 20 steps: about 20 times fewer independent samples
    assert verdict(walk, np.full(walk.size, 2)).assumes.split("time ")[1].split()[0] != "1.0"
    assert verdict(np.empty(0), np.empty(0)).verdict == "no data"
