"""Analytic long-exposure image quality of uncorrected turbulence.

Long-exposure OTF = telescope OTF x exp(-D_phi(lambda f) / 2) (Roddier 1981,
Fried 1966), so the long-exposure Strehl ratio (its peak over the
diffraction-limited peak) is

    S = sum_r T(r) exp(-D_phi(r) / 2) / sum_r T(r),

with ``T`` the pupil autocorrelation at separation ``r`` [m] and ``D_phi`` the
von Karman phase structure function at the imaging wavelength. With r0 varying
in time, the long exposure averages ``exp(-D_phi / 2)`` over the r0 samples.
"""

import numpy as np

from ..atmosphere.statistics import r0_at_wavelength, von_karman_structure_function
from .pupil import Telescope


def pupil_autocorrelation(telescope: Telescope, n_across: int = 512):
    """Telescope OTF (unnormalised pupil autocorrelation) and separations [m].

    Returns ``(otf, r_m)``, both (2n, 2n) on a grid of ``D / n_across`` spacing.
    """
    grid = telescope.grid_for(telescope.diameter_m / n_across)
    pupil = telescope.mask(grid).astype(float)
    m = 2 * grid.n_pix
    spectrum = np.fft.fft2(pupil, s=(m, m))
    otf = np.fft.ifft2(np.abs(spectrum) ** 2).real
    k = np.fft.fftfreq(m, 1.0 / m)
    r_m = np.hypot(k[:, None], k[None, :]) * grid.dx_m
    return np.clip(otf, 0, None), r_m


def long_exposure_strehl(
    telescope: Telescope, wavelength_m: float, r0_500nm_m, outer_scale_m: float, n_across: int = 512
) -> float:
    """Analytic long-exposure Strehl (no recentring); ``r0_500nm_m`` scalar or samples in time."""
    otf, r_m = pupil_autocorrelation(telescope, n_across)
    support = otf > 1e-9 * otf.max()
    r = r_m[support]
    # D scales as r0^(-5/3) at fixed L0: tabulate exp(-D/2) averaged over the r0
    # samples on a fine radial grid (0.2 mm), then interpolate to every separation
    radial = np.linspace(0.0, r.max(), int(r.max() / 2e-4) + 2)
    d_unit = von_karman_structure_function(radial, 1.0, outer_scale_m)
    r0_lambda = r0_at_wavelength(np.atleast_1d(np.asarray(r0_500nm_m, dtype=float)), wavelength_m)
    values, counts = np.unique(np.round(r0_lambda, 6), return_counts=True)
    atmospheric = np.zeros_like(radial)
    for value, count in zip(values, counts):
        atmospheric += count * np.exp(-d_unit * value ** (-5 / 3) / 2)
    atmospheric /= counts.sum()
    return float(np.sum(otf[support] * np.interp(r, radial, atmospheric)) / np.sum(otf[support]))
