"""Lucky selection, shift-and-add and the two-pass driver, against explicit theory."""

import numpy as np
import pytest

from luckyao.lucky.accumulation import recentring_shifts_px
from luckyao.lucky.detector import Detector
from luckyao.lucky.metrics import strehl
from luckyao.lucky.pipeline import run_lucky
from luckyao.lucky.ranking import ExternalCriterion, fraction_counts, rank_frames, selection_bins
from luckyao.optics.imaging import Camera, Imager
from luckyao.optics.pupil import Telescope
from luckyao.seeds import detector_key

from reference import detect, shift_and_add, shift_frames


def test_fraction_counts():
    assert fraction_counts(1000, [0.001, 0.01, 0.1, 0.5, 1.0]).tolist() == [1, 10, 100, 500, 1000]
    # max(1, round(f n)): 0.01 x 10 rounds to 0 -> 1; 2.5 rounds half to even -> 2
    assert fraction_counts(10, [0.01, 0.25, 0.36, 1.0]).tolist() == [1, 2, 4, 10]
    for bad in ([0.0], [1.5], [np.nan]):
        with pytest.raises(ValueError):
            fraction_counts(10, bad)


def test_rank_is_stable_with_ties_and_nan_last():
    values = np.array([3.0, 1.0, np.nan, 3.0, 2.0, 1.0])
    assert rank_frames(values, larger_is_better=True).tolist() == [0, 3, 4, 1, 5, 2]
    assert rank_frames(values, larger_is_better=False).tolist() == [1, 5, 4, 0, 3, 2]


def test_selection_bins_keep_exactly_the_top_fractions():
    rng = np.random.default_rng(3)
    values = rng.permutation(50).astype(float)  # distinct known values
    counts = fraction_counts(50, [0.1, 0.02, 0.5, 0.1])
    bins, last = selection_bins(rank_frames(values, False), counts)
    for count, b in zip(counts, last):
        kept = set(np.flatnonzero((bins >= 0) & (bins <= b)))
        assert kept == set(np.flatnonzero(values < count))  # the `count` smallest values


def compact_pattern(n, rng):
    """Non-negative asymmetric 5x5 pattern near the centre of an n x n frame."""
    image = np.zeros((n, n), dtype=np.float32)
    image[n // 2 - 3 : n // 2 + 2, n // 2 - 1 : n // 2 + 4] = rng.random((5, 5)) + 0.1
    return image


def test_shift_and_add_is_exact_for_integer_shifts():
    """Frames = one compact image rolled by known integer shifts: the sum is K copies of the
    image rolled so that its centroid is nearest (n/2, n/2)."""
    n, rng = 32, np.random.default_rng(4)
    image = compact_pattern(n, rng)
    shifts = rng.integers(-10, 11, size=(12, 2))
    frames = np.stack([np.roll(image, tuple(s), axis=(0, 1)) for s in shifts])
    cy = (image.sum(axis=1) * np.arange(n)).sum() / image.sum()
    cx = (image.sum(axis=0) * np.arange(n)).sum() / image.sum()
    home = (int(np.floor(n / 2 - cy + 0.5)), int(np.floor(n / 2 - cx + 0.5)))
    expected = 12 * np.roll(image.astype(np.float64), home, axis=(0, 1))
    np.testing.assert_allclose(shift_and_add(frames), expected, rtol=1e-6)


@pytest.mark.parametrize("offset, lands_on_second", [(0.3, False), (0.7, True), (0.45, False), (0.55, True)])
def test_subpixel_centroid_rounds_to_nearest_pixel(offset, lands_on_second):
    """Two pixels at x0, x0+1 with weights (1-o, o): centroid x0+o. Nearest to n/2: x0 moves
    to n/2 if o < 1/2, x0+1 does if o > 1/2. Same in y with a vertical pair."""
    n = 16
    frames = np.zeros((2, n, n), dtype=np.float32)
    frames[0, 5, 9], frames[0, 5, 10] = 1 - offset, offset
    frames[1, 11, 3], frames[1, 12, 3] = 1 - offset, offset
    out = shift_frames(frames, recentring_shifts_px(np.array([[5, 9 + offset], [11 + offset, 3]]), n))
    c = n // 2
    if lands_on_second:
        assert out[0, c, c] == np.float32(offset) and out[0, c, c - 1] == np.float32(1 - offset)
        assert out[1, c, c] == np.float32(offset) and out[1, c - 1, c] == np.float32(1 - offset)
    else:
        assert out[0, c, c] == np.float32(1 - offset) and out[0, c, c + 1] == np.float32(offset)
        assert out[1, c, c] == np.float32(1 - offset) and out[1, c + 1, c] == np.float32(offset)


def test_shift_frames_has_roll_semantics():
    frames = np.random.default_rng(5).random((3, 8, 8)).astype(np.float32)
    shifts = np.array([[1, -2], [7, 3], [-9, 0]])
    expected = np.stack([np.roll(f, tuple(s), axis=(0, 1)) for f, s in zip(frames, shifts)])
    np.testing.assert_array_equal(shift_frames(frames, shifts), expected)


def chunker(frames, size):
    return lambda: ((s, frames[s : s + size]) for s in range(0, len(frames), size))


def strehl_flux_of(frames, detector, order, count):
    """The flux a Strehl of the best ``count`` noiseless unit-flux ``frames`` detected by
    ``detector`` is over: a noisy detector's expected flux, N times the noiseless frames' sum
    (:func:`luckyao.lucky.metrics.strehl_flux`); None for the noiseless detector (its image's sum)."""
    if detector.noiseless:
        return None
    return detector.photons_per_frame * sum(frames[f].sum(dtype=np.float64) for f in order[:count])


def brute_force_strehl(frames_e, order, count, peak, flux=None, centroid_frames=None):
    """The Strehl of :func:`brute_force_image` over ``flux`` (None: the image's sum)."""
    raw = brute_force_image(frames_e, order, count, centroid_frames, normalise=False)
    return float(raw.max() / (peak * (raw.sum() if flux is None else flux)))


def brute_force_image(frames_e, order, count, centroid_frames=None, normalise=True):
    """Sum of the best `count` frames, each rolled to put its centroid nearest n/2 (np.roll);
    with `centroid_frames`, each frame is rolled by the shift of its counterpart there; over its
    flux (``normalise``)."""
    n = frames_e.shape[-1]
    total = np.zeros((n, n))
    for f in order[:count]:
        frame = frames_e[f].astype(np.float64)
        ref = frame if centroid_frames is None else centroid_frames[f].astype(np.float64)
        c = [(ref.sum(axis=1 - a) * np.arange(n)).sum() / ref.sum() for a in (0, 1)]
        total += np.roll(frame, (int(np.floor(n / 2 - c[0] + 0.5)), int(np.floor(n / 2 - c[1] + 0.5))), axis=(0, 1))
    return total / total.sum() if normalise else total


def test_run_lucky_matches_brute_force_for_every_criterion_and_fraction():
    """Cumulative bins over irregular chunks equal brute-force sums for each fraction, with
    the same noise (streams keyed by (seed, detector_key(name), frame): ``detect`` of the
    whole cube at once gives the same frames as the chunks); the
    ``*_noiseless`` scores are those of the noiseless frames with the noisy ranking and
    the noisy frames' shifts."""
    n, n_frames, chunk, seed = 32, 40, 7, 11
    rng = np.random.default_rng(6)
    sigma = rng.uniform(1.0, 3.0, n_frames)
    pos = rng.uniform(8, 24, size=(n_frames, 2))
    idx = np.arange(n)
    dy = idx[None, :, None] - pos[:, 0, None, None]
    dx = idx[None, None, :] - pos[:, 1, None, None]
    frames = np.exp(-(dy**2 + dx**2) / (2 * sigma[:, None, None] ** 2))
    frames = (frames / frames.sum(axis=(1, 2), keepdims=True)).astype(np.float32)
    before = frames.copy()
    external = ExternalCriterion("lgs_rms", rng.permutation(n_frames) * 1.0, False, "nm")
    detectors = [Detector("ideal"), Detector("emccd", 300.0, 0.1)]
    fractions = [0.05, 0.1, 0.25, 0.5, 1.0]
    peak = 1 / (2 * np.pi)
    ds = run_lucky(
        chunker(frames, chunk),
        n_frames,
        detectors,
        fractions,
        peak,
        0.02,
        seed,
        criteria_external=[external],
        image_crop_px=None,
        progress_interval_s=0,
    )
    np.testing.assert_array_equal(frames, before)
    assert list(ds.criterion.values) == ["strehl", "d50", "lgs_rms"]
    for i, det in enumerate(detectors):
        noisy = detect(frames, det, seed)  # keyed per frame: the chunking does not matter
        if det.noiseless:
            np.testing.assert_allclose(ds.frame_strehl[i], strehl(noisy, peak), rtol=1e-12)
        else:  # over the frame's expected flux, N times the noiseless frame's, not its noisy sum
            expected_flux = det.photons_per_frame * frames.sum(axis=(1, 2), dtype=np.float64)
            np.testing.assert_allclose(ds.frame_strehl[i], noisy.max(axis=(1, 2)) / (peak * expected_flux), rtol=1e-12)
        for name, values, larger in [
            ("strehl", ds.frame_strehl[i].values, True),
            ("d50", ds.frame_d50_arcsec[i].values, False),
            ("lgs_rms", external.values, False),
        ]:
            sign = -1 if larger else 1
            order = sorted(range(n_frames), key=lambda f: (sign * values[f], f))
            for fraction, count in zip(fractions, fraction_counts(n_frames, fractions)):
                expected = brute_force_image(noisy, order, count)
                got = ds.image.sel(criterion=name, fraction=fraction, detector=det.name).values
                np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-7)
                assert ds.strehl.sel(criterion=name, fraction=fraction, detector=det.name) == pytest.approx(
                    brute_force_strehl(noisy, order, count, peak, strehl_flux_of(frames, det, order, count)), rel=1e-5
                )
                clean = brute_force_image(frames, order, count, centroid_frames=noisy)
                assert ds.strehl_noiseless.sel(criterion=name, fraction=fraction, detector=det.name) == pytest.approx(
                    float(clean.max() / peak), rel=1e-5
                )
        everything = brute_force_image(noisy, list(range(n_frames)), n_frames)
        np.testing.assert_allclose(ds.long_exposure_image.sel(recentring="cog")[i], everything, rtol=1e-5, atol=1e-7)
        plain = noisy.sum(axis=0, dtype=np.float64)
        np.testing.assert_allclose(
            ds.long_exposure_image.sel(recentring="none")[i], plain / plain.sum(), rtol=1e-5, atol=1e-7
        )


def test_guessed_bins_of_noisy_frames_are_corrected_to_each_block_and_run_selection():
    """A noisy detector's frames go to bins guessed from the frames seen so far and the noiseless
    frames (in pass 1, without a second draw of their noise); those guessed wrong are drawn again
    and moved. The run's and every time block's integrated images still equal the brute-force
    sums of their best frames (ranked over the run, or within the block), with chunks that
    straddle blocks; some frames move, not all. A detector so bright (1e12 photons) that the noise
    reorders no frame moves none: the noiseless frames predict the frames not seen yet, whose
    drift the ranks among the frames seen so far miss."""
    n, n_frames, chunk, seed, n_blocks = 32, 63, 5, 3, 3
    rng = np.random.default_rng(12)
    sigma = 1.0 + 2.0 * np.abs(np.sin(np.arange(n_frames) / 7.0)) + rng.uniform(0, 0.3, n_frames)  # drifting
    pos = rng.uniform(10, 22, size=(n_frames, 2))
    idx = np.arange(n)
    frames = np.exp(
        -((idx[None, :, None] - pos[:, 0, None, None]) ** 2 + (idx[None, None, :] - pos[:, 1, None, None]) ** 2)
        / (2 * sigma[:, None, None] ** 2)
    )
    frames = (frames / frames.sum(axis=(1, 2), keepdims=True)).astype(np.float32)
    det = Detector("emccd", 2000.0, 0.1)
    fractions = [0.1, 0.3, 0.5, 1.0]
    peak = 1 / (2 * np.pi)
    ds = run_lucky(
        chunker(frames, chunk),
        n_frames,
        [Detector("ideal"), det, Detector("bright", 1e12)],
        fractions,
        peak,
        0.02,
        seed,
        image_crop_px=None,
        n_blocks=n_blocks,
        progress_interval_s=0,
    )
    ideal_drawn, emccd_drawn, bright_drawn = ds.attrs["frames_drawn_again"]
    assert ideal_drawn == 0 and 0 < emccd_drawn < n_frames and bright_drawn == 0
    for name in ("strehl", "d50"):
        np.testing.assert_array_equal(
            rank_frames(ds.frame_criterion.sel(criterion=name, detector="bright"), True),
            rank_frames(ds.frame_criterion.sel(criterion=name, detector="ideal"), True),
        )
    noisy = detect(frames, det, seed)
    per_block = n_frames // n_blocks
    for name, larger in (("strehl", True), ("d50", False)):
        values = ds.frame_criterion.sel(criterion=name, detector="emccd").values
        for block in [None, *range(n_blocks)]:
            first, count_of = (0, n_frames) if block is None else (block * per_block, per_block)
            frame_ids = range(first, first + count_of)
            order = sorted(frame_ids, key=lambda f: ((-1 if larger else 1) * values[f], f))
            for fraction, count in zip(fractions, fraction_counts(count_of, fractions)):
                expected = brute_force_strehl(noisy, order, count, peak, strehl_flux_of(frames, det, order, count))
                got = (
                    ds.strehl.sel(criterion=name, fraction=fraction, detector="emccd")
                    if block is None
                    else ds.strehl_block.sel(block=block, criterion=name, fraction=fraction, detector="emccd")
                )
                assert float(got) == pytest.approx(expected, rel=1e-9), (block, name, fraction)
                if block is None:
                    clean = brute_force_image(frames, order, count, centroid_frames=noisy)
                    assert float(
                        ds.strehl_noiseless.sel(criterion=name, fraction=fraction, detector="emccd")
                    ) == pytest.approx(float(clean.max() / peak), rel=1e-9)


def test_noiseless_selection_picks_the_sharpest_frames():
    """Centred Gaussians of known widths: Strehl (peak 1/(2 pi sigma^2)) and d50
    (2 sigma sqrt(2 ln 2)) both rank the narrowest first; the 25% selection keeps exactly
    the 25% smallest sigma."""
    n, n_frames = 32, 20
    sigma = np.random.default_rng(8).permutation(np.linspace(1.0, 2.9, n_frames))
    idx = np.arange(n) - n // 2
    r2 = idx[:, None] ** 2 + idx[None, :] ** 2
    frames = np.exp(-r2[None] / (2 * sigma[:, None, None] ** 2))
    frames = (frames / frames.sum(axis=(1, 2), keepdims=True)).astype(np.float32)
    ds = run_lucky(
        chunker(frames, 6), n_frames, [Detector("ideal")], [0.25, 1.0], 1 / (2 * np.pi), 1.0, 0, image_crop_px=None
    )
    np.testing.assert_allclose(ds.frame_strehl[0], 1 / sigma**2, rtol=1e-3)
    np.testing.assert_allclose(ds.frame_d50_arcsec[0], 2 * sigma * np.sqrt(2 * np.log(2)), rtol=2e-3)
    best = np.sort(np.argsort(sigma)[:5])
    expected = frames[best].sum(axis=0, dtype=np.float64)
    for name in ("strehl", "d50"):
        got = ds.image.sel(criterion=name, fraction=0.25, detector="ideal").values
        np.testing.assert_allclose(got, expected / expected.sum(), rtol=1e-5, atol=1e-8)


def test_long_exposure_strehl_of_wandering_diffraction_limited_images():
    """Half the frames displaced by +(6, 9) px, half by -(7, 4): recentred, the long exposure
    is diffraction limited (Strehl 1); not recentred, its peak is half the
    diffraction-limited one (Strehl 1/2, plus the other image's wing there, < 1e-2)."""
    imager = Imager(Telescope(4.2, 1.2), Camera(800e-9, 64, 5 / 256))
    dl = imager.diffraction_limited
    frames = np.stack([np.roll(dl, (6, 9), axis=(0, 1))] * 5 + [np.roll(dl, (-7, -4), axis=(0, 1))] * 5)
    ds = run_lucky(
        chunker(frames, 4),
        10,
        [Detector("ideal")],
        [0.5, 1.0],
        imager.diffraction_limited_peak,
        imager.camera.pixel_scale_arcsec,
        0,
    )
    s = ds.long_exposure_strehl.sel(detector="ideal")
    assert float(s.sel(recentring="cog")) == pytest.approx(1.0, abs=1e-6)
    assert float(s.sel(recentring="none")) == pytest.approx(0.5, abs=1e-2)
    np.testing.assert_allclose(ds.strehl, 1.0, atol=1e-6)


def test_dataset_is_cf_labelled():
    frames = np.zeros((4, 16, 16), dtype=np.float32)
    frames[:, 8, 8] = 1.0
    ds = run_lucky(chunker(frames, 4), 4, [Detector("ideal"), Detector("scmos", 100.0, 1.0)], [0.5, 1.0], 1.0, 0.02, 0)
    assert ds.strehl.dims == ("criterion", "fraction", "detector")
    assert ds.long_exposure_strehl.dims == ("recentring", "detector")
    for name in list(ds.data_vars) + list(ds.coords):
        assert {"units", "long_name"} <= set(ds[name].attrs), name


BATCHED_D50 = ("d50_arcsec", "d50_arcsec_noiseless", "long_exposure_d50_arcsec")
"""Scored by :class:`EncircledEnergy` in float32 batches of 32 images (FFT and matrix
product) holding every detector's images: their last bits (measured <= 1.5e-7 relative)
depend on the other images of the batch, so on the other detectors."""


def assert_detector_unchanged(ds_a, ds_b, detector):
    """Every variable of ``detector`` equal in both datasets: exactly, or within 1e-6
    (float32 batch rounding, a few 1e-7) for the batched d50 scores."""
    for name, var in ds_a.data_vars.items():
        if "detector" in var.dims:
            a, b = var.sel(detector=detector), ds_b[name].sel(detector=detector)
            if name in BATCHED_D50:
                np.testing.assert_allclose(a, b, rtol=1e-6, err_msg=name)
            else:
                np.testing.assert_array_equal(a, b, err_msg=name)


def test_detector_noise_depends_on_its_name_only():
    """A detector's draws are keyed by its name (crc32), not its position: run alone or after
    other detectors it gives the same numbers (frames, centroids, selections, images bit for
    bit); another name with the same parameters gives other draws; duplicate names are
    refused."""
    n, n_frames = 16, 12
    frames = np.stack([compact_pattern(n, np.random.default_rng(k)) for k in range(n_frames)])
    frames /= frames.sum(axis=(1, 2), keepdims=True)

    def run(detectors):
        return run_lucky(chunker(frames, 5), n_frames, detectors, [0.25, 1.0], 0.1, 0.02, 7, progress_interval_s=0)

    a = Detector("a", 300.0, 1.0)
    alone = run([a])
    among = run([Detector("ideal"), Detector("b", 300.0, 1.0), a])
    assert_detector_unchanged(alone, among, "a")
    a_strehl = among.frame_strehl.sel(detector="a").values
    b_strehl = among.frame_strehl.sel(detector="b").values
    assert not np.any(a_strehl == b_strehl)  # every frame's draw differs
    assert detector_key("a") != detector_key("b")
    with pytest.raises(ValueError, match="distinct"):
        run([a, Detector("a", 10.0, 0.1)])


N_CUBE, SEED_CUBE = 48, 21
FRACTIONS_CUBE = [1 / N_CUBE, 0.1, 0.5, 1.0]  # 1, 5, 24 and 48 frames


@pytest.fixture(scope="module")
def cube():
    """48 Nyquist-sampled images (64 px, 800 nm, 4.2 m) of white random phases of rms
    sigma uniform in [0.3, 1.7] rad (Strehl exp(-sigma^2), 0.05 to 0.9) plus integer-pixel
    tilts within +-5 px; the external criterion ``lgs_rms`` is sigma (the frame's true
    quality). Lucky imaging for a noiseless, a very bright (1e10 photons, 0.1 e-) and a
    vanishing-signal (0.05 photon, 1 e-) detector."""
    imager = Imager(Telescope(4.2, 1.2), Camera(800e-9, 64, 5 / 256))
    rng = np.random.default_rng(SEED_CUBE)
    sigma = rng.uniform(0.3, 1.7, N_CUBE)
    x, y = (c[imager.mask] for c in imager.grid.xy_m)
    tilt_rad = rng.integers(-5, 6, (N_CUBE, 2)) * imager.camera.pixel_scale_rad
    phase = (
        sigma[:, None] * rng.standard_normal((N_CUBE, imager.n_valid))
        + 2 * np.pi * (tilt_rad[:, :1] * y + tilt_rad[:, 1:] * x) / 800e-9
    )
    frames = imager.image(phase.astype(np.float32))
    detectors = [Detector("ideal"), Detector("bright", 1e10, 0.1), Detector("faint", 0.05, 1.0)]
    external = ExternalCriterion("lgs_rms", 100 * sigma, False, "nm")
    peak = imager.diffraction_limited_peak
    ds = run_lucky(
        chunker(frames, 20),
        N_CUBE,
        detectors,
        FRACTIONS_CUBE,
        peak,
        imager.camera.pixel_scale_arcsec,
        5,
        criteria_external=[external],
        progress_interval_s=0,
    )
    return frames, peak, imager.camera.pixel_scale_arcsec, external, ds


def test_noiseless_detector_noiseless_scores_are_its_scores_bit_for_bit(cube):
    """Noiseless detector: same selection, same shifts, same frames, same arithmetic, so the
    ``*_noiseless`` values equal the others exactly; and they are those of the detector run
    alone (the noisy detectors beside it change nothing but the batched d50's last bits)."""
    frames, peak, scale, external, ds = cube
    ideal = ds.sel(detector="ideal")
    for name in ("strehl", "fwhm_arcsec", "d50_arcsec"):
        np.testing.assert_array_equal(ideal[name], ideal[f"{name}_noiseless"], err_msg=name)
        assert ds[f"{name}_noiseless"].attrs["units"] == ds[name].attrs["units"]
        assert "noiseless frames" in ds[f"{name}_noiseless"].attrs["long_name"]
    alone = run_lucky(
        chunker(frames, 20),
        N_CUBE,
        [Detector("ideal")],
        FRACTIONS_CUBE,
        peak,
        scale,
        5,
        criteria_external=[external],
        progress_interval_s=0,
    )
    assert_detector_unchanged(alone, ds, "ideal")


def test_very_bright_detector_converges_to_noiseless(cube):
    """1e10 photons per frame, 0.1 e-: the peak pixel of the worst frame (Strehl 0.05,
    P_dl = 0.18) holds N P_dl S ~ 1e8 photons, so the relative photon noise of a frame's
    Strehl is eps = 1/sqrt(N P_dl S_min) ~ 1e-4 (read noise: 0.1 e- x 64 px ~ 6 e- per
    frame, nothing). Frame Strehls agree within 5 eps (measured 1.25e-4); the ranking and
    the whole-pixel shifts are then the noiseless ones (checked), and every integrated score
    agrees within 5 eps (their peaks hold >= the worst frame's photons; FWHM and d50 use
    pixels >= half the peak or the whole image; measured <= 4e-5). The noiseless scores of
    the same selection and shifts are the noiseless detector's (Strehl and FWHM exactly,
    d50 to the float32 batch rounding, 2e-7)."""
    _, peak, _, _, ds = cube
    ideal, bright = ds.sel(detector="ideal"), ds.sel(detector="bright")
    s_min = float(ideal.frame_strehl.min())
    eps = 1 / np.sqrt(1e10 * peak * s_min)
    assert 5e-5 < eps < 5e-4
    np.testing.assert_allclose(bright.frame_strehl, ideal.frame_strehl, rtol=5 * eps)
    for criterion in ds.criterion.values:
        c = ds.criterion.values.tolist().index(criterion)
        np.testing.assert_array_equal(
            rank_frames(bright.frame_criterion[c], bool(ds.larger_is_better[c])),
            rank_frames(ideal.frame_criterion[c], bool(ds.larger_is_better[c])),
        )
    np.testing.assert_array_equal(
        recentring_shifts_px(bright.frame_centroid_px, 64), recentring_shifts_px(ideal.frame_centroid_px, 64)
    )
    for name in ("strehl", "fwhm_arcsec", "d50_arcsec"):
        np.testing.assert_allclose(bright[name], ideal[name], rtol=5 * eps, err_msg=name)
        np.testing.assert_allclose(bright[f"{name}_noiseless"], ideal[name], rtol=1e-6, err_msg=name)


def test_vanishing_signal_selects_at_random_but_external_criterion_does_not(cube):
    """0.05 photon per frame under 1 e- read noise: the image Strehl and centroid are noise.

    * The external criterion's bins do not depend on the detector: its ``strehl_noiseless``
      is that of the best-``lgs_rms`` frames with this detector's (noisy) shifts, computed
      here by brute force; with one frame (shift-free Strehl) it is the best frame's, the
      same for every detector.
    * Selection by image Strehl is no better than random: its ``strehl_noiseless`` for 5
      frames lies within the central 99% of the same score for 4000 random 5-frame subsets
      with the same shifts (the null distribution, computed here with the module's
      shift-and-add; a 1% chance of failing by bad luck, fixed seeds). The noiseless
      detector's image selection lies far above its own null (the test can fail).
    * With one frame, the external criterion beats the image-selected frame.
    """
    frames, peak, _, external, ds = cube
    true_strehl = strehl(frames, peak)  # circular shifts leave a frame's Strehl unchanged
    faint, ideal = ds.sel(detector="faint"), ds.sel(detector="ideal")
    by_quality = rank_frames(external.values, larger_is_better=False)
    shifts = {d: recentring_shifts_px(ds.frame_centroid_px.sel(detector=d).values, 64) for d in ("faint", "ideal")}
    assert np.mean(np.any(shifts["faint"] != shifts["ideal"], axis=1)) > 0.8  # noise
    moved = {d: shift_frames(frames, s).astype(np.float64) for d, s in shifts.items()}
    for fraction, count in zip(FRACTIONS_CUBE, fraction_counts(N_CUBE, FRACTIONS_CUBE)):
        expected = strehl(moved["faint"][by_quality[:count]].sum(axis=0), peak)
        assert float(faint.strehl_noiseless.sel(criterion="lgs_rms", fraction=fraction)) == pytest.approx(
            expected, rel=1e-6
        )
    one = FRACTIONS_CUBE[0]
    best = ds.strehl_noiseless.sel(criterion="lgs_rms", fraction=one).values
    np.testing.assert_allclose(best, true_strehl.max(), rtol=1e-6)  # every detector
    picked = float(faint.strehl_noiseless.sel(criterion="strehl", fraction=one))
    assert picked < float(best[0])

    rng = np.random.default_rng(0)
    subsets = np.argsort(rng.random((4000, N_CUBE)), axis=1)[:, :5]

    def null(d):
        return strehl(moved[d][subsets].sum(axis=1), peak)

    got = float(faint.strehl_noiseless.sel(criterion="strehl", fraction=0.1))
    lo, hi = np.quantile(null("faint"), [0.005, 0.995])
    assert lo < got < hi
    assert float(ideal.strehl_noiseless.sel(criterion="strehl", fraction=0.1)) > null("ideal").max()


def test_registration_methods_images_cut_to_the_square_they_all_hold():
    """On a coarse camera (2.5 m: 31 mas pixels) a sub-pixel method keeps its 1.25" crop, 40
    pixels, against ``image_crop_px`` 64 for ``cog``: every method's images are the central 40
    (each over its whole frame's flux, so the values are the same pixels'), one square along
    ``lucky.nc``'s registration, not NaN padding; the 4.2 m camera keeps its 64."""
    import xarray as xr

    from luckyao.lucky.cropped import crop_px
    from luckyao.lucky.dataset import add_images
    from luckyao.optics.imaging import Camera
    from luckyao.studyspec.lucky_settings import shared_image_crop_px

    coarse, default = Camera(8e-7, 160, 5.0 / 160), Camera(8e-7, 256, 5.0 / 256)
    assert crop_px(160, 5.0 / 160) == 40 and crop_px(256, 5.0 / 256) == 64
    assert shared_image_crop_px(64, ["cog", "xcorr"], coarse) == 40
    assert shared_image_crop_px(64, ["cog", "xcorr"], default) == 64  # the default study: unchanged
    assert shared_image_crop_px(64, ["cog"], coarse) == 64 and shared_image_crop_px(0, ["cog", "xcorr"], coarse) == 0
    m = shared_image_crop_px(None, ["cog", "xcorr"], coarse)
    rng = np.random.default_rng(1)
    whole, cropped = rng.random((1, 1, 1, 160, 160)), rng.random((1, 1, 1, 40, 40))
    cog = add_images(xr.Dataset(), whole, [whole[0, 0]], m, np.ones((1, 1, 1)), [np.ones(1)])
    xcorr = add_images(xr.Dataset(), cropped, [whole[0, 0]], m, np.ones((1, 1, 1)), [np.ones(1)])
    assert cog.sizes["y"] == xcorr.sizes["y"] == cog.sizes["x"] == 40
    np.testing.assert_array_equal(cog.image.values[0, 0, 0], whole[0, 0, 0, 60:100, 60:100].astype(np.float32))
    assert "central 40 x 40 pixels" in cog.image.attrs["long_name"]
