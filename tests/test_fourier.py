"""Fourier lucky imaging (Garrel, Guyon & Baudoz 2012) against theory and a brute-force selection."""

from functools import lru_cache

import numpy as np
import pytest

from luckyao.lucky.detector import Detector
from luckyao.lucky.fourier import FourierRun, FourierSelection, TopAmplitudes, amplitudes, spectra_of
from luckyao.lucky.pipeline import ImageReference, run_lucky_methods
from luckyao.lucky.ranking import fraction_counts
from luckyao.lucky.registration import Registration
from luckyao.optics.imaging import Camera, Imager
from luckyao.optics.pupil import Telescope

C = 16  # crop across [pixel]


def fourier_run(crops: np.ndarray, fractions, chunk: int = 7, n_blocks: int = 0) -> FourierRun:
    """The Fourier selection of crops (k, C, C) fed in chunks of ``chunk`` frames, both passes, over
    the whole run and ``n_blocks`` time blocks."""
    run = FourierRun(1, len(crops), fractions, crops.shape[-1], chunk, n_blocks)
    for start in range(0, len(crops), chunk):
        run.observe(0, crops[start : start + chunk], start)
    run.rank()
    for start in range(0, len(crops), chunk):
        part = crops[start : start + chunk]
        run.add(0, part, part.sum(axis=(1, 2), dtype=np.float64), start)
    return run


def fourier_of(crops: np.ndarray, fractions, chunk: int = 7) -> FourierSelection:
    """The whole run's selection of :func:`fourier_run`."""
    return fourier_run(crops, fractions, chunk).whole


def test_each_time_block_is_selected_as_a_run_of_its_own_frames():
    """The blocks' selections (the Monte-Carlo errors): block ``b`` of a run, fed in chunks that
    straddle the blocks' edges, gives the images of a run over block ``b``'s frames alone; the
    frames past the last block are in none."""
    crops = np.random.default_rng(5).random((47, C, C)).astype(np.float32)
    run = fourier_run(crops, [0.1, 0.5, 1.0], chunk=7, n_blocks=3)  # blocks of 15 frames, 2 left out
    assert run.block_frames == 15
    for b, block in enumerate(run.blocks):
        alone = fourier_of(crops[15 * b : 15 * (b + 1)], [0.1, 0.5, 1.0], chunk=4)
        np.testing.assert_array_equal(block.kept, alone.kept)
        np.testing.assert_allclose(block.images([True])[0], alone.images([True])[0], rtol=0, atol=1e-12)


def test_identical_frames_combine_to_the_frame():
    """Every amplitude ties at every frequency: any n_f frames average to the frame itself."""
    frame = np.random.default_rng(1).random((C, C)).astype(np.float32)
    crops = np.repeat(frame[None], 23, axis=0)
    images, flux, _ = fourier_of(crops, [0.05, 0.3, 1.0]).images([True])
    for image, f in zip(images[0, 0], flux[0, 0]):
        np.testing.assert_allclose(image, frame, rtol=0, atol=1e-12)
        assert f == pytest.approx(frame.sum(dtype=np.float64), rel=1e-15)


def test_selection_keeps_the_largest_amplitudes_count_per_frequency():
    """Brute force: at each frequency the n_f frames of largest amplitude (ties in frame order, the
    stable sort), their complex values averaged; duplicated frames make ties. The streamed top-k
    (chunks of 7, buffers cut) finds the same thresholds."""
    rng = np.random.default_rng(2)
    crops = rng.random((40, C, C)).astype(np.float32)
    crops[30:] = crops[:10]  # ties
    fractions = [0.025, 0.1, 0.25, 0.5, 1.0]
    selection = fourier_of(crops, fractions)
    assert (selection.kept[0] == fraction_counts(40, fractions)[:, None]).all()
    spectra = spectra_of(crops).reshape(40, -1)
    amp = amplitudes(spectra.reshape(40, C, C // 2 + 1))
    for j, n_f in enumerate(fraction_counts(40, fractions)):
        order = np.argsort(-amp, axis=0, kind="stable")[:n_f]  # (n_f, freq)
        expected = np.take_along_axis(spectra, order, axis=0).sum(axis=0)
        np.testing.assert_allclose(selection.sums[0, 0, j], expected, rtol=1e-13, atol=1e-12)


def test_top_amplitudes_thresholds_and_ties():
    top = TopAmplitudes(keep=4, n_freq=1, slack=1)
    for value in [3, 1, 5, 5, 2, 5, 0, 4]:
        top.add(np.array([[value]], np.float32))
    threshold, ties = top.thresholds(np.array([1, 3, 4]))
    np.testing.assert_array_equal(threshold[:, 0], [5, 5, 4])
    np.testing.assert_array_equal(ties[:, 0], [1, 3, 1])


def test_selection_is_hermitian_so_the_image_is_real():
    """The amplitudes of q and -q are equal on the self-conjugate columns (exactly), so the same
    frames are kept at both, and the full plane's average (the fft2 of the kept frames, the mask of
    the right half taken from its mirror) is the transform of a real image."""
    rng = np.random.default_rng(3)
    crops = rng.random((30, C, C)).astype(np.float32)
    amp = amplitudes(spectra_of(crops)).reshape(30, C, C // 2 + 1)
    mirror = (-np.arange(C)) % C
    for column in (0, C // 2):
        np.testing.assert_array_equal(amp[:, :, column], amp[:, mirror, column])
    selection = fourier_of(crops, [0.1])
    images, _, _ = selection.images([True])
    # the full plane: kept frames at (ky, kx) for kx <= C/2 from the half plane, else from (-ky, -kx)
    keep = np.zeros((30, C, C), bool)
    half = np.zeros((30, amp[0].size), bool)
    for q in range(amp[0].size):
        half[np.argsort(-amp.reshape(30, -1)[:, q], kind="stable")[:3], q] = True
    half = half.reshape(30, C, C // 2 + 1)
    keep[:, :, : C // 2 + 1] = half
    kx = np.arange(C // 2 + 1, C)
    keep[:, :, kx] = half[:, mirror][:, :, (-kx) % C]
    full = np.where(keep, np.fft.fft2(crops.astype(np.float64)), 0).sum(axis=0) / 3
    image = np.fft.ifft2(full)
    assert np.abs(image.imag).max() < 1e-13 * np.abs(image.real).max()
    np.testing.assert_allclose(images[0, 0, 0], image.real, atol=1e-13)


@lru_cache
def cube(n_frames: int = 30, n: int = 64):
    """Nyquist-sampled images (800 nm, 4.2 m) of white random phases of rms 0.3-1.5 rad with tilts
    of a few pixels (whole and fractional), the diffraction-limited peak and the pixel scale."""
    imager = Imager(Telescope(4.2, 1.2), Camera(800e-9, n, 5 / 256))
    rng = np.random.default_rng(7)
    sigma = rng.uniform(0.3, 1.5, n_frames)
    x, y = (c[imager.mask] for c in imager.grid.xy_m)
    tilt = rng.uniform(-4, 4, (n_frames, 2)) * imager.camera.pixel_scale_rad
    phase = (
        sigma[:, None] * rng.standard_normal((n_frames, imager.n_valid))
        + 2 * np.pi * (tilt[:, :1] * y + tilt[:, 1:] * x) / 800e-9
    )
    frames = imager.image(phase.astype(np.float32))
    return frames, imager


def run(detectors, fourier, methods=("cog", "xcorr"), crop=32):
    frames, imager = cube()
    core = 800e-9 / 4.2 / imager.camera.pixel_scale_rad
    registrations = [Registration(m, imager.diffraction_limited, core) for m in methods]
    return run_lucky_methods(
        lambda: ((s, frames[s : s + 8]) for s in range(0, len(frames), 8)),
        len(frames),
        detectors,
        [0.1, 0.5, 1.0],
        imager.diffraction_limited_peak,
        imager.camera.pixel_scale_arcsec,
        11,
        image_crop_px=crop,
        n_blocks=3,
        progress_interval_s=0,
        registrations=registrations,
        crop_px=crop,
        fourier_fractions=fourier,
    )


DETECTORS = [Detector("ideal"), Detector("faint", 300.0, 0.5)]


def test_fourier_at_every_frame_is_shift_and_add_and_changes_nothing_else():
    """At 100 % every frequency keeps every frame: the image is the shift-and-add one and its
    Strehl the same to float64 rounding (the image's peak over the frames' flux, both ways); its
    FWHM too for the sub-pixel method (both from the same crop; ``cog``'s from the whole frame:
    close). Every other variable is bit for bit that of a run without Fourier lucky imaging."""
    plain, with_fourier = run(DETECTORS, None), run(DETECTORS, [0.1, 1.0])
    for before, after in zip(plain, with_fourier):
        for name, var in before.data_vars.items():
            np.testing.assert_array_equal(var.values, after[name].values, err_msg=name)
        fourier = after.sel(fourier_fraction=1.0)
        saa = after.sel(fraction=1.0, criterion="strehl")
        for suffix in ("", "_noiseless"):
            np.testing.assert_allclose(fourier[f"fourier_strehl{suffix}"], saa[f"strehl{suffix}"], rtol=1e-12)
        np.testing.assert_allclose(fourier.fourier_image, saa.image, rtol=1e-6, atol=1e-9)
        assert after.fourier_n_frames_selected.values.tolist() == [3, 30]
        ideal = after.sel(detector="ideal")
        for name in ("strehl", "fwhm_arcsec", "d50_arcsec"):
            np.testing.assert_array_equal(ideal[f"fourier_{name}"], ideal[f"fourier_{name}_noiseless"])
    np.testing.assert_allclose(
        with_fourier[1].sel(fourier_fraction=1.0).fourier_fwhm_arcsec,
        with_fourier[1].sel(fraction=1.0, criterion="strehl").fwhm_arcsec,
        rtol=1e-9,
    )


def test_fourier_selection_beats_frame_selection_on_positive_spectra():
    """Frames of one point blurred by centred elliptical Gaussians of random widths and angles: their
    spectra are real and positive, so at each frequency the mean of the n_f largest values is at least
    that of any n_f frames, and the image's peak (the sum of its spectrum) is above that of the n_f
    frames of the highest peak (shift-and-add's best selection), strictly when the best frames differ
    between frequencies."""
    rng = np.random.default_rng(5)
    y, x = np.mgrid[:C, :C] - C // 2
    crops = []
    for _ in range(40):
        a, b, angle = rng.uniform(0.6, 2.5), rng.uniform(0.6, 2.5), rng.uniform(0, np.pi)
        u, v = x * np.cos(angle) + y * np.sin(angle), -x * np.sin(angle) + y * np.cos(angle)
        blur = np.exp(-0.5 * ((u / a) ** 2 + (v / b) ** 2))
        crops.append(blur / blur.sum())
    crops = np.array(crops, np.float32)
    images, flux, _ = fourier_of(crops, [0.1]).images([True])
    best = np.argsort(-crops.max(axis=(1, 2)), kind="stable")[:4]
    frame_selected = crops[best].astype(np.float64).mean(axis=0)
    assert images[0, 0, 0].max() / flux[0, 0, 0] > 1.05 * frame_selected.max() / frame_selected.sum()


def test_no_fourier_with_references():
    frames, _ = cube()
    reference = ImageReference(np.ones((1, 30)), np.ones((1, 30)), np.full((1, 30, 2), 32.0))
    with pytest.raises(ValueError, match="Fourier"):
        run_lucky_methods(
            lambda: iter([(0, frames)]),
            30,
            [Detector("ideal")],
            [0.1],
            1.0,
            0.02,
            1,
            references=[reference],
            fourier_fractions=[0.1],
        )


def test_fourier_config_is_checked_before_any_job():
    """Its cases known and without a reference target; a fourier figure's cases among them, its
    fractions Fourier's; a case's lucky settings carry the fractions only when listed."""
    from luckyao.jobs.resources import fourier_memory_bytes
    from luckyao.studyspec.lucky import lucky_settings
    from luckyao.studyspec.schema import ConfigError
    from luckyao.studyspec.study import validate_study

    from studies import tiny

    study = tiny()
    study["lucky"]["fourier"] = {"cases": ["good", "nope", "field"], "fractions": [0.1, 1.0]}
    with pytest.raises(ConfigError) as refused:
        validate_study(study)
    assert "lucky.fourier.cases': unknown case 'nope'" in str(refused.value)
    assert "case 'field' has a reference_target" in str(refused.value)
    study["lucky"]["fourier"]["cases"] = ["good"]
    study["figures"]["fourier"] = {
        "kind": "fourier",
        "cases": ["good", "bad"],
        "criteria": ["strehl"],
        "fractions": [0.1],
    }
    with pytest.raises(ConfigError, match="lucky.fourier.cases': case 'bad' is not one"):
        validate_study(study)
    study["figures"]["fourier"]["cases"] = ["good"]
    cases = validate_study(study)
    assert lucky_settings(study, cases, "good")["fourier_fractions"] == [0.1, 1.0]
    assert "fourier_fractions" not in lucky_settings(study, cases, "bad")
    assert lucky_settings(study, cases, "bad") == lucky_settings(tiny(), cases, "bad")
    # the pre-flight's memory: 1.25 x (at least a chunk of 64) float32 amplitudes at each of the 64-pixel
    # crop's 2,112 frequencies, per detector (2) and method (cog), for the run and each time block
    settings = lucky_settings(study, cases, "good")
    runs = 1 + settings["error_blocks"]
    assert fourier_memory_bytes(settings) == 1.25 * 64 * 2112 * 4 * 2 * runs
    assert fourier_memory_bytes(lucky_settings(study, cases, "bad")) == 0


@pytest.mark.workflow
def test_a_case_with_fourier_lucky_imaging_keeps_every_other_number_and_draws_its_figure(tmp_path):
    """The tiny study's detector-sweep case (cog and xcorr, a noiseless, a faint and two sweep
    detectors) run with and without ``lucky.fourier``: every variable of ``lucky.nc`` but the new
    ``fourier_*`` ones bit for bit the same; the Fourier image at 100 % is shift-and-add's; the
    fourier figure's data and drawing."""
    import luckyao
    from luckyao.figures import FIGURE_KINDS, FigureSettings
    from luckyao.studyspec.study import validate_study

    from studies import TINY

    study = luckyao.load_study(TINY)
    plain = luckyao.run_case(study, "lgs", workdir=tmp_path / "plain")
    study["lucky"]["fourier"] = {"cases": ["lgs"], "fractions": [0.1, 1.0]}
    ds = luckyao.run_case(study, "lgs", workdir=tmp_path / "fourier")
    for name, var in plain.data_vars.items():
        np.testing.assert_array_equal(var.values, ds[name].values, err_msg=name)
    added = sorted(set(ds.data_vars) - set(plain.data_vars))
    assert all(name.startswith("fourier_") for name in added) and "fourier_strehl_noise_dominated" in added
    assert ds.fourier_strehl.dims == ("registration", "target", "fourier_fraction", "detector")
    np.testing.assert_allclose(
        ds.fourier_strehl.sel(fourier_fraction=1.0), ds.strehl.sel(fraction=1.0, criterion="strehl"), rtol=1e-12
    )
    settings = FigureSettings(
        kind="fourier",
        cases=("lgs",),
        case_configs={"lgs": validate_study(study)["lgs"]},
        criteria=("strehl", "lgs_rms"),
        fractions=(0.1, 1.0),
        read_noise_e=(0.1,),
    )
    data = FIGURE_KINDS["fourier"][0](settings, [ds])
    sizes = {"registration": 2, "case": 1, "fraction": 2, "read_noise": 1, "signal": 3}
    assert data.fourier_strehl_noiseless.sizes == sizes
    assert np.isfinite(data.fourier_strehl_noiseless).all()
    fig = FIGURE_KINDS["fourier"][1](data, "tiny")
    assert len(fig.axes) == 2 * 3  # a row per method: Strehl, d50, and 10 % against signal


def test_a_bright_detectors_selection_scored_on_the_noiseless_frames_is_the_noiseless_detectors():
    """1e10 photons per frame: the amplitudes' relative noise (~1e-5 at the frequencies that carry
    the image) barely moves the selection, and the shifts are the noiseless ones, so the bright
    detector's Fourier scores on the noiseless frames are the noiseless detector's (to 1e-3), while its
    own are within its photon noise of them."""
    ds = run([Detector("ideal"), Detector("bright", 1e10, 0.1)], [0.1, 1.0])[0]
    ideal, bright = ds.sel(detector="ideal"), ds.sel(detector="bright")
    for name in ("strehl", "d50_arcsec"):
        np.testing.assert_allclose(bright[f"fourier_{name}_noiseless"], ideal[f"fourier_{name}"], rtol=1e-3)
        np.testing.assert_allclose(bright[f"fourier_{name}"], ideal[f"fourier_{name}"], rtol=1e-3)
