"""The tomography's prior: layered von Karman turbulence ("virtual DMs").

Each layer at ``heights_m`` is a von Karman phase of ``r0_layer = r0 *
fraction^(-3/5)``; covariances come from the structure function of
:mod:`luckyao.atmosphere.statistics`, tabulated for speed.
"""

import math
from dataclasses import dataclass

import numba
import numpy as np

from ..atmosphere.statistics import von_karman_structure_function
from ..units import REFERENCE_WAVELENGTH_M


@dataclass(frozen=True)
class TurbulencePrior:
    """Layered von Karman prior: ``r0_m`` at ``wavelength_m``, outer scale, layers."""

    r0_m: float
    outer_scale_m: float
    heights_m: tuple[float, ...]
    cn2_fractions: tuple[float, ...]
    wavelength_m: float = REFERENCE_WAVELENGTH_M

    def __post_init__(self):
        if len(self.heights_m) != len(self.cn2_fractions):
            raise ValueError("heights_m and cn2_fractions differ in length")


@dataclass(frozen=True, eq=False)
class StructureTable:
    """Fast ``D(r)`` [m^2 of optical path] for r0 = 1 m at the prior wavelength.

    Tabulates ``D(r) / r^(5/3)`` (smooth, finite at 0) on a log grid
    (relative interpolation error < 1e-6); scale by ``r0^(-5/3)``.
    """

    outer_scale_m: float
    wavelength_m: float

    def __post_init__(self):
        log_r = np.linspace(np.log(1e-5), np.log(1e4), 4000)
        r = np.exp(log_r)
        ratio = von_karman_structure_function(r, 1.0, self.outer_scale_m) / r ** (5 / 3)
        object.__setattr__(self, "_log_r", log_r)
        object.__setattr__(self, "_ratio", ratio * (self.wavelength_m / (2 * np.pi)) ** 2)

    def __call__(self, r_m: np.ndarray) -> np.ndarray:
        r = np.maximum(r_m, 1e-12)
        return np.interp(np.log(r), self._log_r, self._ratio) * r ** (5 / 3)

    def weighted_sums(self, targets: np.ndarray, samples: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """``sum_p w_p D(|t - s_vp|)`` (n_t, n_v) for targets (n_t, 2), samples (n_v, p, 2)."""
        out = np.empty((targets.shape[0], samples.shape[0]))
        _weighted_structure_sums(
            np.ascontiguousarray(targets),
            np.ascontiguousarray(samples),
            np.ascontiguousarray(weights, dtype=float),
            self._log_r[0],
            self._log_r[1] - self._log_r[0],
            self._ratio,
            out,
        )
        return out


@numba.njit(cache=True, nogil=True)
def _weighted_structure_sums(targets, samples, weights, log_r_first, log_r_step, ratio, out):  # pragma: no cover (jit)
    """Fused loop for :meth:`StructureTable.weighted_sums` (no temporaries)."""
    n_table = ratio.size
    for t in range(targets.shape[0]):
        tx = targets[t, 0]
        ty = targets[t, 1]
        for v in range(samples.shape[0]):
            acc = 0.0
            for p in range(samples.shape[1]):
                dx = tx - samples[v, p, 0]
                dy = ty - samples[v, p, 1]
                r2 = dx * dx + dy * dy
                if r2 > 0.0:
                    log_r2 = math.log(r2)
                    position = (0.5 * log_r2 - log_r_first) / log_r_step
                    if position < 0.0:
                        position = 0.0
                    i = int(position)
                    if i > n_table - 2:
                        i = n_table - 2
                    frac = position - i
                    value = ratio[i] + (ratio[i + 1] - ratio[i]) * frac
                    acc += weights[p] * value * math.exp(log_r2 * (5.0 / 6.0))
            out[t, v] = acc
