"""Low-light metrics that cannot be absurd: a noisy detector's Strehl over its expected flux,
the values beyond the diffraction limit and the d50 set by the field flagged."""

import numpy as np
import pytest
import xarray as xr

from luckyao.lucky.accumulation import WholeFrames
from luckyao.lucky.cropped import CroppedFrames
from luckyao.lucky.detector import Detector, KeyedNoise
from luckyao.lucky.limits import FIELD_EDGE, add_limit_flags, beyond_diffraction_limit, field_bound
from luckyao.lucky.metrics import EncircledEnergy, fwhm_arcsec, score_images, strehl, strehl_flux
from luckyao.lucky.pipeline import run_lucky
from luckyao.lucky.registration import Registration
from luckyao.lucky.scoring import expected_fluxes
from luckyao.optics.imaging import Camera, Imager
from luckyao.optics.pupil import Telescope

SCALE_ARCSEC = 5 / 256  # the study's camera: 800 nm, 4.2 m (1.2 m obscuration), lambda/D = 2.0 px


def diffraction_limited(n: int) -> tuple[np.ndarray, float]:
    """The obscured 4.2 m telescope's unit-flux diffraction-limited image (n, n) at 800 nm and
    its peak (the Strehl reference)."""
    imager = Imager(Telescope(4.2, 1.2), Camera(800e-9, n, SCALE_ARCSEC))
    return imager.diffraction_limited, imager.diffraction_limited_peak


def chunks_of(frames, size=16):
    return lambda: ((s, frames[s : s + size]) for s in range(0, len(frames), size))


def wandering(image: np.ndarray, n_frames: int, seed: int) -> np.ndarray:
    """``image`` rolled by random whole pixels (up to 6) each frame: images of the same Strehl."""
    rng = np.random.default_rng(seed)
    shifts = rng.integers(-6, 7, size=(n_frames, 2))
    return np.stack([np.roll(image, tuple(s), axis=(0, 1)) for s in shifts]).astype(np.float32)


def test_strehl_of_the_diffraction_limit_is_one_for_every_detector():
    """The diffraction-limited image, frame after frame (wandering by whole pixels): its Strehl
    is 1 with the noiseless detector (over its own flux) and, over the expected flux (N photons a
    frame), with a detector so bright that the photon noise is ~1e-5 of the peak; a frame's, an
    integrated image's and the long exposure's alike, by ``cog`` and by a sub-pixel method."""
    n, n_frames = 64, 40
    image, peak = diffraction_limited(n)
    frames = wandering(image, n_frames, 3)
    detectors = [Detector("noiseless"), Detector("bright", 1e12, 1.0)]
    for registration in (None, Registration("xcorr", image, 2.0)):
        extra = {} if registration is None else {"registration": registration}
        ds = run_lucky(chunks_of(frames), n_frames, detectors, [0.1, 0.5, 1.0], peak, SCALE_ARCSEC, 5, **extra)
        np.testing.assert_allclose(ds.frame_strehl, 1.0, rtol=1e-5)
        np.testing.assert_allclose(ds.strehl.sel(criterion=["strehl", "d50"]), 1.0, rtol=1e-5)
        assert not beyond_diffraction_limit("strehl", ds.strehl.sel(detector="noiseless").values, None).any()
        np.testing.assert_allclose(ds.long_exposure_strehl.sel(recentring="cog"), 1.0, rtol=1e-5)
        np.testing.assert_allclose(ds.frame_recentred_strehl, 1.0, rtol=1e-5)


def test_the_expected_flux_leaves_a_noiseless_images_scores_bit_for_bit():
    """Today's values on the noiseless detector: a Strehl over an expected flux of NaN is over the
    measured flux, bit for bit (whole frames and a sub-pixel method's vectors); a noiseless
    detector's frames' Strehl is :func:`.metrics.strehl` of them, and every value of it
    is the same whatever the noisy detector beside it (its place in the stacks the same: the
    scores of a stack's rows depend on its shape in their last bits, not on the other rows)."""
    n = 32
    rng = np.random.default_rng(4)
    images = rng.random((3, 2, 2, n, n)) + 0.1
    encircled = EncircledEnergy(n)
    nan = np.full((3, 2, 2), np.nan)
    for a, b in zip(score_images(images, 0.1, 0.02, encircled), score_images(images, 0.1, 0.02, encircled, nan)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(score_images(images, 0.1, 0.02, encircled)[0], strehl(images, 0.1))
    whole = WholeFrames(n, encircled, 0.1, 0.02)
    for a, b in zip(whole.score(images), whole.score(images, nan)):
        np.testing.assert_array_equal(a, b)
    cropped = CroppedFrames(n, 16, encircled, 0.1, 0.02)
    vectors = rng.random((3, 2, 2, *cropped.item_shape)) + 0.1
    for a, b in zip(cropped.score(vectors), cropped.score(vectors, nan)):
        np.testing.assert_array_equal(a, b)
    expected = np.where(np.arange(2) == 0, np.nan, 5.0) * np.ones((3, 2, 2))
    np.testing.assert_array_equal(strehl_flux(np.ones((3, 2, 2)), expected)[..., 0], 1.0)
    np.testing.assert_array_equal(strehl_flux(np.ones((3, 2, 2)), expected)[..., 1], 5.0)

    image, peak = diffraction_limited(n)
    frames = (wandering(image, 30, 8) * rng.uniform(0.5, 1.0, (30, 1, 1))).astype(np.float32)  # Strehls differ
    frames = frames / frames.sum(axis=(1, 2), keepdims=True)
    runs = [
        run_lucky(
            chunks_of(frames, 7),
            30,
            [Detector("noiseless"), Detector("noisy", photons, 1.0)],
            [0.1, 1.0],
            peak,
            SCALE_ARCSEC,
            2,
            n_blocks=3,
        ).sel(detector="noiseless")
        for photons in (30.0, 3000.0)
    ]
    for name, variable in runs[0].data_vars.items():
        np.testing.assert_array_equal(variable.values, runs[1][name].values, err_msg=name)
    np.testing.assert_allclose(runs[0].frame_strehl, strehl(frames, peak), rtol=1e-15)  # from its row sums


@pytest.mark.parametrize("detector", [Detector("emccd", 20.0, 0.1), Detector("scmos", 20.0, 1.0, True)])
def test_the_expected_flux_is_the_detected_frames_mean_flux(detector):
    """The flux estimate is unbiased: over many frames, a noisy detector's detected flux (Poisson
    photons, zero-mean read noise; an EMCCD's Gamma gain of mean 1) averages N times the noiseless
    frame's flux, to its standard error sqrt(N F (1 + EM) + n^2 sigma^2) / sqrt(frames) (4 sigma)."""
    n, n_frames, seed = 32, 2000, 9
    image, _ = diffraction_limited(n)
    unit = (0.7 * np.broadcast_to(image, (64, n, n))).astype(np.float32)  # a pupil transmitting 70 %
    noise = KeyedNoise(n, 64)
    fluxes = []
    for start in range(0, n_frames, 64):
        chunk = noise.prepare(unit)
        _, rows, _, _ = chunk.detect(detector, seed, start)
        fluxes.append(rows.sum(axis=1))
    flux = np.concatenate(fluxes)
    expected = detector.photons_per_frame * unit[0].sum(dtype=np.float64)
    variance = expected * (2 if detector.electron_multiplying else 1) + n * n * detector.read_noise_e**2
    assert abs(flux.mean() - expected) < 4 * np.sqrt(variance / len(flux))
    # the measured flux of a faint frame is often near zero or below: the Strehl over it absurd
    if detector.read_noise_e == 1.0:
        assert (flux < 0.2 * expected).mean() > 0.1


def test_selection_by_strehl_at_low_light_no_longer_keeps_the_frames_without_flux():
    """At 10 photons a frame under 1 e- of read noise (1024 pixels: 32 e- rms of flux), a frame's
    Strehl over its measured flux is largest where that flux is near zero: selection by it kept
    those frames. Over the expected flux (10 photons x the noiseless frame's), the frames kept
    have the flux of any other (their mean within noise of 10), every Strehl is finite, and the
    integrated image of the best 10 % is over 10 x its frames' expected flux."""
    n, n_frames, seed = 32, 400, 3
    image, peak = diffraction_limited(n)
    frames = wandering(image, n_frames, 1)
    det = Detector("faint", 10.0, 1.0)
    ds = run_lucky(chunks_of(frames, 50), n_frames, [det], [0.1, 1.0], peak, SCALE_ARCSEC, seed)
    frame_strehl = ds.frame_strehl[0].values
    assert np.isfinite(frame_strehl).all()
    measured = KeyedNoise(n, n_frames).prepare(frames).detect(det, seed, 0)[1].sum(axis=1)
    kept = np.argsort(-frame_strehl, kind="stable")[: int(ds.n_frames_selected.sel(fraction=0.1))]
    old = np.argsort(-(frame_strehl * 10.0 / measured), kind="stable")[: len(kept)]  # over the measured flux
    assert abs(measured[old].mean()) < 5  # the old selection: frames of almost no flux
    assert abs(measured[kept].mean() - 10) < 4 * 32 / np.sqrt(len(kept))
    expected = det.photons_per_frame * frames[kept].sum(dtype=np.float64)
    assert expected == pytest.approx(10.0 * len(kept), rel=1e-5)
    # the image lucky.nc keeps is over its measured flux; its Strehl is over the expected one
    peak_value = float(ds.image.sel(criterion="strehl", fraction=0.1).max()) * measured[kept].sum()
    assert float(ds.strehl.sel(criterion="strehl", fraction=0.1, detector="faint")) == pytest.approx(
        peak_value / (peak * expected), rel=1e-5
    )


def test_expected_fluxes_sum_each_selections_frames():
    """An integrated image's expected flux is the sum of its frames' (those of bins 0..last_bin);
    a noiseless detector's row (NaN) stays NaN."""
    estimate = np.array([[1.0, 2.0, 4.0, 8.0, 16.0], [np.nan] * 5])
    bins = np.array([[[0, 1, -1, 0, 1]], [[0, 0, 1, 1, -1]]])  # (det, criterion, frame)
    out = expected_fluxes(estimate, bins, np.array([0, 1]))
    np.testing.assert_array_equal(out[0, :, 0], [1 + 8, 1 + 2 + 8 + 16])
    assert np.isnan(out[..., 1]).all()


def test_the_field_bounds_a_d50_whose_energy_does_not_reach_half_within_it():
    """A compact image's d50 is measured; a uniform field's (its 50 % disc 0.8 of the field wide)
    is the field's, flagged; an image whose light sits in the corners never reaches 50 % within
    the inscribed disc (NaN), flagged; a d50 whose time blocks did not (error NaN), flagged."""
    n = 64
    field = n * SCALE_ARCSEC
    encircled = EncircledEnergy(n)
    compact, _ = diffraction_limited(n)
    flat = np.full((n, n), 1.0 / n**2)
    corners = np.zeros((n, n))
    y, x = np.indices((n, n))
    corners[np.hypot(y - n / 2, x - n / 2) > 0.5 * n] = 1.0
    corners /= corners.sum()
    images = np.stack([compact, flat, corners])
    d50 = 2 * SCALE_ARCSEC * encircled.radius_px(images, centres_px=np.full((3, 2), n / 2))
    assert d50[0] < 0.1 and d50[1] == pytest.approx(np.sqrt(2 / np.pi) * field, rel=0.02) and np.isnan(d50[2])
    assert d50[1] > FIELD_EDGE * field
    np.testing.assert_array_equal(field_bound(d50, None, field), [False, True, True])
    np.testing.assert_array_equal(field_bound(d50[:1], np.array([np.nan]), field), [True])
    np.testing.assert_array_equal(field_bound(d50[:1], np.array([0.001]), field), [False])


def test_values_beyond_the_diffraction_limit_are_flagged_and_the_limit_itself_is_not():
    """Flags: a Strehl above 1, a FWHM or d50 below the diffraction-limited image's, by the same
    measures; the diffraction-limited image's own values are not beyond it. ``add_limit_flags``
    writes them (int8, CF flag attributes) beside the integrated and long-exposure scores."""
    n = 64
    image, peak = diffraction_limited(n)
    d50_dl = 2 * SCALE_ARCSEC * float(EncircledEnergy(n).radius_px(image[None])[0])
    fwhm_dl = float(fwhm_arcsec(image, SCALE_ARCSEC))
    assert not beyond_diffraction_limit("d50_arcsec", d50_dl, d50_dl)
    assert not beyond_diffraction_limit("fwhm_arcsec", fwhm_dl, fwhm_dl)
    assert not beyond_diffraction_limit("strehl", float(strehl(image, peak)), None)
    np.testing.assert_array_equal(beyond_diffraction_limit("strehl", [0.5, 1.0, 1.2, np.nan], None), [0, 0, 1, 0])
    np.testing.assert_array_equal(beyond_diffraction_limit("d50_arcsec", [0.02, 0.3], d50_dl), [1, 0])
    dims = ("criterion", "fraction", "detector")
    ds = xr.Dataset(
        {
            "strehl": (dims, [[[0.3, 1.4]]]),
            "d50_arcsec": (dims, [[[0.5, 0.01]]]),
            "d50_arcsec_error": (dims, [[[0.01, np.nan]]]),
            "d50_arcsec_noiseless": (dims, [[[0.5, 3.0]]]),
            "long_exposure_strehl": (("recentring", "detector"), [[0.1, 1.1]]),
        },
        attrs={
            "n_pixels": n,
            "pixel_scale_arcsec": SCALE_ARCSEC,
            "diffraction_limited_d50_arcsec": d50_dl,
            "diffraction_limited_fwhm_arcsec": fwhm_dl,
        },
    )
    add_limit_flags(ds)
    assert ds.strehl_beyond_diffraction_limit.values.tolist() == [[[0, 1]]]
    assert ds.long_exposure_strehl_beyond_diffraction_limit.values.tolist() == [[0, 1]]
    assert ds.d50_arcsec_beyond_diffraction_limit.values.tolist() == [[[0, 1]]]
    assert ds.d50_arcsec_field_bound.values.tolist() == [[[0, 1]]]  # its error NaN
    assert ds.d50_arcsec_noiseless_field_bound.values.tolist() == [[[0, 1]]]  # 3" of a 1.25" field
    for name in ("strehl_beyond_diffraction_limit", "d50_arcsec_field_bound"):
        flag = ds[name]
        assert flag.dtype == np.int8 and flag.attrs["units"] == "1" and list(flag.attrs["flag_values"]) == [0, 1]
        assert len(flag.attrs["flag_meanings"].split()) == 2
