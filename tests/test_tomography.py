"""MAP tomography: von Karman prior and recovery of a known layered phase."""

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.special import gamma

from luckyao.atmosphere.statistics import von_karman_structure_function
from luckyao.geometry import cone_coordinates
from luckyao.optics.pupil import Telescope, TiltRemover
from luckyao.tomography.criterion import lgs_rms_nm, lucky_frame_rms_nm
from luckyao.tomography.prior import TurbulencePrior
from luckyao.tomography.reconstructor import factorize, pupil_points, target_reconstructor
from luckyao.tomography.slopes import SlopeGeometry, slope_covariance
from luckyao.units import ARCSEC_RAD
from luckyao.wfs.beacons import LgsConfig
from luckyao.wfs.shack_hartmann import ShackHartmann

from reference import layer_reconstructor

TELESCOPE = Telescope(4.2, 1.2)
WFS = ShackHartmann(TELESCOPE, 8, 532e-9)
LGS = LgsConfig.rayleigh()
TRUE_HEIGHT_M = 4500.0
LAYER_R0_M = 0.135 * 3**0.6  # one third of the Cn2 of r0 = 13.5 cm
NOISE_RAD = 0.01 * ARCSEC_RAD


def test_structure_function_kolmogorov_limit():
    """D_vK(r) = 6.8839 (r/r0)^(5/3) [1 - 1.485 (r/L0)^(1/3) + O((r/L0)^2)] (Conan 2000)."""
    r0, outer = 0.135, 20.0
    kolmogorov = 2 * (24 / 5 * gamma(6 / 5)) ** (5 / 6)
    np.testing.assert_allclose(kolmogorov, 6.8839, rtol=1e-4)
    r = np.array([2e-4, 2e-3, 2e-2])
    ratio = von_karman_structure_function(r, r0, outer) / (kolmogorov * (r / r0) ** (5 / 3))
    np.testing.assert_allclose(ratio, 1 - 1.485 * (r / outer) ** (1 / 3), rtol=2e-4)


def von_karman_screen_m(n, dx_m, r0_m, outer_m, seed):
    """FFT phase screen [m of optical path at 500 nm r0], PSD 0.023 r0^-5/3 (f^2 + L0^-2)^-11/6."""
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(n, dx_m)
    f2 = f[:, None] ** 2 + f[None, :] ** 2
    psd = 0.023 * r0_m ** (-5 / 3) * (f2 + outer_m**-2) ** (-11 / 6)
    psd[0, 0] = 0
    noise = rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))
    screen = np.fft.ifft2(noise * np.sqrt(psd) / (n * dx_m)).real * n * n
    return screen * 500e-9 / (2 * np.pi)


SCREEN_N, SCREEN_DX = 512, 0.02
SCREEN = von_karman_screen_m(SCREEN_N, SCREEN_DX, LAYER_R0_M, 20.0, seed=3)


def screen_at(x_m, y_m):
    index = [y_m / SCREEN_DX + (SCREEN_N - 1) / 2, x_m / SCREEN_DX + (SCREEN_N - 1) / 2]
    return map_coordinates(SCREEN, index, order=3, mode="wrap")


def geometric_slopes(directions_rad):
    """Mean gradient over each cone-projected sub-aperture (edge means, 32 points
    per edge) of the screen at TRUE_HEIGHT_M, tilt removed, (n_b, 2, n_valid) [rad]."""
    d = WFS.subaperture_m
    e = ((np.arange(32) + 0.5) / 32 - 0.5) * d
    xc, yc = WFS.subaperture_xy_m[:, :1], WFS.subaperture_xy_m[:, 1:]
    out = np.zeros((len(directions_rad), 2, WFS.n_valid))
    for b, theta in enumerate(directions_rad):
        for sign in (1, -1):
            for axis, (px, py) in enumerate([(xc + sign * d / 2 + 0 * e, yc + e), (xc + e, yc + sign * d / 2 + 0 * e)]):
                x_l, y_l = cone_coordinates(px, py, TRUE_HEIGHT_M, LGS.height_m, theta)
                out[b, axis] += sign * screen_at(x_l, y_l).mean(axis=-1) / d
    return out - out.mean(axis=-1, keepdims=True)


POINTS = pupil_points(TELESCOPE, WFS.subaperture_m / 2)[2]
TRUTH = TiltRemover(POINTS[:, 0], POINTS[:, 1]).residual(screen_at(*POINTS.T).astype(np.float32))


def on_axis_error(prior, n_beacons):
    directions = LgsConfig(n_beacons=n_beacons).directions_rad
    geometry = SlopeGeometry(WFS.subaperture_xy_m, WFS.subaperture_m, directions, LGS.height_m)
    rec = target_reconstructor(prior, geometry, NOISE_RAD, POINTS)
    estimate = rec @ geometric_slopes(directions).reshape(-1).astype(np.float32)
    return np.sqrt(np.mean((estimate - TRUTH) ** 2) / np.mean(TRUTH**2))


def test_error_falls_as_beacons_are_added():
    prior = TurbulencePrior(0.135, 20.0, (0.0, TRUE_HEIGHT_M, 9000.0), (1 / 3, 1 / 3, 1 / 3))
    errors = [on_axis_error(prior, n) for n in (1, 2, 4)]
    assert errors[0] > errors[1] > errors[2]
    # 4 beacons: most of the tilt-removed variance recovered; the floor is the
    # 8x8 fitting error, ~sqrt(0.28/0.134) (d/D)^(5/6) = 0.26 (Kolmogorov)
    assert errors[2] < 0.45


def test_phase_is_recovered_at_the_right_height():
    """With single-layer priors at trial heights, the data are best explained (on
    axis, 4 beacons) by the layer at the true height, down to the fitting error."""
    errors = {}
    for height in (0.0, 2250.0, TRUE_HEIGHT_M, 9000.0):
        prior = TurbulencePrior(LAYER_R0_M, 20.0, (height,), (1.0,))
        errors[height] = on_axis_error(prior, 4)
    best = errors.pop(TRUE_HEIGHT_M)
    assert best < 0.35
    assert all(best < 0.6 * other for other in errors.values())


def test_layer_estimates_concentrate_on_the_true_layer():
    """Virtual DMs at (0, 4.5, 9) km: the 4.5 km estimate matches the screen where
    all four beacons overlap, better than the estimates at the other heights."""
    prior = TurbulencePrior(0.135, 20.0, (0.0, TRUE_HEIGHT_M, 9000.0), (1 / 3, 1 / 3, 1 / 3))
    geometry = SlopeGeometry.from_wfs(WFS, LGS)
    slopes = geometric_slopes(LGS.directions_rad).reshape(-1)
    factor = factorize(slope_covariance(prior, geometry, NOISE_RAD))
    inner = POINTS[np.hypot(*POINTS.T) < 1.2]  # central layer region seen by all beacons
    truth = screen_at(*inner.T)
    truth = truth - truth.mean()
    correlations = []
    for layer in range(3):
        estimate = layer_reconstructor(prior, geometry, layer, inner, factor) @ slopes
        estimate = estimate - estimate.mean()
        correlations.append(estimate @ truth / np.sqrt((estimate @ estimate) * (truth @ truth)))
    assert np.argmax(correlations) == 1


def test_slope_covariance_matches_monte_carlo_screens():
    """Mean squared tilt-removed slope, trace(S)/n (no noise), against slopes of
    12 independent random screens: agreement within 3 Monte-Carlo standard errors."""
    prior = TurbulencePrior(LAYER_R0_M, 20.0, (TRUE_HEIGHT_M,), (1.0,))
    geometry = SlopeGeometry(WFS.subaperture_xy_m, WFS.subaperture_m, LGS.directions_rad[:1], LGS.height_m)
    expected = np.trace(slope_covariance(prior, geometry, 0.0, n_edge=4)) / geometry.n_slopes
    global SCREEN
    samples = []
    saved = SCREEN
    try:
        for seed in range(12):
            SCREEN = von_karman_screen_m(SCREEN_N, SCREEN_DX, LAYER_R0_M, 20.0, seed=100 + seed)
            samples.append(np.mean(geometric_slopes(LGS.directions_rad[:1]) ** 2))
    finally:
        SCREEN = saved
    samples = np.array(samples)
    standard_error = samples.std(ddof=1) / np.sqrt(len(samples))
    assert abs(samples.mean() - expected) < 3 * standard_error


def test_lgs_rms_and_lucky_frame_combination():
    rec = np.array([[1.0, 0.0], [0.0, -1.0]], dtype=np.float32) * 1e-9 / 1e-6  # m/rad
    slopes = np.array([3e-6, 4e-6]).reshape(1, 2, 1)
    np.testing.assert_allclose(lgs_rms_nm(rec, slopes), np.sqrt((3**2 + 4**2) / 2) * 1e-3 * 1e3, rtol=1e-6)
    np.testing.assert_allclose(lucky_frame_rms_nm(np.array([3.0, 4.0])), np.sqrt(12.5))
