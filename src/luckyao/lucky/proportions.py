"""A fraction of correlated frames with its binomial interval: the probability of a lucky frame.

Frames are correlated in time (the turbulence moves past in tens of frames), so ``N`` frames
hold fewer independent draws: the effective sample size is ``N / g`` with ``g`` the variance
inflation of a mean of the series, ``g = N var(mean) / var(x)`` (the integrated autocorrelation
time, twice it less one in frames; Geyer 1992, Stat. Sci. 7, 473), ``var(mean)`` from batch
means (:func:`.accumulation.batch_mean_error`). The interval is Wilson's score interval (Wilson
1927, JASA 22, 209; Brown, Cai & DasGupta 2001, Stat. Sci. 16, 101) at that sample size: never
of zero width, also when no frame (or every frame) qualifies, where a batch-means error is 0.
"""

import numpy as np

from .accumulation import batch_mean_error

Z_ONE_SIGMA = 1.0
"""The interval's half-width in standard deviations: 68.3 %, as the study's other errors."""


def wilson_interval(fraction, n, z: float = Z_ONE_SIGMA) -> tuple[np.ndarray, np.ndarray]:
    """Wilson's score interval (low, high) of a binomial proportion ``fraction`` observed in
    ``n`` independent trials (arrays broadcast), holding ``fraction``: centre ``(p + z^2/2n) / (1 + z^2/n)``,
    half-width ``z sqrt(p (1 - p) / n + z^2 / 4n^2) / (1 + z^2/n)``."""
    p, n = np.asarray(fraction, dtype=float), np.asarray(n, dtype=float)
    shrink = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / shrink
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / shrink
    # p lies inside in exact arithmetic; at p = 0 or 1 rounding may leave a bound 1e-20 beyond it
    return np.minimum(np.clip(centre - half, 0.0, 1.0), p), np.maximum(np.clip(centre + half, 0.0, 1.0), p)


def effective_sample_size(series: np.ndarray, n_blocks: int) -> float:
    """``N / g``, ``g = N var(mean) / var(x)`` with ``var(mean)`` from ``n_blocks`` batch
    means, ``g`` kept within [1, N] (a series of independent values: N; a constant one: N)."""
    x = np.asarray(series, dtype=float)
    n, spread = len(x), float(np.var(x, ddof=1))
    if n_blocks < 2 or spread == 0.0:
        return float(n)
    inflation = n * batch_mean_error(x, n_blocks) ** 2 / spread
    return float(n / np.clip(inflation, 1.0, n))


def lucky_fraction(values: np.ndarray, threshold: float, n_blocks: int) -> dict:
    """The fraction of frames whose ``values`` (a per-frame series, e.g. the short-exposure
    Strehl) exceed ``threshold``: ``fraction``, its Wilson interval ``low``/``high`` at the
    series' effective sample size ``n_effective`` (the correlation of ``values`` itself, which
    a count of 0 or N does not hide), and the frames ``n_frames``."""
    values = np.asarray(values, dtype=float)
    fraction = float(np.mean(values > threshold))
    n_effective = effective_sample_size(values, n_blocks)
    low, high = wilson_interval(fraction, n_effective)
    return {
        "fraction": fraction,
        "low": float(low),
        "high": float(high),
        "n_effective": n_effective,
        "n_frames": len(values),
    }
