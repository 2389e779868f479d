"""Detector noise against theory: Poisson photon noise plus Gaussian read noise."""

import numpy as np
import pytest

from luckyao.lucky.detector import Detector, apply_detector


def two_level_frames(k, n=64):
    """Unit-flux frames (k, n, n): left half 3 times brighter than the right half."""
    frame = np.ones((n, n))
    frame[:, : n // 2] = 3.0
    frame /= frame.sum()
    return np.broadcast_to(frame, (k, n, n)).astype(np.float32), frame > frame.min()


# 64 x 64 pixels: below 256 photons per frame the photon-by-photon sampler is used,
# above it the per-pixel one; both must give independent Poisson pixels.
NOISE_CASES = [(8000.0, 0.0), (8000.0, 0.1), (8000.0, 1.0), (400.0, 1.0), (200.0, 0.0),
               (200.0, 0.1), (100.0, 1.0)]


@pytest.mark.parametrize("photons, read_noise_e", NOISE_CASES)
def test_mean_variance_and_skewness_match_poisson_plus_gaussian(photons, read_noise_e):
    """Per pixel: mean N I, variance N I + sigma^2, third central moment N I (Poisson only).

    Tolerances are 5 standard errors of the estimators over M = 300 x 2048 pixels per level:
    sqrt(v / M) for the mean, sqrt((lam + 2 v^2) / M) for the variance (fourth central
    moment lam + 3 v^2), sqrt(15 v^3 / M) for the third moment (bounds its variance,
    6 v^3 Gaussian, for these lam).
    """
    frames, bright = two_level_frames(300)
    detector = Detector("test", photons, read_noise_e)
    electrons = apply_detector(frames, detector, np.random.default_rng(7))
    assert electrons.dtype == np.float32 and electrons.shape == frames.shape
    for region in (bright, ~bright):
        lam = photons * float(frames[0][region][0])
        values = electrons[:, region].astype(np.float64).ravel()
        m = values.size
        v = lam + read_noise_e**2
        centred = values - values.mean()
        assert values.mean() == pytest.approx(lam, abs=5 * np.sqrt(v / m))
        assert np.mean(centred**2) == pytest.approx(v, abs=5 * np.sqrt((lam + 2 * v**2) / m))
        assert np.mean(centred**3) == pytest.approx(lam, abs=5 * np.sqrt(15 * v**3 / m))


@pytest.mark.parametrize("photons, read_noise_e", [(100.0, 0.0), (100.0, 0.1), (8000.0, 0.0),
                                                   (8000.0, 0.1)])
def test_frame_totals_are_poisson(photons, read_noise_e):
    """Pixels are independent, so the frame total of n^2 = 4096 pixels has variance
    N + n^2 sigma^2 (a multinomial with a fixed total would give n^2 sigma^2). 2000
    frames: the variance estimator's relative standard error is ~sqrt(2 / 2000) = 3.2%;
    tolerance 5 of them."""
    frames, _ = two_level_frames(2000, 64)
    electrons = apply_detector(frames, Detector("t", photons, read_noise_e),
                               np.random.default_rng(9))
    totals = electrons.sum(axis=(-2, -1), dtype=np.float64)
    variance = photons + 4096 * read_noise_e**2
    assert totals.mean() == pytest.approx(photons, abs=5 * np.sqrt(variance / 2000))
    assert totals.var() == pytest.approx(variance, rel=5 * np.sqrt(2 / 2000))


def test_photon_counts_are_integers_without_read_noise():
    frames, _ = two_level_frames(4)
    electrons = apply_detector(frames, Detector("pc", 1000.0), np.random.default_rng(1))
    np.testing.assert_array_equal(electrons, np.round(electrons))
    assert electrons.min() >= 0


def test_noiseless_returns_unchanged_float32_copy():
    frames = np.random.default_rng(2).random((3, 8, 8))
    before = frames.copy()
    out = apply_detector(frames, Detector("ideal"), np.random.default_rng(0))
    assert out.dtype == np.float32 and out is not frames
    np.testing.assert_array_equal(out, frames.astype(np.float32))
    np.testing.assert_array_equal(frames, before)


def test_noisy_does_not_mutate_and_is_reproducible():
    frames, _ = two_level_frames(3, 16)
    before = frames.copy()
    detector = Detector("emccd", 500.0, 0.1)
    a = apply_detector(frames, detector, np.random.default_rng([1, 2, 3]))
    b = apply_detector(frames, detector, np.random.default_rng([1, 2, 3]))
    c = apply_detector(frames, detector, np.random.default_rng([1, 2, 4]))
    np.testing.assert_array_equal(frames, before)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("kwargs", [dict(photons_per_frame=None, read_noise_e=1.0),
                                    dict(photons_per_frame=0.0),
                                    dict(photons_per_frame=-5.0),
                                    dict(photons_per_frame=10.0, read_noise_e=-1.0)])
def test_invalid_detectors_raise(kwargs):
    with pytest.raises(ValueError):
        Detector("bad", **kwargs)
