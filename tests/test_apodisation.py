"""Adaptive apodisation against theory: the apodised pupil's image, diffraction-limited peak and
flux against a direct FFT and (open area)^2, open area; blocking the regions with the largest
residual lowers the residual of the pupil kept."""

import numpy as np
import pytest

from luckyao.ao.apodisation import Apodiser, SubapertureRegions
from luckyao.optics.imaging import Camera, Imager
from luckyao.optics.pupil import Telescope, TiltRemover


@pytest.fixture(scope="module")
def imager():
    return Imager(Telescope(4.2, 1.2), Camera(800e-9, 64, 0.02))


def _apodiser(imager, fraction, n_across=8):
    x, y = imager.grid.xy_m
    return Apodiser(SubapertureRegions(4.2, n_across), x[imager.mask], y[imager.mask], fraction)


@pytest.mark.parametrize("fraction", [0.1, 0.3, 0.5])
def test_apodised_pupil_peak_and_flux_against_direct_computation(imager, fraction):
    """Blocked regions chosen at random: the unbinned intensity equals |FFT_M(t)|^2 / (M^2 n_valid)
    of the zero-padded transmission, its axis value (the diffraction-limited peak) is
    (n_open / n_valid)^2 of the full pupil's and its flux n_open / n_valid."""
    apodiser = _apodiser(imager, fraction)
    rng = np.random.default_rng(1)
    t = apodiser.open_samples(rng.random(apodiser.regions.n_regions))[None]
    n_valid, n_open, m = imager.n_valid, float(t.sum()), imager.fft_size
    assert n_open < n_valid
    intensity = imager.intensity(np.zeros_like(t), t)[0]
    full = imager.intensity(np.zeros_like(t))[0]

    n = imager.grid.n_pix
    field = np.zeros((m, m))
    field[:n, :n][imager.mask] = t[0]
    direct = np.abs(np.fft.fft2(field)) ** 2 / (m * m * n_valid)
    np.testing.assert_allclose(intensity, direct, rtol=0, atol=1e-6 * direct.max())
    assert intensity[0, 0] == pytest.approx(n_open**2 / (m * m * n_valid), rel=1e-5)
    assert intensity[0, 0] / full[0, 0] == pytest.approx((n_open / n_valid) ** 2, rel=1e-5)
    assert intensity.sum() == pytest.approx(n_open / n_valid, rel=1e-5)
    assert intensity.max() == intensity[0, 0]  # an aberration-free pupil peaks on the axis


def test_blocked_count_and_area(imager):
    """round(f n_regions) of the regions holding samples are blocked; with sub-aperture squares
    of nearly equal area the blocked area is close to f."""
    apodiser = _apodiser(imager, 0.25)
    assert len(apodiser.present) == 60  # 8 x 8 squares less the 4 inside the 1.2 m obscuration
    assert apodiser.n_blocked == 15
    t = apodiser.from_residual(np.random.default_rng(2).normal(size=imager.n_valid))
    assert len(np.unique(apodiser.labels[t == 0])) == 15
    assert 0.1 < 1 - t.mean() < 0.4


def test_region_mean_square_direct(imager):
    apodiser = _apodiser(imager, 0.2)
    values = np.random.default_rng(3).normal(size=imager.n_valid)
    ms = apodiser.regions.mean_square(apodiser.labels, values)
    for region in apodiser.present[:10]:
        assert ms[region] == pytest.approx(np.mean(values[apodiser.labels == region] ** 2))
    assert np.all(ms[np.setdiff1d(np.arange(64), apodiser.present)] == 0)


def test_blocking_a_known_aberrated_square_leaves_a_flat_pupil(imager):
    """A phase step of 1 rad on one sub-aperture square, 0 elsewhere: blocking one region blocks
    that square and the kept pupil's tilt-removed rms is 0."""
    apodiser = _apodiser(imager, 1 / 60)
    x, y = imager.grid.xy_m
    x, y = x[imager.mask], y[imager.mask]
    target = 3 * 8 + 6  # square ix = 6, iy = 3
    phase = (apodiser.labels == target).astype(np.float32)
    residual = TiltRemover(x, y).residual(phase)
    assert apodiser.n_blocked == 1
    assert list(apodiser.blocked_regions(apodiser.regions.mean_square(apodiser.labels, residual))) == [target]
    kept = apodiser.from_residual(residual) > 0
    assert TiltRemover(x, y).rms(phase)[()] > 0.1
    assert TiltRemover(x[kept], y[kept]).rms(phase[kept])[()] < 1e-6


@pytest.mark.parametrize("fraction", [0.1, 0.25, 0.5])
def test_blocking_the_largest_residual_lowers_the_kept_rms(imager, fraction):
    """For random smooth phases: the kept pupil's tilt-removed rms is at most the whole pupil's
    (module docstring) and below that after blocking as many regions chosen at random."""
    apodiser = _apodiser(imager, fraction)
    x, y = imager.grid.xy_m
    x, y = x[imager.mask], y[imager.mask]
    rng = np.random.default_rng(4)
    better = 0
    for _ in range(20):
        k = rng.normal(0, 3.0, (12, 2))  # spatial frequencies [rad/m]
        phase = rng.normal(size=12) @ np.cos(k @ np.stack([x, y]) + rng.uniform(0, 2 * np.pi, (12, 1)))
        phase = phase.astype(np.float32)
        whole = TiltRemover(x, y)
        kept = apodiser.from_residual(whole.residual(phase)) > 0
        random_kept = apodiser.open_samples(rng.random(64)) > 0
        rms_kept = TiltRemover(x[kept], y[kept]).rms(phase[kept])[()]
        assert rms_kept <= whole.rms(phase)[()] * (1 + 1e-5)
        better += rms_kept < TiltRemover(x[random_kept], y[random_kept]).rms(phase[random_kept])[()]
    assert better >= 18
