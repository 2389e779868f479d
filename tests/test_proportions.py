"""The probability of a lucky frame: Wilson's interval and the effective sample size of
correlated frames, against the binomial and AR(1) theory."""

import numpy as np
import pytest
from scipy.stats import binom

from luckyao.lucky.proportions import effective_sample_size, lucky_fraction, wilson_interval


def exact_coverage(interval, p: float, n: int) -> float:
    """The probability that ``interval(k / n, n)`` covers ``p``, k binomial (n, p): summed exactly."""
    k = np.arange(n + 1)
    low, high = interval(k / n, n)
    return float(binom.pmf(k, n, p)[(low <= p) & (p <= high)].sum())


def wald(fraction, n):
    half = np.sqrt(fraction * (1 - fraction) / n)
    return fraction - half, fraction + half


def test_wilson_interval_covers_the_true_probability_68_percent_of_the_time():
    """Exact binomial coverage at n = 200, averaged over p (it oscillates with p, Brown, Cai &
    DasGupta 2001): 68.3 % within 1 % for p in 2-30 %; at p of 0.1-1 %, where 0 lucky frames
    is likely, Wilson's interval still covers ~70 %, the Wald interval (zero width at a count
    of 0) about 54 %."""
    n = 200
    middle = [exact_coverage(wilson_interval, p, n) for p in np.linspace(0.02, 0.3, 200)]
    assert np.mean(middle) == pytest.approx(0.683, abs=0.01)
    rare = np.linspace(0.001, 0.01, 100)
    wilson_rare = np.mean([exact_coverage(wilson_interval, p, n) for p in rare])
    assert wilson_rare == pytest.approx(0.683, abs=0.04)
    assert np.mean([exact_coverage(wald, p, n) for p in rare]) < wilson_rare - 0.1


@pytest.mark.parametrize("count", [0, 50])
def test_a_count_of_none_or_all_has_a_nonzero_interval(count):
    """0 of 50 (or 50 of 50): the bound is z^2 / (n + z^2) = 1/51 from the edge, not 0."""
    low, high = wilson_interval(count / 50, 50)
    assert high - low == pytest.approx(1 / 51)
    assert (low, high) == ((0.0, pytest.approx(1 / 51)) if count == 0 else (pytest.approx(50 / 51), 1.0))


def test_effective_sample_size_of_an_ar1_series():
    """x_t = rho x_(t-1) + e_t: the variance of the mean of N values is inflated by
    (1 + rho) / (1 - rho), so N / 3 independent values at rho = 0.5 (batch means of 20 blocks
    of 5,000, within 20 %); independent values give N (within 25 %)."""
    rng = np.random.default_rng(5)
    n, rho = 100_000, 0.5
    e = rng.normal(size=n)
    x = np.empty(n)
    x[0] = e[0]
    for t in range(1, n):
        x[t] = rho * x[t - 1] + e[t]
    assert effective_sample_size(x, 20) == pytest.approx(n * (1 - rho) / (1 + rho), rel=0.2)
    assert effective_sample_size(e, 20) == pytest.approx(n, rel=0.25)


def test_lucky_fraction_counts_frames_above_the_threshold():
    values = np.array([0.05, 0.15, 0.25, 0.35] * 25)
    found = lucky_fraction(values, 0.2, 5)
    assert found["fraction"] == 0.5 and found["n_frames"] == 100
    assert found["low"] < 0.5 < found["high"]


def test_the_interval_holds_the_fraction_at_no_and_every_frame():
    """At a count of 0 or N the bound on that side is the fraction itself, not 1e-20 beyond it
    (rounding of the centre against the half-width: an error bar of negative length)."""
    n = np.concatenate([np.arange(1.0, 2000.0), np.geomspace(2000, 1e7, 500)])
    low, high = wilson_interval(np.zeros_like(n), n)
    assert (low == 0).all() and (high > 0).all()
    low, high = wilson_interval(np.ones_like(n), n)
    assert (high == 1).all() and (low < 1).all()
    p = np.linspace(0, 1, 101)[:, None]
    low, high = wilson_interval(p, n[None, :])
    assert (low <= p).all() and (p <= high).all()
