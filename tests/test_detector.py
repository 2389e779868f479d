"""Detector noise against theory: Poisson photon noise plus Gaussian read noise."""

import numpy as np
import pytest

from luckyao.lucky.detector import Detector, KeyedNoise

from reference import apply_detector, detect


def two_level_frames(k, n=64):
    """Unit-flux frames (k, n, n): left half 3 times brighter than the right half."""
    frame = np.ones((n, n))
    frame[:, : n // 2] = 3.0
    frame /= frame.sum()
    return np.broadcast_to(frame, (k, n, n)).astype(np.float32), frame > frame.min()


# 64 x 64 pixels: below 256 photons per frame the photon-by-photon sampler is used,
# above it the per-pixel one; both must give independent Poisson pixels.
NOISE_CASES = [(8000.0, 0.0), (8000.0, 0.1), (8000.0, 1.0), (400.0, 1.0), (200.0, 0.0), (200.0, 0.1), (100.0, 1.0)]


def _assert_poisson_plus_gaussian(electrons, frames, bright, photons, read_noise_e):
    """Per region of equal mean ``lam``: mean ``lam``, variance ``lam + sigma^2`` and third
    central moment ``lam`` (the Gaussian adds none), each within 5 standard errors (the
    third's from the sixth central moment, ~15 v^3 + lam)."""
    assert electrons.dtype == np.float32 and electrons.shape == frames.shape
    for region in (bright, ~bright):
        lam = photons * float(frames[0][region][0])
        values = electrons[:, region].astype(np.float64).ravel()
        m = values.size
        v = lam + read_noise_e**2
        centred = values - values.mean()
        assert values.mean() == pytest.approx(lam, abs=5 * np.sqrt(v / m))
        assert np.mean(centred**2) == pytest.approx(v, abs=5 * np.sqrt((lam + 2 * v**2) / m))
        assert np.mean(centred**3) == pytest.approx(lam, abs=5 * np.sqrt((15 * v**3 + lam) / m))


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
    _assert_poisson_plus_gaussian(electrons, frames, bright, photons, read_noise_e)


@pytest.mark.parametrize("photons, read_noise_e", [(100.0, 0.0), (100.0, 0.1), (8000.0, 0.0), (8000.0, 0.1)])
def test_frame_totals_are_poisson(photons, read_noise_e):
    """Pixels are independent, so the frame total of n^2 = 4096 pixels has variance
    N + n^2 sigma^2 (a multinomial with a fixed total would give n^2 sigma^2). 2000
    frames: the variance estimator's relative standard error is ~sqrt(2 / 2000) = 3.2%;
    tolerance 5 of them."""
    frames, _ = two_level_frames(2000, 64)
    electrons = apply_detector(frames, Detector("t", photons, read_noise_e), np.random.default_rng(9))
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


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(photons_per_frame=None, read_noise_e=1.0),
        dict(photons_per_frame=0.0),
        dict(photons_per_frame=-5.0),
        dict(photons_per_frame=10.0, read_noise_e=-1.0),
    ],
)
def test_invalid_detectors_raise(kwargs):
    with pytest.raises(ValueError):
        Detector("bad", **kwargs)


# The keyed streams of run_lucky (KeyedNoise / detect): same model, own sampler. 64 x 64
# pixels: below n^2 / 10 = 410 expected photons a frame's photons are placed by search,
# above it pixel by pixel (own draws from a mean of 1, PTRS from 10, arrivals below 1).
KEYED_CASES = [(100.0, 0.0), (200.0, 1.0), (2000.0, 0.1), (8000.0, 0.0), (8000.0, 1.0), (1e5, 0.1)]


@pytest.mark.parametrize("photons, read_noise_e", KEYED_CASES)
def test_keyed_noise_mean_variance_and_skewness_match_poisson_plus_gaussian(photons, read_noise_e):
    """As for apply_detector, for the keyed sampler; the third moment's tolerance also holds
    for small means without read noise (sixth central moment ~lam, not ~15 v^3)."""
    frames, bright = two_level_frames(300)
    electrons = detect(frames, Detector("test", photons, read_noise_e), seed=7)
    _assert_poisson_plus_gaussian(electrons, frames, bright, photons, read_noise_e)


@pytest.mark.parametrize("photons", [100.0, 8000.0])
def test_keyed_frame_totals_are_poisson(photons):
    """Independent pixels: the frame total has variance N (2000 frames, tolerance 5 standard
    errors of the variance, as above); neighbouring pixels and consecutive frames are
    uncorrelated (|r| < 5 / sqrt(samples))."""
    frames, _ = two_level_frames(2000, 64)
    electrons = detect(frames, Detector("t", photons), seed=9).astype(np.float64)
    totals = electrons.sum(axis=(-2, -1))
    assert totals.mean() == pytest.approx(photons, abs=5 * np.sqrt(photons / 2000))
    assert totals.var() == pytest.approx(photons, rel=5 * np.sqrt(2 / 2000))
    centred = electrons - electrons.mean(axis=0)
    for a, b in ((centred[:, :, :-1], centred[:, :, 1:]), (centred[:-1], centred[1:])):
        r = np.mean(a * b) / np.sqrt(np.mean(a**2) * np.mean(b**2))
        assert abs(r) < 5 / np.sqrt(a.size)


def test_keyed_read_noise_is_standard_normal():
    """4M deviates of the ziggurat (no photons: 1e-9 expected per frame): Kolmogorov-Smirnov
    against the normal distribution (p > 1e-3), and the tail beyond the ziggurat's base
    (|z| > 3.654) and beyond 4.5 as often as theory says (5 standard errors)."""
    from scipy import stats

    frames = np.full((1000, 64, 64), 1 / 4096, dtype=np.float32)
    z = detect(frames, Detector("rn", 1e-9, 1.0), seed=3).astype(np.float64).ravel()
    assert stats.kstest(z, "norm").pvalue > 1e-3
    for edge in (3.6541528853610088, 4.5):
        p = 2 * stats.norm.sf(edge)
        assert np.mean(np.abs(z) > edge) == pytest.approx(p, abs=5 * np.sqrt(p / z.size))
    assert abs(z.mean()) < 5 / np.sqrt(z.size) and z.var() == pytest.approx(1, abs=5 * np.sqrt(2 / z.size))


def test_keyed_streams_depend_on_seed_name_and_frame_only():
    """A frame's draws are keyed by (seed, name, frame index): any chunking gives the same
    frames; another seed, name or frame index gives others; the input is not modified."""
    frames, _ = two_level_frames(10, 64)
    frames = frames.copy()
    before = frames.copy()
    detector = Detector("emccd", 500.0, 0.1)
    whole = detect(frames, detector, seed=5)
    np.testing.assert_array_equal(frames, before)
    np.testing.assert_array_equal(
        np.concatenate([detect(frames[:3], detector, 5), detect(frames[3:], detector, 5, first_frame=3)]), whole
    )
    assert not np.array_equal(detect(frames, detector, 6), whole)
    assert not np.array_equal(detect(frames, Detector("emccd2", 500.0, 0.1), 5), whole)
    assert not np.array_equal(whole[0], whole[1])  # same unit frame, another key


def test_keyed_photons_never_land_on_dark_pixels():
    """Pixels of zero (or negative: clipped) intensity get no photon in either way."""
    frames = np.zeros((50, 64, 64), dtype=np.float32)
    frames[:, 10:20, 30:33] = 1.0
    frames[:, 40, 40] = -1.0
    frames /= 30
    for photons in (50.0, 1e5):
        electrons = detect(frames, Detector("pc", photons), seed=1)
        dark = np.ones((64, 64), bool)
        dark[10:20, 30:33] = False
        assert not electrons[:, dark].any()
        assert electrons.sum() == pytest.approx(50 * photons, abs=5 * np.sqrt(50 * photons))


def test_a_chunk_is_detected_only_while_its_sums_are_held():
    """``KeyedNoise.prepare`` returns the chunk that detects; once another chunk is prepared the
    first one's sums are gone, and detecting it is refused rather than drawing from the wrong sums."""
    rng = np.random.default_rng(2)
    first, second = (rng.random((3, 8, 8)).astype(np.float32) for _ in range(2))
    noise = KeyedNoise(8, 4)
    assert not hasattr(noise, "detect")
    chunk = noise.prepare(first)
    frames = chunk.detect(Detector("a", 100.0, 1.0), 5, 0)[0].copy()
    noise.prepare(second)
    with pytest.raises(RuntimeError, match="replaced"):
        chunk.detect(Detector("a", 100.0, 1.0), 5, 0)
    np.testing.assert_array_equal(noise.prepare(first).detect(Detector("a", 100.0, 1.0), 5, 0)[0], frames)


def _emccd_frames(lam: float, detector: Detector, k: int = 200, n: int = 64) -> np.ndarray:
    """k detected frames of a uniform image with ``lam`` mean photo-electrons per pixel."""
    frames = np.full((k, n, n), 1.0 / n**2, np.float32)
    return KeyedNoise(n, k).prepare(frames).detect(detector, 3, 0)[0].astype(np.float64)


@pytest.mark.parametrize("lam, read_noise_e", [(0.2, 0.1), (3.0, 0.1), (3.0, 1.0)])
def test_emccd_output_has_the_gain_registers_mean_and_excess_noise(lam, read_noise_e):
    """Input-referred EMCCD pixel: Gamma(Poisson(lam), 1) + Normal(0, sigma): mean lam and variance
    2 lam + sigma^2 (excess-noise factor sqrt 2), each within 5 standard errors (the variance's from
    the fourth central moment, measured); the same detector without the register has lam + sigma^2."""
    n = 64
    em = Detector("em", lam * n**2, read_noise_e, electron_multiplying=True)
    values = _emccd_frames(lam, em).ravel()
    m = values.size
    centred = values - values.mean()
    variance = 2 * lam + read_noise_e**2
    assert values.mean() == pytest.approx(lam, abs=5 * np.sqrt(variance / m))
    assert np.mean(centred**2) == pytest.approx(variance, abs=5 * np.sqrt(np.var(centred**2) / m))
    plain = _emccd_frames(lam, Detector("em", lam * n**2, read_noise_e)).ravel()
    assert np.var(plain) == pytest.approx(lam + read_noise_e**2, rel=0.05)


def test_photon_counting_probability_against_theory():
    """Thresholded EMCCD pixel: P(1) = sum_n Poisson(n; lam) P(Gamma(n, 1) + Normal(0, sigma) > t)
    (n = 0: the read noise alone), within 5 standard errors of the binomial fraction."""
    from scipy import integrate, stats

    lam, sigma, threshold, n = 0.15, 0.2, 0.6, 64
    detector = Detector("pc", lam * n**2, sigma, electron_multiplying=True, photon_counting_threshold_e=threshold)
    values = _emccd_frames(lam, detector)
    assert set(np.unique(values)) <= {0.0, 1.0}
    expected = stats.poisson.pmf(0, lam) * stats.norm.sf(threshold / sigma)
    for electrons in range(1, 30):
        above = integrate.quad(
            lambda x: stats.gamma.pdf(x, electrons) * stats.norm.sf((threshold - x) / sigma), 0, np.inf
        )[0]
        expected += stats.poisson.pmf(electrons, lam) * above
    p = values.mean()
    assert p == pytest.approx(expected, abs=5 * np.sqrt(expected * (1 - expected) / values.size))
    assert p < lam  # coincidence and threshold losses: fewer counts than photons


def test_emccd_options_are_checked_by_name():
    with pytest.raises(ValueError, match="'pc'.*threshold"):
        Detector("pc", 100.0, 0.1, photon_counting_threshold_e=0.5)
    with pytest.raises(ValueError, match="'em'.*noiseless"):
        Detector("em", None, 0.0, electron_multiplying=True)


def _xoshiro256pp(state):
    """One step of xoshiro256++ (Blackman & Vigna 2021, the authors' C code) of ``state`` (4 Python
    ints, updated): its output."""
    mask = (1 << 64) - 1

    def rotl(x, k):
        return ((x << k) | (x >> (64 - k))) & mask

    a, b, c, d = state
    out = (rotl((a + d) & mask, 23) + a) & mask
    t = (b << 17) & mask
    c ^= a
    d ^= b
    b ^= c
    a ^= d
    c ^= t
    state[:] = [a, b, c, rotl(d, 45)]
    return out


def test_vector_generators_step_as_xoshiro256pp():
    """The LANES generators stepped as one vector (:func:`.stream_vectors.xoshiro_fill`) give,
    value for value, the authors' scalar xoshiro256++ of each generator in turn, and leave its state."""
    from luckyao.lucky import noise_streams

    rng = np.random.default_rng(0)
    lanes = rng.integers(0, 2**63, (4, noise_streams.LANES), dtype=np.uint64) * np.uint64(2) + np.uint64(1)
    states = [[int(lanes[w, g]) for w in range(4)] for g in range(noise_streams.LANES)]
    out = np.empty(noise_streams.LANES * 37, np.uint64)
    noise_streams._fill_bits(lanes, out)
    expected = [_xoshiro256pp(states[i % noise_streams.LANES]) for i in range(out.size)]
    assert [int(v) for v in out] == expected
    assert [[int(lanes[w, g]) for w in range(4)] for g in range(noise_streams.LANES)] == states
    assert _xoshiro256pp([1, 2, 3, 4]) == (5 << 23) + 1  # rotl(1 + 4, 23) + 1


def test_rectangle_test_of_16_words_is_the_scalar_ziggurats():
    """The vector rectangle test (:func:`.stream_vectors.ziggurat_rectangle`) gives, bit for bit, the
    scalar ziggurat's deviate ``±m w[layer]`` (float32) of every word, and fails exactly the words
    of ``m >= k[layer]``; :func:`.noise_streams._normals` keeps the deviates that pass."""
    import numba

    from luckyao.lucky import noise_streams
    from luckyao.lucky.stream_vectors import ziggurat_rectangle

    @numba.njit
    def rectangle(words, out):
        failed = np.empty(words.size, np.bool_)
        for start in range(0, words.size, 16):
            mask = ziggurat_rectangle(words, start, noise_streams._ZW, noise_streams._ZK32, out)
            for k in range(16):
                failed[start + k] = (mask >> k) & 1
        return failed

    words = np.random.default_rng(1).integers(-(2**31), 2**31, 16 * 4096, dtype=np.int64).astype(np.int32)
    layer, magnitude = words & 0xFF, (words >> 9) & 0x7FFFFF
    deviate = magnitude.astype(np.float32) * noise_streams._ZW[layer]
    deviate = np.where((words >> 8) & 1, -deviate, deviate)
    out = np.full(words.size, np.nan, np.float32)
    failed = rectangle(words, out)
    np.testing.assert_array_equal(failed, magnitude >= noise_streams._ZK32[layer])
    assert 0.005 < failed.mean() < 0.03  # the rare slow path (~1.5%)
    np.testing.assert_array_equal(out.view(np.int32), deviate.view(np.int32))
    normals = np.empty(words.size, np.float32)
    noise_streams._normals(words, normals, np.array([1, 2, 3, 4], np.uint64))
    np.testing.assert_array_equal(normals[~failed].view(np.int32), deviate[~failed].view(np.int32))


@pytest.mark.parametrize("n", [64, 61])
def test_frame_sums_add_each_row_and_column_in_pixel_order(n):
    """Row and column sums of detected frames are float64 sums in the order of the pixels (what the
    centre of gravity and the flux are made of: no reordering by the compiler), the peak the
    largest pixel."""
    from luckyao.lucky import noise_streams

    rng = np.random.default_rng(2)
    frames = (rng.standard_normal((3, n, n)) * 10.0 ** rng.uniform(-4, 4, (3, n, n))).astype(np.float32)
    rows, cols, peak = np.empty((3, n)), np.empty((3, n)), np.empty(3, np.float32)
    noise_streams.frame_sums(frames, rows, cols, peak)
    values = frames.astype(np.float64)
    np.testing.assert_array_equal(rows, np.add.accumulate(values, axis=2)[:, :, -1])
    np.testing.assert_array_equal(cols, np.add.accumulate(values, axis=1)[:, -1, :])
    np.testing.assert_array_equal(peak, frames.max(axis=(1, 2)))
    assert not np.array_equal(rows, values.sum(axis=2))  # pairwise summation differs: the order is tested
