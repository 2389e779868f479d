"""Registration on several stars (issue 44, item 1) against theory: the inverse-variance mean of N
stars' positions, each star's positions from its detected frames, the tilt anisoplanatism between
two directions, and a tiny field registered on 1, 2 and 3 stars through the workflow."""

import numpy as np
import pytest
import xarray as xr
import yaml

from luckyao.atmosphere.screens import periodic_screen_amplitude, periodic_screen_pair
from luckyao.atmosphere.statistics import von_karman_psd
from luckyao.atmosphere.tilt_anisoplanatism import differential_tilt_variance_rad2
from luckyao.lucky.detector import Detector
from luckyao.lucky.pipeline import run_lucky_methods
from luckyao.lucky.registration import COG, Registration
from luckyao.lucky.stars import combined_positions, noise_variance_px2, star_positions, star_weights
from luckyao.optics.imaging import Camera, Imager
from luckyao.optics.pupil import Telescope
from luckyao.studyspec.schema import ConfigError
from luckyao.studyspec.study import validate_study

from studies import snakemake, tiny

N = 64
SCALE_ARCSEC = 5 / 256


def sample_variance_tolerance(m: int) -> float:
    """Five standard errors of a ratio of two independent variance estimates from ``m`` Gaussian
    samples each (relative standard error sqrt(2 / (m - 1)) each)."""
    return 5 * np.sqrt(2 * 2 / (m - 1))


@pytest.mark.parametrize("n_stars", [2, 4])
def test_the_mean_of_n_equal_stars_has_one_nth_the_variance_of_one(n_stars):
    """N stars of equal noise, no anisoplanatism: equal weights, and the combined position's
    variance 1/N of one star's (Monte Carlo, independent samples, within 5 standard errors)."""
    m, rng = 20000, np.random.default_rng(1)
    positions = 32.0 + rng.normal(0.0, 0.7, (n_stars, m, 2))
    single = 32.0 + rng.normal(0.0, 0.7, (m, 2))
    weights = star_weights(np.full((n_stars, 2), 0.49), np.zeros((n_stars, 2)))
    np.testing.assert_allclose(weights, 1 / n_stars)
    combined = combined_positions(positions, weights)
    ratio = combined.var(axis=0) / single.var(axis=0)
    np.testing.assert_allclose(ratio, 1 / n_stars, rtol=sample_variance_tolerance(m))


def test_anisoplanatic_weights_give_the_inverse_variance_bound():
    """Stars whose errors are noise plus anisoplanatism (independent): weights 1 / (noise + aniso)
    give the combined variance 1 / sum(1 / (noise + aniso)), below the weights of the noise alone
    (which trust the bright far star); Monte Carlo within 5 standard errors."""
    m, rng = 20000, np.random.default_rng(2)
    noise = np.array([0.01, 0.2, 0.3])[:, None] * np.ones(2)  # a bright star far away, two faint near ones
    aniso = np.array([1.0, 0.05, 0.1])[:, None] * np.ones(2)
    errors = rng.normal(0.0, 1.0, (3, m, 2)) * np.sqrt(noise + aniso)[:, None, :]
    both = combined_positions(errors, star_weights(noise, aniso)).var(axis=0)
    noise_only = combined_positions(errors, star_weights(noise, np.zeros_like(aniso))).var(axis=0)
    bound = 1 / (1 / (noise + aniso)).sum(axis=0)
    np.testing.assert_allclose(both, bound, rtol=5 * np.sqrt(2 / (m - 1)))
    assert (noise_only > 2 * both).all()


def test_a_star_that_cannot_register_a_frame_drops_out_of_it():
    positions = np.array([[[1.0, 2.0], [np.nan, np.nan]], [[3.0, 4.0], [5.0, 6.0]]])  # (star, frame, 2)
    combined = combined_positions(positions, np.array([[0.75, 0.75], [0.25, 0.25]]))
    np.testing.assert_allclose(combined, [[1.5, 2.5], [5.0, 6.0]])
    assert np.isnan(combined_positions(np.full((2, 1, 2), np.nan), np.full((2, 2), 0.5))).all()


def airy() -> tuple[np.ndarray, float]:
    camera = Camera(800e-9, N, SCALE_ARCSEC)
    image = Imager(Telescope(4.2, 1.2), camera).diffraction_limited
    return image / image.sum(), camera.wavelength_m / 4.2 / camera.pixel_scale_rad


def spot_frames(m: int, rng) -> np.ndarray:
    """``m`` unit-flux frames of a Gaussian spot (sigma 2.5 px) moving about the axis by up to a pixel."""
    y, x = np.indices((N, N)) - N // 2
    centres = rng.uniform(-1, 1, (m, 2))
    frames = np.exp(-0.5 * ((y - centres[:, :1, None]) ** 2 + (x - centres[:, 1:, None]) ** 2) / 2.5**2)
    return (frames / frames.sum(axis=(1, 2), keepdims=True)).astype(np.float32)


def chunks_of(frames: np.ndarray, size: int = 50):
    return lambda: ((s, frames[s : s + size]) for s in range(0, len(frames), size))


def test_star_positions_are_the_pipelines_registered_positions():
    """A star's positions from one pass (each detector's noise keyed as the pipeline's) are bit for bit
    the lucky pipeline's ``frame_registered_px``, for ``cog`` and ``xcorr``, noisy and noiseless."""
    frames = spot_frames(120, np.random.default_rng(3))
    image, core = airy()
    methods = [COG, Registration("xcorr", image, core, 40)]
    detectors = [Detector("noiseless"), Detector("faint", 200.0, 0.1)]
    positions = star_positions(chunks_of(frames), len(frames), detectors, 11, methods)
    results = run_lucky_methods(
        chunks_of(frames), len(frames), detectors, [0.5, 1.0], 1e-2, SCALE_ARCSEC, 11, registrations=methods
    )
    for m, ds in enumerate(results):
        np.testing.assert_array_equal(positions[m], ds.frame_registered_px.values)


def test_detected_stars_combined_have_one_nth_the_noise_variance():
    """N stars with the same frames and flux, each its own detector noise (its seed): the combined
    position's noise variance (against the noiseless positions) is 1/N of one star's (within 5
    standard errors of the sample)."""
    m, n_stars = 3000, 3
    frames = spot_frames(m, np.random.default_rng(4))
    detectors = [Detector("noiseless"), Detector("faint", 150.0, 0.2)]
    positions = np.stack([star_positions(chunks_of(frames, 500), m, detectors, 100 + i, [COG]) for i in range(n_stars)])
    noise = noise_variance_px2(positions, positions[:, :, :1])  # (star, method, detector, 2)
    weights = star_weights(noise, np.full_like(noise, 1e-6))  # equal (the noiseless detector: by the 1e-6)
    combined = combined_positions(positions, weights)  # (method, detector, frame, 2)
    truth = positions[0, 0, 0]
    single = ((positions[0, 0, 1] - truth) ** 2).mean(axis=0)
    together = ((combined[0, 1] - truth) ** 2).mean(axis=0)
    np.testing.assert_allclose(together / single, 1 / n_stars, rtol=sample_variance_tolerance(m))
    np.testing.assert_allclose(combined[0, 0], truth, rtol=1e-14)  # the noiseless detector: the same positions


def kolmogorov_g_tilt_rad2(diameter_m: float, r0_m: float) -> float:
    """One direction's G-tilt variance per axis, Kolmogorov, unobscured: 0.170 (lambda/D)^2 (D/r0)^(5/3)
    (Tyler 1994; 0.16980 from the integral's closed form, Gradshteyn 6.574.2), at 500 nm."""
    return 0.16980 * (500e-9 / diameter_m) ** 2 * (diameter_m / r0_m) ** (5 / 3)


def test_differential_tilt_against_its_limits():
    """Far apart, two directions' tilts are independent: twice one direction's G-tilt variance (in
    every direction of separation); close, the motion along the separation varies three times as
    much as across it, and both grow as theta^2."""
    far = differential_tilt_variance_rad2([[1e9, 0.0], [0.0, 1e9]], [1e6], [1.0], 0.135, 1e12, 4.2)
    np.testing.assert_allclose(far, 2 * kolmogorov_g_tilt_rad2(4.2, 0.135), rtol=3e-3)
    near = differential_tilt_variance_rad2([[0.2, 0.0], [0.0, 0.1]], [1000.0], [1.0], 0.135, 20.0, 4.2, 1.2)
    assert near[0, 0] / near[0, 1] == pytest.approx(3.0, rel=1e-3)  # along x / across
    assert near[1, 1] / near[1, 0] == pytest.approx(3.0, rel=1e-3)
    assert near[0, 0] / near[1, 1] == pytest.approx(4.0, rel=1e-3)  # theta^2
    profile = differential_tilt_variance_rad2([[20.0, 0.0]], [0.0, 5000.0], [0.5, 0.5], 0.135, 20.0, 4.2, 1.2)
    layer = differential_tilt_variance_rad2([[20.0, 0.0]], [5000.0], [1.0], 0.135, 20.0, 4.2, 1.2)
    np.testing.assert_allclose(profile, 0.5 * layer, rtol=1e-12)  # a ground layer moves every direction alike


def test_differential_tilt_of_screens_against_theory():
    """The mean phase gradient over two annular pupils 1 and 3 m apart on von Karman screens (the
    study's periodic FFT screens, 25.6 m at 0.1 m; central differences): their difference's variance
    per axis is the theory's for one layer at 10 km and theta = separation / height, larger along
    the separation than across (Monte Carlo, 2000 screens, within 5 standard errors)."""
    n, dx, diameter, obscuration, r0, outer_scale, height = 256, 0.1, 4.2, 1.2, 0.135, 20.0, 1e4
    amplitude = periodic_screen_amplitude(lambda f: von_karman_psd(f, r0, outer_scale), n, dx)
    m = int(np.ceil(diameter / dx)) + 2
    r = np.hypot(*((np.indices((m, m)) - (m - 1) / 2) * dx))
    pupil = (r <= diameter / 2) & (r >= obscuration / 2)

    def tilt_rad(phase, row, col):  # (y, x) mean gradient over the pupil, as an angle
        box = phase[row - 1 : row + m + 1, col - 1 : col + m + 1]
        gy = (box[2:, 1:-1] - box[:-2, 1:-1]) / (2 * dx)
        gx = (box[1:-1, 2:] - box[1:-1, :-2]) / (2 * dx)
        return np.array([gy[pupil].mean(), gx[pupil].mean()]) * 500e-9 / (2 * np.pi)

    offsets_px, rng, draws = (10, 30), np.random.default_rng(5), 1000
    differences = {k: [] for k in offsets_px}
    for _ in range(draws):
        for phase in periodic_screen_pair(amplitude, rng):
            for k in offsets_px:
                differences[k].append(tilt_rad(phase, 80, 60 + k) - tilt_rad(phase, 80, 60))
    for k in offsets_px:
        theta_arcsec = k * dx / height * 180 / np.pi * 3600
        theory = differential_tilt_variance_rad2(
            [[theta_arcsec, 0.0]], [height], [1.0], r0, outer_scale, diameter, obscuration
        )[0, ::-1]  # (y, x)
        np.testing.assert_allclose(np.var(differences[k], axis=0), theory, rtol=5 * np.sqrt(2 / (2 * draws - 1)))
        assert theory[1] > 2 * theory[0]  # along the separation (x): 3 times across as theta -> 0


STARS = {"targets": [0, 2, 3], "flux_ratio": [1.0, 0.5, 0.5], "science_target": 1, "counts": [1, 2, 3]}


def stars_study() -> dict:
    """The tiny study with a field of 4 targets (the science target 10" off axis, stars at 0, 20
    and 10") registered on 1, 2 and 3 stars, and its ``more_stars`` figure."""
    study = tiny()
    study["cases"]["stars"] = {
        "lgs": {"enabled": True},
        "targets_arcsec": [[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [0.0, 10.0]],
        "reference_target": 0,
        "stars": STARS,
    }
    study["lucky"]["detector_sweep"]["cases"] = ["lgs", "stars"]
    study["figures"] = {
        "more_stars": {
            "kind": "more_stars",
            "cases": ["stars"],
            "criteria": ["lgs_rms", "strehl"],
            "fractions": [0.1, 1.0],
            "read_noise_e": [0.1],
        }
    }
    return study


@pytest.mark.parametrize(
    "change, key",
    [
        ({"targets": [2, 0, 3]}, "stars.targets"),  # the brightest is not the reference
        ({"targets": [0, 1, 3]}, "stars.targets"),  # the science target among the stars
        ({"flux_ratio": [0.5, 1.0, 0.5]}, "stars.flux_ratio"),
        ({"flux_ratio": [1.0, 0.5]}, "stars.flux_ratio"),
        ({"counts": [1, 4]}, "stars.counts"),
        ({"science_target": 7}, "stars'"),
    ],
)
def test_a_bad_stars_block_is_refused_naming_its_key(change, key):
    study = stars_study()
    study["cases"]["stars"]["stars"] = {**STARS, **change}
    with pytest.raises(ConfigError, match=f"cases.stars.{key}"):
        validate_study(study)


def test_stars_need_a_noiseless_detector_and_the_figure_a_case_with_stars():
    study = stars_study()
    del study["lucky"]["detectors"]["noiseless"]
    with pytest.raises(ConfigError, match="cases.stars.stars': needs a noiseless detector"):
        validate_study(study)
    study = stars_study()
    study["figures"]["more_stars"]["cases"] = ["lgs"]
    with pytest.raises(ConfigError, match="figures.more_stars.cases': case 'lgs' has no stars"):
        validate_study(study)


@pytest.mark.workflow
def test_a_field_registered_on_several_stars_through_the_workflow(tmp_path):
    """The tiny field through Snakemake: on one star the science target's values are the field's own
    (the single-star path, bit for bit); on 2 and 3 stars finite noiseless values; the anisoplanatism
    along the separation above the one across; the figure's knees per count of stars."""
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text(yaml.safe_dump(stars_study()))
    result = snakemake(tmp_path, "figures/more_stars.pdf")
    assert result.returncode == 0, result.stderr[-3000:]
    ds = xr.open_dataset(tmp_path / "results" / "cases" / "stars" / "lucky.nc")
    for name in ("strehl", "d50_arcsec", "strehl_noiseless", "d50_arcsec_noiseless", "strehl_error"):
        single = ds[f"stars_{name}"].sel(n_stars=1)
        np.testing.assert_array_equal(single.transpose(*ds[name].sel(target=1).dims), ds[name].sel(target=1), name)
    assert np.isfinite(ds.stars_strehl.sel(detector="noiseless").values).all()
    theory = ds.star_differential_tilt_variance_theory_px2
    assert (theory.sel(star=0, axis="x") > 2.9 * theory.sel(star=0, axis="y")).all()  # the separation along x
    figure = xr.open_dataset(tmp_path / "figures" / "more_stars.nc")
    assert figure.strehl_knee_photons.sizes["n_stars"] == 3
