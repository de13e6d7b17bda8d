"""NIS / NEES consistency verdicts of `fusion inspect`, for one run or several independent runs.

For K independent samples of a consistent filter, sum(values) ~ chi2(sum(dofs)). Estimation
errors are correlated in time (NEES above all: a slowly forgetting filter carries its initial
error for the whole run), so the samples of one track are not independent. The verdict
estimates the integrated autocorrelation time tau of the samples, pooled over the independent
sequences it is given (each track of each run, in time order; Geyer's initial positive sequence;
about the pooled sample mean, corrected for that estimator's low bias in sequences of L samples,
E[tau_hat] ~ tau (1 - tau / L); with several sequences at least the batch-means estimate from the
spread of their means, `batch_means_time`), and tests the mean against the interval of K / tau effectively
independent samples: chi2.ppf((0.025, 0.975), sum(dofs) / tau) / (K / tau). White samples (NIS
of a consistent filter) give tau ~ 1, the plain chi-square test.

An autocorrelation time estimated from one sequence is reliable only when the sequence is long
against it (L >= ~50 tau, Sokal's rule): a shorter sequence cannot show correlations longer than
itself, tau comes out low and the interval too narrow. A too narrow interval cannot turn a
"consistent" into a wrong one (the true, wider interval holds the mean too), but it can raise a
false alarm. So, with fewer than MIN_EFFECTIVE effective samples in fewer than MIN_SEQUENCES
independent sequences, a mean outside the interval is "inconclusive" (with the number of
effective samples) unless it lies outside even the widest interval, that of one independent
sample per sequence (tau = L), where it is "too high" / "too low" whatever tau is. Several
sequences (independent runs, or independent targets) show the persistent part as differences
between their means, which the pooled estimate about the common mean sees.
From the spread of the run means over 400 seeds (the runs of tests/io/test_inspect_verdicts.py),
one run of radar2d with the start drawn from the prior holds about 2 effectively independent NEES
samples (tau ~ 107 of its 200 steps), one run of cv1d_a about 5 (tau ~ 21 of 100). Over the
test's seeds, one run: radar2d 29 consistent, 11 inconclusive, no false alarm in 40; cv1d_a 32,
8, none; 40 groups of 5 runs: 38 and 39 of 40 consistent.

Independent runs of one scenario (Bar-Shalom's Monte Carlo test, `per_time`): at each time held by
all N runs, the sum of the N runs' values is chi2(sum of their dofs), i.e. the run-averaged NEES
is chi2(n N) / N; the fraction of times inside that 95 % interval is reported (0.95 expected; the
times are correlated, so it scatters more than a binomial fraction would). The verdict itself is
the time average over all runs, tested as above with tau pooled over every run's tracks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

MIN_EFFECTIVE = 50  # effective samples below which one sequence cannot show its own correlation
MIN_SEQUENCES = 5  # independent sequences from which the pooled estimate is trusted at any length


@dataclass
class PerTime:
    """Run-averaged values at each time held by every run (Bar-Shalom's N-run test)."""

    runs: int
    times: int  # times held by every run
    inside: int  # of them, how many within their 95 % interval chi2(sum dofs) / sum dofs
    interval: tuple[float, float] | None  # 95 % interval of the average value per sample at the first time


@dataclass
class Consistency:
    samples: int
    dof: int  # total degrees of freedom
    mean: float | None  # mean value per sample
    interval: tuple[float, float] | None  # 95 % interval of the mean per sample
    verdict: str  # "consistent" | "too high" | "too low" | "inconclusive" | "no data"
    assumes: str = ""
    effective: float = 0.0  # effectively independent samples (K / tau)
    runs: int = 1
    per_time: PerTime | None = None

    def describe(self) -> str:
        """The verdict in words: 'consistent', or 'inconclusive: 8 effective samples'."""
        if self.verdict == "inconclusive":
            return f"inconclusive: {self.effective:.0f} effective samples"
        return self.verdict


def autocorrelation_time(seqs: list[np.ndarray], mean: float) -> float:
    """Integrated autocorrelation time tau = 1 + 2 sum_k rho_k of samples pooled over sequences
    (each in time order), rho from the pooled autocovariance about `mean` (the pooled sample mean:
    differences between the sequences' means then show as correlation), by FFT, the sum cut by
    Geyer's initial positive sequence (pairs rho_2m + rho_2m+1 summed while positive). At least 1."""
    seqs = [q for q in seqs if q.size > 1]
    if not seqs:
        return 1.0
    n_max = max(q.size for q in seqs)
    acov = np.zeros(n_max)
    pairs = np.zeros(n_max)
    for q in seqs:
        x = q - mean
        f = np.fft.rfft(x, 2 * q.size)
        acov[: q.size] += np.fft.irfft(f * np.conj(f))[: q.size]
        pairs[: q.size] += np.arange(q.size, 0, -1)
    if acov[0] <= 0:
        return 1.0
    rho = (acov / pairs) / (acov[0] / pairs[0])
    tau = -1.0
    for m in range(n_max // 2):
        g = rho[2 * m] + rho[2 * m + 1]
        if g <= 0:
            break
        tau += 2.0 * g
    return max(tau, 1.0)


def batch_means_time(seqs: list[np.ndarray]) -> float:
    """Autocorrelation time from the spread of the sequences' means (each sequence a batch):
    Var(mean of L correlated samples) ~ sigma^2 tau / L, so tau ~ sum_j L_j (m_j - m)^2 / ((J - 1)
    sigma^2), m the pooled mean, sigma^2 the pooled variance; capped at the mean length, 1 for fewer
    than two sequences. It sees a persistence longer than the sequences, which Geyer's sum cannot."""
    seqs = [q for q in seqs if q.size > 1]
    if len(seqs) < 2:
        return 1.0
    allv = np.concatenate(seqs)
    var = float(allv.var(ddof=1))
    if var <= 0:
        return 1.0
    m = float(allv.mean())
    tau = sum(q.size * (float(q.mean()) - m) ** 2 for q in seqs) / ((len(seqs) - 1) * var)
    return float(min(tau, np.mean([q.size for q in seqs])))


def verdict(values: np.ndarray, dofs: np.ndarray, seqs: list[np.ndarray] | None = None, *,
            runs: int = 1) -> Consistency:
    """See the module docstring. values, dofs: per sample; seqs: the values of each independent
    sequence (track) in time order, over all `runs` (one sequence of all values when not given)."""
    k = int(values.size)
    if k == 0:
        return Consistency(0, 0, None, None, "no data", "", runs=runs)
    total, dof = float(values.sum()), int(dofs.sum())
    seqs_ = [q for q in (seqs if seqs is not None else [values]) if q.size]
    tau_hat = autocorrelation_time(seqs_, float(values.mean()))
    # about the sample mean, the estimate is biased low: E[tau_hat] ~ tau (1 - tau / L) for
    # sequences of L samples; solved for tau (capped at L / 2)
    L = float(np.mean([q.size for q in seqs_ if q.size > 1] or [k]))
    tau = L / 2 * (1 - np.sqrt(1 - 4 * tau_hat / L)) if tau_hat < L / 4 else L / 2
    tau = max(float(tau), batch_means_time(seqs_), 1.0)
    k_eff = k / tau
    nu = dof / tau  # chi-square degrees of freedom of the k_eff effectively independent samples
    lo, hi = chi2.ppf(0.025, nu) / k_eff, chi2.ppf(0.975, nu) / k_eff
    mean = total / k
    n_seq = sum(q.size > 1 for q in seqs_)
    who = f"{runs} independent runs" if runs > 1 else "one run"
    how = (f"{who}, {n_seq} track sequences; time-correlated samples: autocorrelation time {tau:.1f} samples, "
           f"so {k_eff:.0f} effectively independent ones; sum ~ chi2(sum of dofs / {tau:.1f}) scaled")
    if lo <= mean <= hi:
        return Consistency(k, dof, mean, (float(lo), float(hi)), "consistent", how, k_eff, runs)
    # outside: a tau estimated too short (the interval too narrow) would make this a false alarm,
    # unless the mean is outside even the widest interval (one independent sample per sequence)
    lo_w, hi_w = chi2.ppf(0.025, dof / L) / (k / L), chi2.ppf(0.975, dof / L) / (k / L)
    trusted = k_eff >= MIN_EFFECTIVE or n_seq >= MIN_SEQUENCES
    if not trusted and lo_w <= mean <= hi_w:
        return Consistency(k, dof, mean, (float(lo), float(hi)), "inconclusive",
                           how + f"; too few to trust tau (under {MIN_EFFECTIVE} effective samples in under "
                                 f"{MIN_SEQUENCES} sequences), and inside [{lo_w:.3f}, {hi_w:.3f}], the interval of "
                                 "one independent sample per sequence: give several independent runs", k_eff, runs)
    if not trusted:
        how += f"; outside even [{lo_w:.3f}, {hi_w:.3f}], the interval of one independent sample per sequence"
    return Consistency(k, dof, mean, (float(lo), float(hi)), "too high" if mean > hi else "too low", how, k_eff,
                       runs)


def per_time(t_ns: np.ndarray, run: np.ndarray, values: np.ndarray, dofs: np.ndarray) -> PerTime:
    """Bar-Shalom's N-run test at each time held by every run: sum of the values at t against
    chi2.ppf((0.025, 0.975), sum of the dofs at t) (the run average: the same divided by N)."""
    n_runs = int(np.unique(run).size)
    if not t_ns.size:
        return PerTime(n_runs, 0, 0, None)
    times, inv = np.unique(t_ns, return_inverse=True)
    runs_at = np.zeros(times.size, dtype=np.int64)
    pairs = np.unique(np.stack([inv, run]), axis=1)  # (time, run) pairs present
    np.add.at(runs_at, pairs[0], 1)
    s = np.bincount(inv, weights=values, minlength=times.size)
    d = np.bincount(inv, weights=dofs, minlength=times.size)
    full = runs_at == n_runs
    if not full.any():
        return PerTime(n_runs, 0, 0, None)
    lo, hi = chi2.ppf(0.025, d[full]), chi2.ppf(0.975, d[full])
    inside = int(np.sum((s[full] >= lo) & (s[full] <= hi)))
    c = np.bincount(inv, minlength=times.size)[full][0]  # samples at the first time: the average's divisor
    return PerTime(n_runs, int(full.sum()), inside, (float(lo[0] / c), float(hi[0] / c)))
