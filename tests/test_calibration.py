"""The calibrated WFS response and the centroiders, against geometric slopes and known shifts."""

import hashlib
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import yaml

from luckyao.atmosphere.screens import ScreenSet, periodic_screen_amplitude, periodic_screen_pair, strip_screen
from luckyao.optics.pupil import Telescope
from luckyao.steps import calibration as calibration_product
from luckyao.steps.reconstructor import build_commands, build_reconstructors
from luckyao.steps.screens import TurbulenceSpec, strip_specs
from luckyao.steps.simulation import lgs_chain, simulate
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import calibration_spec, commands_spec, reconstructor_spec, turbulence_spec
from luckyao.studyspec.schema import deep_merge
from luckyao.units import ARCSEC_RAD, REFERENCE_WAVELENGTH_M
from luckyao.wfs import shack_hartmann as sh
from luckyao.wfs.beacons import LgsConfig
from luckyao.wfs.calibration import BeaconSeeing, measure_response, reference_spot_spectra
from luckyao.wfs.centroiders import CentreOfGravity, Correlation, ThresholdedCentreOfGravity

TELESCOPE = Telescope(4.2, 1.2)
HEIGHTS_M = (47, 140, 281, 562, 1125, 2250, 4500, 9000, 18000)  # the study's profile
CN2 = (0.5224, 0.0260, 0.0444, 0.1160, 0.0989, 0.0295, 0.0598, 0.0430, 0.0600)
BEACONS = {
    "rayleigh": LgsConfig(22e3, 532e-9, 4, 40.0),
    "sodium": LgsConfig(90e3, 589e-9, 4, 40.0, profile="gaussian", profile_width_m=10e3),
}


@cache
def sensor(n_sub: int, beacon: str):
    lgs = BEACONS[beacon]
    wfs = sh.ShackHartmann(TELESCOPE, n_sub, lgs.wavelength_m, 4, 0.84, 0.5, lgs.launch_diameter_m)
    return wfs, sh.lgs_elongation_otf(wfs, lgs), lgs


def known_phases(wfs):
    """Phases [rad at 500 nm] (k, n, n) of a tilt and of low-order aberrations (defocus,
    astigmatism, coma), their analytic gradients [rad of slope] (k, 2, n, n), with edge
    slopes of 0.15" (the turbulence's sub-aperture slopes at r0 = 20 cm)."""
    x, y = (c / 2.1 for c in wfs.grid.xy_m)  # unit pupil radius
    theta = 0.15 * ARCSEC_RAD
    scale = theta * 2.1  # optical path [m] for a slope theta over the pupil radius
    paths = [
        (x, (np.ones_like(x), 0 * x)),
        (y, (0 * x, np.ones_like(x))),
        ((x**2 + y**2) / 2, (x, y)),
        ((x**2 - y**2) / 2, (x, -y)),
        (x * y, (y, x)),
        ((x**2 + y**2) * x / 3, ((3 * x**2 + y**2) / 3, 2 * x * y / 3)),
    ]
    phases = np.stack([scale * p for p, _ in paths]) * 2 * np.pi / REFERENCE_WAVELENGTH_M
    gradients = np.stack([np.stack(g) for _, g in paths]) * theta
    return phases, gradients


def geometric_slopes(wfs, gradients):
    """Mean gradient over each valid sub-aperture's illuminated samples (k, 2, n_valid)
    [rad]: what a slope sensor measures (Teague 1983; Primot 2003)."""
    weights = wfs._split(wfs.mask.astype(float))  # (n_valid, n_s, n_s)
    blocks = wfs._split(gradients)  # (k, 2, n_valid, n_s, n_s)
    return (blocks * weights).sum(axis=(-2, -1)) / weights.sum(axis=(-2, -1))


def responses(wfs, elongation, seeing, estimate, draws, seed):
    """Mean over turbulence draws (x 4 beacons) of ``(s(phi + P) - s(phi - P)) / 2`` per
    known phase ``P``, positions from ``estimate(images)`` (k, 2, n_valid) [rad]."""
    phases, _ = known_phases(wfs)
    rng = np.random.default_rng(seed)
    n, n_launch = wfs.grid.n_pix, wfs.launch_grid.n_pix
    amplitude = periodic_screen_amplitude(seeing.psd, 4 * n, wfs.grid.dx_m)
    total = np.zeros((len(phases), 2, wfs.n_valid))
    for _ in range(draws):
        down, up = periodic_screen_pair(amplitude, rng)
        down = np.stack([down[i : i + n, j : j + n] for i in (0, 2 * n) for j in (0, 2 * n)])
        up = np.stack([up[i : i + n_launch, j : j + n_launch] for i in (0, 2 * n) for j in (0, 2 * n)])[None]
        for k, phase in enumerate(phases):
            plus, minus = (
                estimate(sh.exposure_images(wfs, (down + sign * phase)[None], REFERENCE_WAVELENGTH_M, elongation, up))
                for sign in (1.0, -1.0)
            )
            total[k] += ((plus - minus) / 2).sum(axis=0)
    return total / (4 * draws)


@pytest.mark.parametrize("beacon", ["rayleigh", "sodium"])
@pytest.mark.parametrize("n_sub", [8, 16, 32])
@pytest.mark.parametrize("r0_m", [0.10, 0.135, 0.20])
def test_calibrated_slopes_are_the_geometric_slopes(n_sub, beacon, r0_m):
    """Under turbulence of r0 (cone-compressed layers), the calibrated slopes of a known
    tilt and of known low-order phases (0.15" at the edge) are their geometric slopes
    within 5 % (least-squares gain over every sub-aperture and axis), with turbulence
    draws independent of the calibration's, and sub-aperture by sub-aperture within the
    draws' sampling error (4-9 % rms here: 64 calibration and 16 test samples); the raw
    centres of gravity are 10-40 % low."""
    wfs, elongation, lgs = sensor(n_sub, beacon)
    seeing = BeaconSeeing(r0_m, 20.0, HEIGHTS_M, CN2, lgs.height_m)
    cog = CentreOfGravity(wfs)
    response = measure_response(wfs, elongation, seeing, cog, 4, 16, np.random.default_rng(1))
    measured = responses(wfs, elongation, seeing, lambda images: response.apply(cog.positions(images)), 4, 2)
    expected = geometric_slopes(wfs, known_phases(wfs)[1])
    for k in range(len(expected)):
        gain = (measured[k] * expected[k]).sum() / (expected[k] * expected[k]).sum()
        assert abs(gain - 1) < 0.05, f"phase {k}: calibrated gain {gain:.3f}"
        error = np.linalg.norm(measured[k] - expected[k]) / np.linalg.norm(expected[k])
        assert error < 0.12, f"phase {k}: calibrated slopes off by {error:.3f} rms"
    raw = responses(wfs, elongation, seeing, cog.positions, 1, 2)
    gain = (raw * expected).sum() / (expected * expected).sum()
    assert gain < 0.92  # what the calibration corrects


def shifted_images(wfs, spectra, shift_rad):
    f_y, f_x = wfs.harmonics
    phase = np.exp(-2j * np.pi * (f_x[None, :] * shift_rad[0] + f_y[:, None] * shift_rad[1]))
    return sh.pixel_images(wfs, spectra * phase)[None]


@pytest.mark.parametrize("beacon", ["rayleigh", "sodium"])
def test_correlation_centroider_is_unbiased_for_a_shifted_elongated_spot(beacon):
    """A copy of the (elongated) reference spot moved by a known shift, up to a third of
    a pixel: the correlation centroider returns the shift (to 1e-4 pixel); the centre of
    gravity of the same images is off by tens of percent on the edge sub-apertures."""
    wfs, elongation, lgs = sensor(16, beacon)
    seeing = BeaconSeeing(0.135, 20.0, HEIGHTS_M, CN2, lgs.height_m)
    spectra = reference_spot_spectra(wfs, elongation, seeing)
    correlation = Correlation(wfs, spectra)
    pixel = wfs.pixel_scale_rad
    for shift in ([0.3 * pixel, -0.1 * pixel], [-0.05 * pixel, 0.33 * pixel]):
        images = shifted_images(wfs, spectra, np.array(shift))
        estimate = correlation.positions(images)[0]
        np.testing.assert_allclose(
            estimate, np.broadcast_to(np.array(shift)[:, None], estimate.shape), atol=1e-4 * pixel
        )
        cog = (
            CentreOfGravity(wfs).positions(images)[0]
            - CentreOfGravity(wfs).positions(shifted_images(wfs, spectra, np.zeros(2)))[0]
        )
        assert np.abs(cog - np.array(shift)[:, None]).max() > 0.1 * np.abs(shift).max()


def test_thresholded_centre_of_gravity_ignores_a_background():
    """A spot on a uniform background: the centre of gravity is pulled towards the
    detector centre, the thresholded one (threshold above the background) is not;
    threshold 0 is the plain centre of gravity."""
    wfs, elongation, _ = sensor(8, "rayleigh")
    spot = np.zeros((1, wfs.n_valid, 4, 4), dtype=np.float32)
    spot[..., 1, 2] = 1.0  # one lit pixel at (x, y) = (0.5, -0.5) pixels
    background = spot + np.float32(0.05)
    pixel = wfs.pixel_scale_rad
    tcog = ThresholdedCentreOfGravity(wfs, 0.2).positions(background)[0]
    np.testing.assert_allclose(tcog[0], 0.5 * pixel, rtol=1e-5)
    np.testing.assert_allclose(tcog[1], -0.5 * pixel, rtol=1e-5)
    assert np.all(CentreOfGravity(wfs).positions(background)[0, 0] < 0.45 * pixel)
    np.testing.assert_array_equal(
        ThresholdedCentreOfGravity(wfs, 0.0).positions(background), CentreOfGravity(wfs).positions(background)
    )


TINY = Path(__file__).parent / "data" / "tiny.yaml"
OLD_TELEMETRY_SHA256 = "f7cab846303966da8a848346da80d00663a4a065257dcfcdd0a542e96ddc6ab8"
"""Every variable of the tiny LTAO case's telemetry (0.1 s, seed 7) without calibration, on one
thread (tests/conftest.py, as the workflow's jobs). Recorded at ``1055013``, whose telemetry on two
threads has the digest ``1f8ee428...`` that the code before the centroiders and the calibration
(d889eb8) wrote when the suite still ran on the cores' threads."""


@pytest.fixture(scope="module")
def tiny_ltao():
    study = yaml.safe_load(TINY.read_text())
    config = deep_merge(study["base"], {"lgs": {"enabled": True}, "ao": {"mode": "ltao"}, "duration_s": 0.1})
    specs = strip_specs(TurbulenceSpec.from_config(turbulence_spec(study, config)))
    screens = ScreenSet.from_screens(
        specs, [strip_screen(s, 20.0, np.random.default_rng([7, i])) for i, s in enumerate(specs)]
    )
    reconstructors = build_reconstructors(reconstructor_spec(config))["reconstructor"].values
    commands = build_commands(commands_spec(config))
    commands = commands["command_matrix"].values, commands["dm_slopes"].values

    def run(product=None, **wfs):
        case_config = deep_merge(config, {"wfs": wfs})
        case = Case.from_config(case_config)
        sensor, estimator = lgs_chain(case, screens, reconstructors, 7, product)
        return case_config, simulate(case, screens, lambda start, block: None, sensor, estimator, commands)

    return study, run


def test_uncalibrated_centre_of_gravity_reproduces_the_old_telemetry(tiny_ltao):
    _, run = tiny_ltao
    _, telemetry = run(calibration="none")
    digest = hashlib.sha256()
    for name in sorted(telemetry.data_vars):
        digest.update(name.encode())
        digest.update(np.ascontiguousarray(telemetry[name].values).tobytes())
    assert digest.hexdigest() == OLD_TELEMETRY_SHA256


def test_calibrated_open_loop_rms_is_the_raw_one_over_the_gain(tiny_ltao):
    """The reconstruction is linear in the slopes: with every sub-aperture's gain g in
    [g_min, g_max], the calibrated open-loop rms is the raw one times 1/g within them."""
    study, run = tiny_ltao
    config, raw = run(calibration="none")
    spec = calibration_spec(study, deep_merge(config, {"wfs": {"calibration": "dither", "calibration_draws": 8}}))
    product = calibration_product.build_calibration(spec)
    gains = product["response"].values[[0, 1], [0, 1]]
    _, calibrated = run(product, calibration="dither")
    ratio = calibrated.lgs_rms_nm.values / raw.lgs_rms_nm.values
    assert 0.6 < gains.min() and gains.max() < 1.0
    assert np.all(ratio > 0.95 / gains.max()) and np.all(ratio < 1.05 / gains.min())
    with pytest.raises(ValueError, match="calibration product"):
        run(None, calibration="dither")
