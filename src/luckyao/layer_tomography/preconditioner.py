"""Fourier-domain preconditioner (FDPCG, Vogel & Yang 2006, Appl. Opt. 45, 5123).

On periodic grids every operator of the normal equations is diagonal in Fourier space but for the
coupling of layers at the same frequency: with the cone-scaled layer pitch (:mod:`.grids`) beacon
``b``'s ray tracing of layer ``l`` is a constant bilinear shift of symbol

    T_bl(k) = exp(2 pi i k . o_bl) ((1 - f_x) + f_x exp(2 pi i k_x)) ((1 - f_y) + f_y exp(2 pi i k_y))

(``k`` in cycles per sample, ``o_bl`` the stencil's integer offset and ``f`` its fraction), and the
gradient's symbol ``g(k) = |G_x|^2 + |G_y|^2``, ``|G_x| = 2 |sin(pi o k_x)| |E(k_y)| / d`` with ``E`` the
edge mean's symbol (``cos(pi k)`` for ``o = 1`` pupil samples per sub-aperture, Fried geometry: exact on
a periodic grid; ``cos^2(pi k)`` for ``o = 2``, whose slopes sample every other point: weight ``1/o^2``). So::

    A(k) = (1 / sigma^2) (g(k) / o^2) sum_b T_b(k)^* T_b(k)^T + diag_l(w_l |L_l(k)|^2)

is an ``n_layers x n_layers`` Hermitian matrix per frequency; the preconditioner applies ``A(k)^-1``
(inverted once at set-up) between two real FFTs of the layers. Left out of the approximation: the
pupil and grid edges, the aliasing of the slopes' two-sample stride and the tilt removal ``P``.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.fft

from . import kernels
from .operators import MeasurementOperator
from .prior import BiharmonicPrior


def frequencies(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(k_x, k_y)`` [cycles per sample] of a real FFT of ``n x n`` samples, shapes (1, n//2+1), (n, 1)."""
    return scipy.fft.rfftfreq(n)[None, :], scipy.fft.fftfreq(n)[:, None]


@dataclass(frozen=True, eq=False)
class FourierPreconditioner:
    """``M^-1 r = F^-1 A(k)^-1 F r`` (see the module), ``inverse`` (n, n//2+1, n_layers, n_layers)."""

    inverse: np.ndarray
    n: int

    @classmethod
    def build(
        cls, operator: MeasurementOperator, prior: BiharmonicPrior, mean_inverse_noise_rad2: float, dtype=np.float64
    ):
        """From the operator, the prior and the mean inverse slope variance [1/rad^2]; applied in
        ``dtype`` (float32: complex64 spectra)."""
        n, n_layers = operator.grids.n, operator.grids.n_layers
        kx, ky = frequencies(n)
        d, o = operator.gradient.subaperture_m, operator.gradient.oversampling
        gx = 2 * np.sin(np.pi * o * kx) * np.cos(np.pi * ky) ** o / d
        gy = 2 * np.sin(np.pi * o * ky) * np.cos(np.pi * kx) ** o / d
        data_weight = mean_inverse_noise_rad2 * (gx**2 + gy**2) / o**2  # (n, n//2+1)
        system = np.zeros((n, kx.shape[1], n_layers, n_layers), dtype=complex)
        for beacon in operator.beacons:
            integer = np.floor(beacon.offsets)
            fx, fy = (beacon.offsets - integer).T
            symbol = np.exp(2j * np.pi * (kx * integer[:, 0, None, None] + ky * integer[:, 1, None, None]))
            symbol = symbol * ((1 - fx[:, None, None]) + fx[:, None, None] * np.exp(2j * np.pi * kx))
            symbol = symbol * ((1 - fy[:, None, None]) + fy[:, None, None] * np.exp(2j * np.pi * ky))
            t = np.moveaxis(symbol, 0, -1)  # (n, n//2+1, n_layers)
            system += data_weight[..., None, None] * np.conj(t)[..., :, None] * t[..., None, :]
        prior_symbol = prior.symbol(kx, ky)  # (n_layers, n, n//2+1)
        system[..., np.arange(n_layers), np.arange(n_layers)] += np.moveaxis(prior_symbol, 0, -1)
        return cls(np.linalg.inv(system).astype(np.result_type(dtype, np.complex64)), n)

    @cached_property
    def _upper(self) -> tuple[np.ndarray, np.ndarray]:
        """``inverse``'s upper triangle (it is Hermitian): the pairs ``(l, k)``, ``l <= k``
        (n_pairs, 2), and their blocks (n_pairs, n, n//2+1), each block's frequencies contiguous."""
        pairs = np.stack(np.triu_indices(self.inverse.shape[-1]), axis=1)
        return pairs, np.ascontiguousarray(np.moveaxis(self.inverse[:, :, pairs[:, 0], pairs[:, 1]], -1, 0))

    def apply(self, residual: np.ndarray) -> np.ndarray:
        """``M^-1 r`` of layers ``(n_layers, n, n)`` (:func:`.kernels.couple_layers` per frequency)."""
        spectrum = scipy.fft.rfft2(residual).astype(self.inverse.dtype, copy=False)
        coupled = np.empty_like(spectrum)
        kernels.couple_layers(*self._upper, spectrum, coupled)
        return scipy.fft.irfft2(coupled, s=(self.n, self.n), overwrite_x=True)
