"""Intermittent turbulence: each layer's strength varying in time, a log-normal process.

Layer ``l``'s Cn2 weight at time step ``k`` is its mean fraction times a factor
``c_l(k) = exp(x_l(k) - sigma^2 / 2)``, where ``x_l`` is a stationary Ornstein-Uhlenbeck
process of standard deviation ``sigma`` (``sigma_ln``, of ln Cn2) and correlation time ``T``:
``<x(t) x(t + tau)> = sigma^2 exp(-|tau| / T)``. It is drawn exactly at the time step ``dt``
(an AR(1) with ``a = exp(-dt / T)``: ``x(k+1) = a x(k) + sigma sqrt(1 - a^2) n(k)``, ``x(0)``
from the stationary law), so ``E[c] = 1``: the mean Cn2 of every layer, and so the mean
profile the tomography's prior assumes, is kept. The layers are independent, each from its
own stream of the seed (:func:`luckyao.seeds.layer_strength_rng`); the draws are in time
order, so a longer run starts with a shorter one's factors.

The normalised phase screens are only scaled (``studyspec.case.Case.layer_scales``: by
``sqrt(c_l)``), so a case with and one without variability see the same turbulence
(common random numbers).
"""

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from ..seeds import layer_strength_rng


@dataclass(frozen=True)
class LayerVariability:
    """Each layer's Cn2 factor in time: log-normal, ``sigma_ln`` the standard deviation of
    its log, ``correlation_time_s`` that of the log's exponential autocorrelation, drawn
    from ``seed``."""

    sigma_ln: float
    correlation_time_s: float
    seed: int

    def log_factors(self, n_layers: int, n_steps: int, time_step_s: float) -> np.ndarray:
        """``x_l(k)`` (n_steps, n_layers): each layer's zero-mean Gaussian process, variance
        ``sigma_ln^2``, sampled at the time steps."""
        a = np.exp(-time_step_s / self.correlation_time_s)
        out = np.empty((n_steps, n_layers))
        for layer in range(n_layers):
            noise = layer_strength_rng(self.seed, layer).standard_normal(n_steps)
            start = self.sigma_ln * noise[0]  # the stationary law
            drive = self.sigma_ln * np.sqrt(1 - a * a) * noise[1:]
            out[0, layer] = start
            out[1:, layer] = lfilter([1.0], [1.0, -a], drive, zi=[a * start])[0]
        return out

    def cn2_factors(self, n_layers: int, n_steps: int, time_step_s: float) -> np.ndarray:
        """``c_l(k) = exp(x_l(k) - sigma^2 / 2)`` (n_steps, n_layers), of mean 1."""
        return np.exp(self.log_factors(n_layers, n_steps, time_step_s) - self.sigma_ln**2 / 2)
