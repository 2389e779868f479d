"""The sparse prior: a bi-harmonic (Laplacian squared) approximation of each layer's von Karman statistics.

The inverse covariance of layer ``l``'s samples is approximated by ``w_l L_l^T L_l`` with
``L_l = Lap - kappa_0^2 I``, ``Lap`` the 5-point Laplacian [1/m^2] on the layer's grid and
``kappa_0 = 2 pi / L0`` (Ellerbroek 2002, JOSA A 19, 1803; Vogel & Yang 2006, Appl. Opt. 45, 5123,
without the outer-scale term). Its symbol is ``w ((2 pi k)^2 + kappa_0^2)^2`` at low frequency
``k`` [cycles/m]: a power spectrum ``(k^2 + L0^-2)^-2``, i.e. ``k^-4`` above ``1 / L0``, in place of
von Karman's ``(k^2 + L0^-2)^-11/6``; the outer-scale term makes the matrix positive definite (as
von Karman's spectrum saturates at the lowest frequencies). The grid is periodic (its edges lie
beyond every footprint): a Laplacian that is zero beyond the edge instead makes a layer's piston and
other smooth modes cost ~100 times the periodic symbol, which the Fourier preconditioner
(:mod:`.preconditioner`) cannot know, and doubles the PCG iterations. The weight matches
the two spectra of the sampled layer at ``k_match`` (default ``1 / (2 d)``, the WFS's Nyquist
frequency, where the prior and the noise trade):

    w_l = Delta_l^2 / (Phi_l(k_match) ((2 pi k_match)^2 + kappa_0^2)^2),
    Phi_l(k) = 0.023 r0^(-5/3) f_l (k^2 + L0^-2)^(-11/6) (lambda / 2 pi)^2   [m^2 of optical path per (1/m)^2]

(``Delta_l`` the layer's pitch: the samples' inverse covariance has symbol ``Delta^2 / Phi``; ``f_l`` the
layer's Cn2 fraction of ``r0`` at ``lambda``, the prior of :class:`luckyao.tomography.prior.TurbulencePrior`).
A layer of zero fraction is not reconstructed: its weight is ``1e6`` times the largest.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse

from ..tomography.prior import TurbulencePrior
from . import kernels
from .grids import LayerGrids

VON_KARMAN_PSD_CONSTANT = 0.023
"""``Phi(k) = 0.023 r0^(-5/3) k^(-11/3)`` [rad^2 per (cycles/m)^2], the Kolmogorov phase spectrum (Noll 1976)."""


def von_karman_psd_m2(k_per_m, r0_m: float, outer_scale_m: float, wavelength_m: float):
    """Optical-path power spectrum [m^2 per (1/m)^2] of von Karman turbulence at frequency ``k`` [cycles/m]."""
    k2 = np.asarray(k_per_m, dtype=float) ** 2
    phase = VON_KARMAN_PSD_CONSTANT * r0_m ** (-5 / 3) * (k2 + outer_scale_m**-2) ** (-11 / 6)
    return phase * (wavelength_m / (2 * np.pi)) ** 2


def laplacian(n: int, pitch_m: float, kappa0_per_m: float = 0.0) -> scipy.sparse.csr_matrix:
    """5-point Laplacian [1/m^2] on an ``n x n`` periodic grid (row-major), less ``kappa0^2`` times
    the identity."""
    second = scipy.sparse.diags([1.0, -2.0, 1.0, 1.0, 1.0], [-1, 0, 1, n - 1, 1 - n], shape=(n, n))
    eye = scipy.sparse.identity(n)
    lap = (scipy.sparse.kron(eye, second) + scipy.sparse.kron(second, eye)) / pitch_m**2
    return (lap - kappa0_per_m**2 * scipy.sparse.identity(n * n)).tocsr()


@dataclass(frozen=True, eq=False)
class BiharmonicPrior:
    """``C^-1 ~ blockdiag_l w_l L_l^T L_l`` on the layer grids, for ``prior`` (its heights are the
    grids'), applied in ``dtype``."""

    prior: TurbulencePrior
    grids: LayerGrids
    match_frequency_per_m: float
    dtype: type = np.float64

    def __post_init__(self):
        if tuple(self.prior.heights_m) != tuple(self.grids.heights_m):
            raise ValueError("the prior's layer heights are not the grids'")

    @property
    def kappa0_per_m(self) -> float:
        """``kappa_0 = 2 pi / L0`` [rad/m]."""
        return 2 * np.pi / self.prior.outer_scale_m

    @cached_property
    def weights(self) -> np.ndarray:
        """``w_l`` [m^2] per layer (n_layers,)."""
        k = self.match_frequency_per_m
        fractions = np.asarray(self.prior.cn2_fractions, dtype=float)
        psd = von_karman_psd_m2(k, self.prior.r0_m, self.prior.outer_scale_m, self.prior.wavelength_m)
        weights = np.empty_like(fractions)
        live = fractions > 0
        weights[live] = self.grids.pitches_m[live] ** 2 / (
            psd * fractions[live] * ((2 * np.pi * k) ** 2 + self.kappa0_per_m**2) ** 2
        )
        weights[~live] = 1e6 * weights[live].max()
        return weights

    @cached_property
    def laplacians(self) -> tuple[scipy.sparse.csr_matrix, ...]:
        return tuple(laplacian(self.grids.n, pitch, self.kappa0_per_m) for pitch in self.grids.pitches_m)

    def apply(self, layers: np.ndarray) -> np.ndarray:
        """``C^-1 x`` for layers ``(n_layers, n, n)``, in ``dtype`` (:func:`.kernels.biharmonic`:
        the Laplacian's stencil twice, the matrix unassembled)."""
        layers = np.ascontiguousarray(layers, dtype=self.dtype)
        scales, shifts, weights = self._stencil
        out = np.empty_like(layers)
        kernels.biharmonic(layers, scales, shifts, weights, out)
        return out

    @cached_property
    def _stencil(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per layer, in ``dtype``: ``1 / pitch^2`` [1/m^2], ``kappa_0^2`` [1/m^2], ``w_l`` [m^2]."""
        kappa2 = np.full(self.grids.n_layers, self.kappa0_per_m**2)
        return tuple(np.asarray(v, dtype=self.dtype) for v in (self.grids.pitches_m**-2.0, kappa2, self.weights))

    def matrix(self) -> scipy.sparse.csr_matrix:
        """``C^-1`` as a sparse block-diagonal matrix (small systems: tests, direct solves)."""
        return scipy.sparse.block_diag([w * (lap.T @ lap) for lap, w in zip(self.laplacians, self.weights)], "csr")

    def symbol(self, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
        """Fourier symbol ``w_l |L_l(k)|^2`` (n_layers, ...) of the periodic operator at frequencies
        ``kx, ky`` [cycles per sample] (:mod:`.preconditioner`)."""
        lap = 2 * np.cos(2 * np.pi * kx) + 2 * np.cos(2 * np.pi * ky) - 4  # times 1/pitch^2
        pitches = self.grids.pitches_m.reshape((-1,) + (1,) * np.ndim(lap))
        return self.weights.reshape(pitches.shape) * (lap / pitches**2 - self.kappa0_per_m**2) ** 2
