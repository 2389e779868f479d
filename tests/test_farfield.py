"""Pruned FFT intensity against the direct |FFT_M(padded field)|^2 / (M^2 n_valid)."""

import numpy as np
import pytest

from luckyao.optics.farfield import FarField
from luckyao.optics.pupil import Telescope


@pytest.mark.parametrize("n_pix, fft_size", [(128, 256), (82, 300)])  # 300: last row block partial
def test_accumulate_matches_direct_fft(n_pix, fft_size):
    telescope = Telescope(4.2, 1.2)
    mask = telescope.mask(telescope.grid_for(4.2 / n_pix))
    n = mask.shape[0]
    rng = np.random.default_rng(0)
    phase_rad = rng.normal(0.0, 3.0, (2, mask.sum())).astype(np.float32)
    field = np.zeros((2, fft_size, fft_size), dtype=complex)
    field[:, :n, :n][:, mask] = np.exp(1j * phase_rad.astype(float))
    direct = np.abs(np.fft.fft2(field)) ** 2 / (fft_size**2 * mask.sum())

    out = np.zeros((2, fft_size, fft_size), dtype=np.float32)
    far_field = FarField(mask, fft_size)
    far_field.accumulate(phase_rad, out)
    far_field.accumulate(phase_rad, out)  # adds; the buffers are reused
    np.testing.assert_allclose(out / 2, direct, rtol=0, atol=1e-6 * direct.max())
    np.testing.assert_allclose(out.sum(axis=(1, 2)) / 2, 1.0, rtol=1e-5)
