"""The geometric LGS WFS (``wfs.model: geometric``): its mean gradients against the exact ones of
known phases, against the physical-optics sensor, its noise against the NEA (and the NEA against
a Monte-Carlo centre of gravity), the tomography weighing by the same NEA, and the config key's
default moving no hash."""

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from luckyao.layer_tomography.noise import SlopeNoise, SubapertureNoise
from luckyao.optics.pupil import Telescope
from luckyao.studyspec.case import Case
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, read_study, validate_study
from luckyao.studyspec.view import resolve_study
from luckyao.tomography.prior import TurbulencePrior
from luckyao.tomography.slopes import SlopeGeometry, slope_covariance
from luckyao.units import ARCSEC_RAD, REFERENCE_WAVELENGTH_M
from luckyao.wfs.beacons import LgsConfig, altitude_profile
from luckyao.wfs.centroiders import CentreOfGravity
from luckyao.wfs.geometric import (
    GeometricLgsSensor,
    centroid_noise_rad2,
    mean_gradients,
    node_grid,
    node_mask,
)
from luckyao.wfs.shack_hartmann import ShackHartmann, exposure_images, lgs_elongation_otf

CONFIG = Path(__file__).resolve().parents[1] / "config"
TINY = Path(__file__).parent / "data" / "tiny.yaml"
WFS = ShackHartmann(Telescope(4.2, 1.2), 8, 532e-9, n_pixels=8, pixel_scale_arcsec=0.5)


def exact_polynomial_gradients(wfs, coefficients) -> np.ndarray:
    """Exact mean x and y gradients (2, n_valid) over each sub-aperture of ``sum c_ij x^i y^j``:
    the integrals of the monomials' derivatives over the square, in closed form."""
    d = wfs.subaperture_m
    x0, y0 = wfs.subaperture_xy_m.T
    lo_x, hi_x, lo_y, hi_y = x0 - d / 2, x0 + d / 2, y0 - d / 2, y0 + d / 2

    def mean_power(lo, hi, k):  # mean of t^k over [lo, hi]
        return (hi ** (k + 1) - lo ** (k + 1)) / ((k + 1) * d)

    out = np.zeros((2, wfs.n_valid))
    for (i, j), c in coefficients.items():
        if i:
            out[0] += c * (hi_x**i - lo_x**i) / d * mean_power(lo_y, hi_y, j)
        if j:
            out[1] += c * mean_power(lo_x, hi_x, i) * (hi_y**j - lo_y**j) / d
    return out


def on_nodes(wfs, function) -> np.ndarray:
    x, y = node_grid(wfs).xy_m
    return function(x, y)


@pytest.mark.parametrize(
    "coefficients",
    [
        {(1, 0): 2e-6, (0, 1): -1e-6},  # tilt
        {(2, 0): 1e-6, (0, 2): 1e-6},  # defocus
        "random",  # every monomial up to degree 4
    ],
    ids=["tilt", "defocus", "random_degree_4"],
)
def test_mean_gradients_of_low_order_phases_are_exact(coefficients):
    """Simpson's rule on each edge: exact for polynomials up to degree 4 (to rounding)."""
    if coefficients == "random":
        rng = np.random.default_rng(3)
        coefficients = {(i, j): rng.normal() * 1e-6 for i in range(5) for j in range(5 - i)}

    def phase(x, y):
        return sum(c * x**i * y**j for (i, j), c in coefficients.items())

    gradients = mean_gradients(WFS, on_nodes(WFS, phase))
    expected = exact_polynomial_gradients(WFS, coefficients)
    np.testing.assert_allclose(gradients, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


def test_mean_gradients_of_sinusoids_are_within_simpsons_error():
    """``cos(k . r + c)``: exact mean gradient ``-k sinc(k_x d/2) sinc(k_y d/2) sin(k . r0 + c)``;
    the edge rule's error is below 0.5 % of the rms gradient up to half the sub-aperture's
    Nyquist frequency and below 6 % at it (the corners alone, Fried geometry: 25 % and 100 %)."""
    d = WFS.subaperture_m
    x0, y0 = WFS.subaperture_xy_m.T
    rng = np.random.default_rng(5)
    for frequency, tolerance in ((1 / (4 * d), 0.005), (1 / (2 * d), 0.06)):
        for _ in range(4):
            angle, offset = rng.uniform(0, 2 * np.pi, 2)
            k = 2 * np.pi * frequency * np.array([np.cos(angle), np.sin(angle)])
            gradients = mean_gradients(WFS, on_nodes(WFS, lambda x, y: np.cos(k[0] * x + k[1] * y + offset)))
            envelope = np.sinc(k[0] * d / (2 * np.pi)) * np.sinc(k[1] * d / (2 * np.pi))
            expected = -k[:, None] * envelope * np.sin(k[0] * x0 + k[1] * y0 + offset)
            error = np.abs(gradients - expected).max() / np.linalg.norm(k)
            assert error < tolerance, (frequency, error)


def test_node_mask_reads_only_the_valid_subapertures_edges():
    mask = node_mask(WFS)
    assert mask.shape == (17, 17) and np.array_equal(mask[1::2, 1::2], WFS.valid)  # the centres
    phase = np.where(mask, on_nodes(WFS, lambda x, y: 3e-6 * x - 2e-6 * y), np.nan)
    gradients = mean_gradients(WFS, phase)  # NaN anywhere it reads outside the mask
    np.testing.assert_allclose(gradients, [[3e-6] * WFS.n_valid, [-2e-6] * WFS.n_valid], rtol=1e-12)


def test_geometric_and_physical_slopes_of_the_same_phase_agree():
    """A smooth phase (degree <= 4, ~0.2" rms slopes), every beacon its own, seen by the physical
    sensor with a 4" field of 0.5" pixels (its centre of gravity is linear there) and the
    Rayleigh range gate's elongation (up to 1.3"), noiseless. The physical centroids are the mean
    gradients times a gain of 0.93 (0.90-0.97 allowed): the spot's wings beyond the finite field
    wrap (a square sub-aperture's sinc^2 holds ~2 % of its light beyond +-9.5 lambda/d, the
    field's half-width, and the elongated spot more), which pulls the centroid towards the
    centre; the physical sensor's calibration (``wfs.calibration: dither``) measures and removes
    this gain. After it, the slopes of fully lit sub-apertures agree to 6 % of the slopes' rms
    (4.4 % measured: the wrapped light's own shape, not a pure gain); on partly lit ones the
    physical sensor averages over the lit part only, the geometric over the square: 12 % (7.4 %
    measured)."""
    rng = np.random.default_rng(11)
    lgs = LgsConfig.rayleigh()
    n, n_launch = WFS.grid.n_pix, WFS.launch_grid.n_pix
    phases, geometric = np.zeros((2, 4, n, n), np.float32), np.zeros((4, 2, WFS.n_valid))
    for b in range(4):
        coefficients = {(i, j): rng.normal() * 0.4 ** (i + j) for i in range(5) for j in range(5 - i) if i + j > 1}

        def path_m(x, y, c=coefficients):
            return 1e-5 * sum(value * (x / 2.1) ** i * (y / 2.1) ** j for (i, j), value in c.items())

        x, y = WFS.grid.xy_m
        phases[:, b] = 2 * np.pi * path_m(x, y) / REFERENCE_WAVELENGTH_M
        geometric[b] = mean_gradients(WFS, on_nodes(WFS, path_m))
    images = exposure_images(
        WFS, phases, REFERENCE_WAVELENGTH_M, lgs_elongation_otf(WFS, lgs), np.zeros((2, 4, n_launch, n_launch))
    )
    physical = CentreOfGravity(WFS).positions(images, remove_tilt=True)
    geometric -= geometric.mean(axis=2, keepdims=True)
    full = WFS.illumination[WFS.valid] > 0.999
    rms = np.sqrt(np.mean(geometric**2))
    assert 0.1 < rms / ARCSEC_RAD < 0.4
    gain = (physical * geometric)[..., full].sum() / (geometric**2)[..., full].sum()
    assert 0.90 < gain < 0.97
    difference = physical / gain - geometric
    assert np.sqrt(np.mean(difference[..., full] ** 2)) < 0.06 * rms
    assert np.sqrt(np.mean(difference[..., ~full] ** 2)) < 0.12 * rms


def test_centroid_noise_formula_matches_a_monte_carlo_centre_of_gravity():
    """An elongated Gaussian spot (1.2" x 0.4" rms, 30 deg) on 16 x 16 pixels of 0.5" (untruncated),
    500 photons (Poisson, on the pixels) and 1 e- read noise: the centroids' sample covariance is
    the formula's within its sampling error (4,000 images: ~2.2 % on a variance; 6 % allowed)."""
    rng = np.random.default_rng(2)
    p, n, photons, read = 0.5 * ARCSEC_RAD, 16, 500.0, 1.0
    angle = np.deg2rad(30)
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    moments = rotation @ np.diag(np.array([1.2, 0.4]) ** 2 * ARCSEC_RAD**2) @ rotation.T
    centres = (np.arange(n) - (n - 1) / 2) * p
    fine = np.linspace(-n * p / 2, n * p / 2, 16 * n + 1)
    fine = 0.5 * (fine[1:] + fine[:-1])
    fx, fy = np.meshgrid(fine, fine)
    points = np.stack([fx, fy], -1)
    density = np.exp(-0.5 * np.einsum("...a,ab,...b->...", points, np.linalg.inv(moments), points))
    pixels = density.reshape(n, 16, n, 16).sum(axis=(1, 3))
    pixels *= photons / pixels.sum()
    images = rng.poisson(pixels, size=(4000, n, n)) + rng.normal(0, read, size=(4000, n, n))
    flux = images.sum(axis=(1, 2))
    cog = np.stack([(images * centres[None, None, :]).sum((1, 2)), (images * centres[None, :, None]).sum((1, 2))], 1)
    cog /= flux[:, None]
    sample = np.cov(cog.T)
    expected = centroid_noise_rad2(moments, photons, p, n, read)
    np.testing.assert_allclose(np.diag(sample), np.diag(expected), rtol=0.06)
    correlation = sample[0, 1] / np.sqrt(sample[0, 0] * sample[1, 1])
    assert correlation == pytest.approx(expected[0, 1] / np.sqrt(expected[0, 0] * expected[1, 1]), abs=0.04)


@pytest.fixture(scope="module")
def noisy_sensor():
    """The tiny study's LGS case, sodium from a side launch, geometric with 200 photons and 0.5 e-."""
    study = yaml.safe_load(TINY.read_text())
    config = deep_merge(
        study["base"],
        {
            "lgs": {**dict(LgsConfig.sodium().__dict__), "enabled": True, "launch_x_m": 2.6, "launch_y_m": 0.0},
            "wfs": {"model": "geometric", "photons_per_subaperture": 200.0, "read_noise_e": 0.5},
        },
    )
    case = Case.from_config(config)
    wfs = case.shack_hartmann()
    nea = case.slope_noise_covariance_rad2(wfs)
    sensor = GeometricLgsSensor(case.lgs, wfs, 2, [], _NoScreens(), seed=7, noise_covariance_rad2=nea)
    return case, wfs, nea, sensor


class _NoScreens:
    """No layers: the sensor's noise alone."""

    specs: list = []
    flat = np.zeros(1, np.float32)
    starts = np.zeros(0, np.int64)


def test_the_drawn_noise_has_the_nea_covariance_elongated_along_the_launch_baseline(noisy_sensor):
    """20,000 exposures' draws: each sub-aperture's sample variances within 5 % of the NEA's
    (sampling error ~1 %), its correlation within 0.03; the NEA's major axis along the
    sub-aperture's baseline from the launch (within 1 deg: the elongation adds to an isotropic core)."""
    case, wfs, nea, sensor = noisy_sensor
    draws = np.stack([sensor.noise() for _ in range(5000)]).transpose(0, 1, 3, 2).reshape(-1, wfs.n_valid, 2)
    sample = np.einsum("kva,kvb->vab", draws, draws) / len(draws)
    np.testing.assert_allclose(np.diagonal(sample, axis1=1, axis2=2), np.diagonal(nea, axis1=1, axis2=2), rtol=0.05)
    correlation = sample[:, 0, 1] / np.sqrt(sample[:, 0, 0] * sample[:, 1, 1])
    expected = nea[:, 0, 1] / np.sqrt(nea[:, 0, 0] * nea[:, 1, 1])
    np.testing.assert_allclose(correlation, expected, atol=0.03)
    values, vectors = np.linalg.eigh(nea)
    baseline = wfs.subaperture_xy_m - case.lgs.launch_xy_m
    baseline /= np.linalg.norm(baseline, axis=1, keepdims=True)
    elongated = values[:, 1] > 1.05 * values[:, 0]
    assert elongated.sum() > wfs.n_valid // 2
    cosine = np.abs(np.einsum("va,va->v", vectors[:, :, 1], baseline))[elongated]
    assert np.all(cosine > np.cos(np.deg2rad(1)))
    # the elongation's variance along the baseline b is b^2 var(1/H - 1/z) over the sodium profile
    distance = np.linalg.norm(wfs.subaperture_xy_m - case.lgs.launch_xy_m, axis=1)
    z_m, weights = altitude_profile(case.lgs, 4096)
    inverse = 1 / case.lgs.height_m - 1 / z_m
    spread = weights @ inverse**2 - (weights @ inverse) ** 2
    photons = 200.0 * wfs.illumination[wfs.valid]
    np.testing.assert_allclose((values[:, 1] - values[:, 0]) * photons, distance**2 * spread, rtol=1e-3)
    assert np.sqrt(spread) * 4.6 / ARCSEC_RAD == pytest.approx(0.5, abs=0.05)  # 0.5" rms at the far edge
    # the sensor's draws are seeded: the same seed, the same noise
    again = GeometricLgsSensor(case.lgs, wfs, 2, [], _NoScreens(), seed=7, noise_covariance_rad2=nea)
    first = GeometricLgsSensor(case.lgs, wfs, 2, [], _NoScreens(), seed=7, noise_covariance_rad2=nea).noise()
    np.testing.assert_array_equal(again.noise(), first)


def test_the_tomography_weighs_the_slopes_by_the_sensors_nea(noisy_sensor):
    """The dense slope covariance adds each sub-aperture's NEA block for every beacon (the uniform
    sigma^2 I when the NEA is sigma^2 I); the layer tomography's N^-1 is its block inverse."""
    case, wfs, nea, sensor = noisy_sensor
    np.testing.assert_allclose(sensor.noise_factor @ np.swapaxes(sensor.noise_factor, 1, 2), nea, rtol=1e-12)
    prior = TurbulencePrior(0.135, 20.0, (0.0, 5000.0), (0.7, 0.3))
    geometry = SlopeGeometry.from_wfs(wfs, case.lgs)
    sigma = 0.02 * ARCSEC_RAD
    uniform = slope_covariance(prior, geometry, sigma)
    isotropic = np.broadcast_to(sigma**2 * np.eye(2), nea.shape)
    np.testing.assert_array_equal(slope_covariance(prior, geometry, 0.0, noise_covariance_rad2=isotropic), uniform)
    blocks = slope_covariance(prior, geometry, 0.0, noise_covariance_rad2=nea) - (
        uniform - sigma**2 * np.eye(len(uniform))
    )
    n_b, n_v = case.lgs.n_beacons, wfs.n_valid
    expected = np.zeros((n_b, 2, n_v, n_b, 2, n_v))
    for b in range(n_b):
        for v in range(n_v):
            expected[b, :, v, b, :, v] = nea[v]
    np.testing.assert_allclose(blocks, expected.reshape(blocks.shape), atol=1e-6 * nea.max())
    slopes = np.random.default_rng(1).normal(size=(n_b, 2, n_v))
    weighed = SubapertureNoise(nea).weigh(slopes)  # N^-1 s: N times it is s again
    np.testing.assert_allclose(np.einsum("vab,kbv->kav", nea, weighed), slopes, rtol=1e-9)
    np.testing.assert_allclose(
        SubapertureNoise(isotropic).weigh(slopes), SlopeNoise.uniform(sigma).weigh(slopes), rtol=1e-12
    )


def test_the_default_model_moves_no_hash_and_a_geometric_case_has_no_calibration():
    """``wfs.model: physical`` spelled out leaves every config hash and product key of the default
    and paper studies as they are; a geometric case has no calibration product and none of the
    physical sensor's keys, and refuses another centroider and the residual budget by key."""
    for files in ((CONFIG / "config.yaml",), (CONFIG / "config.yaml", CONFIG / "paper.yaml")):
        config = read_study(*files)
        spelled = copy.deepcopy(config)
        spelled["base"]["wfs"]["model"] = "physical"
        before, after = (resolve_study(c, validate_study(c)) for c in (config, spelled))
        for name, case in before.cases.items():
            assert after.cases[name].config_sha256 == case.config_sha256, name
            keys = {kind: product.key for kind, product in case.products().items()}
            assert {kind: product.key for kind, product in after.cases[name].products().items()} == keys
    config, cases = load_study(CONFIG / "config.yaml")
    geometric = deep_merge(config, {"cases": {"ltao_geo": {"ao": {"mode": "ltao"}, "wfs": {"model": "geometric"}}}})
    view = resolve_study(geometric, validate_study(geometric))
    case = view.cases["ltao_geo"]
    assert case.calibration is None and case.reconstructor is not None
    assert not {"centroider", "calibration", "threshold", "calibration_draws"} & case.config["wfs"].keys()
    tcog = deep_merge(geometric, {"cases": {"ltao_geo": {"wfs": {"centroider": "tcog"}}}})
    with pytest.raises(ConfigError, match=r"cases.ltao_geo.wfs.centroider"):
        validate_study(tcog)
    budget = deep_merge(geometric, {"cases": {"ltao_geo": {"ao": {"residual_budget": True}}}})
    with pytest.raises(ConfigError, match=r"cases.ltao_geo.ao.residual_budget.*wfs.model physical"):
        validate_study(budget)


def test_a_noisy_geometric_ltao_case_runs_its_time_loop_with_the_nea_in_its_reconstructor():
    """The tiny LTAO case, geometric with photon noise: its reconstructor spec carries the seeing
    (the NEA's spot), its time loop measures finite, noisy slopes with the geometric sensor."""
    from luckyao.atmosphere.screens import ScreenSet, strip_screen
    from luckyao.steps.reconstructor import build_commands, build_reconstructors
    from luckyao.steps.screens import TurbulenceSpec, strip_specs
    from luckyao.steps.simulation import lgs_chain, simulate
    from luckyao.studyspec.products import calibration_spec, commands_spec, reconstructor_spec, turbulence_spec

    study = yaml.safe_load(TINY.read_text())
    config = deep_merge(
        study["base"],
        {
            "lgs": {"enabled": True},
            "ao": {"mode": "ltao"},
            "duration_s": 0.05,
            "wfs": {"model": "geometric", "photons_per_subaperture": 100.0, "read_noise_e": 0.5},
        },
    )
    specs = strip_specs(TurbulenceSpec.from_config(turbulence_spec(study, config)))
    screens = ScreenSet.from_screens(
        specs, [strip_screen(s, 20.0, np.random.default_rng([7, i])) for i, s in enumerate(specs)]
    )
    spec = reconstructor_spec(config)
    assert spec["atmosphere"]["r0_500nm_m"] == 0.135 and calibration_spec(study, config) is None
    reconstructors = build_reconstructors(spec)["reconstructor"].values
    commands = build_commands(commands_spec(config))
    case = Case.from_config(config)
    sensor, estimator = lgs_chain(case, screens, reconstructors, 7)
    assert isinstance(sensor, GeometricLgsSensor)
    telemetry = simulate(
        case,
        screens,
        lambda start, block: None,
        sensor,
        estimator,
        (commands["command_matrix"].values, commands["dm_slopes"].values),
    )
    assert np.all(np.isfinite(telemetry.lgs_rms_nm.values)) and np.all(telemetry.lgs_rms_nm.values > 0)
    noiseless = GeometricLgsSensor(case.lgs, sensor.wfs, 2, list(case.layers), screens, seed=7)
    scales = case.layer_scales([0, 1])
    noise = sensor.exposure_slopes([0, 1], scales) - noiseless.exposure_slopes([0, 1], scales)
    nea = case.slope_noise_covariance_rad2()
    assert np.std(noise) == pytest.approx(np.sqrt(np.mean(np.diagonal(nea, axis1=1, axis2=2))), rel=0.25)
