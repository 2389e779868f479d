"""Shack-Hartmann WFS against geometry and diffraction theory."""

import numpy as np
import pytest

from luckyao.optics.pupil import Telescope
from luckyao.units import ARCSEC_RAD
from luckyao.wfs import shack_hartmann as sh
from luckyao.wfs.beacons import LgsConfig
from luckyao.wfs.centroiders import centroids_rad
from luckyao.wfs.codelets import Codelet, dft, term_value
from luckyao.wfs.detector import add_noise
from luckyao.wfs.sensor import measure_slopes

from reference import reference_exposure_images

TELESCOPE = Telescope(4.2, 1.2)
WAVELENGTH_M = 532e-9


def tilt_phase(wfs, theta_x_rad, theta_y_rad):
    """Phase [rad at the WFS wavelength] of a wavefront tilt, (1, 1, n, n)."""
    x, y = wfs.grid.xy_m
    phase = 2 * np.pi * (theta_x_rad * x + theta_y_rad * y) / WAVELENGTH_M
    return phase[None, None]


def dirichlet_pixel_centroid(wfs, theta_rad):
    """Expected 1-D centroid [rad] of a fully illuminated sub-aperture under a tilt.

    Theory: n_s samples of pitch dx give the periodic intensity
    ``sin^2(pi n_s u) / sin^2(pi u)``, ``u = dx (alpha - theta) / lambda``
    (Fraunhofer pattern of a sampled slit), integrated over each pixel by
    fine mid-point quadrature, then the centre of gravity of the pixels.
    """
    n_s = wfs.samples_per_subaperture
    p = wfs.pixel_scale_rad
    n_q = 4000
    fluxes = []
    for j in range(wfs.n_pixels):
        lower = (j - wfs.n_pixels / 2) * p
        alpha = lower + (np.arange(n_q) + 0.5) / n_q * p
        u = wfs.grid.dx_m * (alpha - theta_rad) / WAVELENGTH_M
        with np.errstate(invalid="ignore", divide="ignore"):
            value = (np.sin(np.pi * n_s * u) / np.sin(np.pi * u)) ** 2
        value = np.where(np.abs(np.sin(np.pi * u)) < 1e-12, float(n_s**2), value)
        fluxes.append(value.mean())
    fluxes = np.array(fluxes)
    return float(fluxes @ wfs.pixel_centres_rad / fluxes.sum())


@pytest.mark.parametrize("n_sub", [8, 16, 32])
def test_tilt_matches_diffraction_theory_sign_and_scale(n_sub):
    wfs = sh.ShackHartmann(TELESCOPE, n_sub, WAVELENGTH_M)
    full = wfs.illumination[tuple(wfs.subaperture_index.T)] == 1.0
    assert full.sum() > 10
    for theta_x, theta_y in [(0.05, 0.0), (0.0, -0.2), (0.3, 0.12)]:
        tx, ty = theta_x * ARCSEC_RAD, theta_y * ARCSEC_RAD
        images = sh.exposure_images(wfs, tilt_phase(wfs, tx, ty), WAVELENGTH_M)
        slopes = centroids_rad(wfs, images)[0]
        for axis, theta in ((0, tx), (1, ty)):
            expected = dirichlet_pixel_centroid(wfs, theta)
            measured = slopes[axis, full]
            if theta != 0:
                assert np.all(np.sign(measured) == np.sign(theta))
            np.testing.assert_allclose(measured, expected, rtol=1e-4, atol=1e-4 * ARCSEC_RAD)


def test_resolved_spot_centroid_equals_mean_gradient():
    """With pixels of ~lambda/d the COG is the mean phase gradient (Primot 2003),
    for tilts small against lambda/d (larger ones alias in the periodic field)."""
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M, n_pixels=16, pixel_scale_arcsec=0.21)
    full = wfs.illumination[tuple(wfs.subaperture_index.T)] == 1.0
    for theta in (0.02, -0.01):
        images = sh.exposure_images(wfs, tilt_phase(wfs, theta * ARCSEC_RAD, 0.0), WAVELENGTH_M)
        slopes = centroids_rad(wfs, images)[0] / ARCSEC_RAD
        np.testing.assert_allclose(slopes[0, full], theta, rtol=0.01)
        np.testing.assert_allclose(slopes[1, full], 0.0, atol=1e-4)


@pytest.mark.parametrize("n_sub", [8, 16, 32])
def test_defocus_gives_radial_slopes_proportional_to_position(n_sub):
    """phi = a r^2 -> mean gradient 2 a (x_c, y_c) lambda / 2 pi on full sub-apertures,
    times the small-signal pixel gain of the diffraction spot (theory above)."""
    wfs = sh.ShackHartmann(TELESCOPE, n_sub, WAVELENGTH_M)
    x, y = wfs.grid.xy_m
    slope_at_edge_rad = 0.01 * ARCSEC_RAD
    a = slope_at_edge_rad * 2 * np.pi / WAVELENGTH_M / (2 * 2.1)  # rad / m^2
    phase = (a * (x**2 + y**2))[None, None]
    slopes = centroids_rad(wfs, sh.exposure_images(wfs, phase, WAVELENGTH_M))[0]
    full = wfs.illumination[tuple(wfs.subaperture_index.T)] == 1.0
    small = 1e-3 * ARCSEC_RAD
    gain = (dirichlet_pixel_centroid(wfs, small) - dirichlet_pixel_centroid(wfs, -small)) / (2 * small)
    expected = gain * 2 * a * WAVELENGTH_M / (2 * np.pi) * wfs.subaperture_xy_m[full].T
    np.testing.assert_allclose(slopes[:, full], expected, rtol=0.01, atol=1e-3 * slope_at_edge_rad)
    radial = (slopes * wfs.subaperture_xy_m.T).sum(axis=0)
    assert np.all(radial > 0)


def test_valid_subapertures_follow_illuminated_area():
    """Valid = annulus area fraction >= threshold (area from a 10x finer sampling)."""
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M, min_illumination=0.5)
    d = wfs.subaperture_m
    fine = (np.arange(160) + 0.5) / 160 * d
    fraction = np.zeros((8, 8))
    for iy in range(8):
        for ix in range(8):
            xx, yy = np.meshgrid(-2.1 + ix * d + fine, -2.1 + iy * d + fine)
            r = np.hypot(xx, yy)
            fraction[iy, ix] = np.mean((r <= 2.1) & (r >= 0.6))
    clear = np.abs(fraction - 0.5) > 0.05
    np.testing.assert_array_equal(wfs.valid[clear], fraction[clear] >= 0.5)
    np.testing.assert_allclose(wfs.illumination, fraction, atol=0.05)


def test_uplink_tilt_moves_every_spot_like_a_wavefront_tilt():
    """An uplink tilt theta moves the laser spot on the sky by +theta: every
    sub-aperture image shifts exactly as for a downlink wavefront tilt theta
    (image = downlink PSF convolved with the spot), uniformly, i.e. as a tilt."""
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M, n_pixels=16, pixel_scale_arcsec=0.21)
    theta = 0.05 * ARCSEC_RAD
    x, y = wfs.launch_grid.xy_m
    uplink = (2 * np.pi * theta * y / WAVELENGTH_M)[None, None]
    flat_up = np.zeros_like(uplink)
    flat_down = np.zeros((1, 1) + wfs.grid.xy_m[0].shape)
    reference = centroids_rad(wfs, sh.exposure_images(wfs, flat_down, WAVELENGTH_M, uplink_phase_rad=flat_up))
    moved = centroids_rad(wfs, sh.exposure_images(wfs, flat_down, WAVELENGTH_M, uplink_phase_rad=uplink))
    tilted = centroids_rad(
        wfs, sh.exposure_images(wfs, tilt_phase(wfs, 0.0, theta), WAVELENGTH_M, uplink_phase_rad=flat_up)
    )
    shift = (moved - reference)[0]
    assert np.all(shift[1] > 0.9 * theta)
    np.testing.assert_allclose(moved, tilted, rtol=1e-3, atol=1e-4 * theta)
    # a common shift on identical (fully illuminated) sub-apertures is a pure tilt
    full = wfs.illumination[tuple(wfs.subaperture_index.T)] == 1.0
    np.testing.assert_allclose(shift[1, full], shift[1, full].mean(), rtol=1e-4)
    np.testing.assert_allclose(shift[0, full], 0.0, atol=1e-4 * theta)


def test_uplink_aperture_broadens_the_spot():
    """The diffraction of the 0.35 m launch aperture widens the sub-aperture spot."""
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M, n_pixels=16, pixel_scale_arcsec=0.21)
    downlink = np.zeros((1, 1) + wfs.grid.xy_m[0].shape)
    flat = np.zeros((1, 1) + wfs.launch_grid.xy_m[0].shape)
    point = sh.exposure_images(wfs, downlink, WAVELENGTH_M)[0]
    laser = sh.exposure_images(wfs, downlink, WAVELENGTH_M, uplink_phase_rad=flat)[0]
    centre = wfs.n_pixels // 2
    core = (slice(centre - 1, centre + 1),) * 2
    assert laser[:, core[0], core[1]].sum() < 0.8 * point[:, core[0], core[1]].sum()
    np.testing.assert_allclose(laser.sum(axis=(-2, -1)), point.sum(axis=(-2, -1)), rtol=0.02)


@pytest.mark.parametrize("n_sub", [8, 32])
def test_the_wfs_reads_only_its_sensed_samples(n_sub):
    """The propagation samples only ``sensed_mask`` (pupil samples of valid
    sub-apertures): phases elsewhere must not change the exposure."""
    wfs = sh.ShackHartmann(TELESCOPE, n_sub, WAVELENGTH_M)
    assert wfs.sensed_mask.sum() < wfs.mask.sum()  # some pupil samples are in invalid sub-apertures
    phase = np.random.default_rng(4).normal(0.0, 2.0, (2, 1) + wfs.mask.shape).astype(np.float32)
    sensed = np.where(wfs.sensed_mask, phase, np.float32(0.0))
    np.testing.assert_array_equal(
        sh.exposure_images(wfs, sensed, WAVELENGTH_M), sh.exposure_images(wfs, phase, WAVELENGTH_M)
    )


def test_two_steps_average_and_noise_is_off_by_default():
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M)
    a = tilt_phase(wfs, 0.1 * ARCSEC_RAD, 0.0)[0]
    b = tilt_phase(wfs, -0.1 * ARCSEC_RAD, 0.05 * ARCSEC_RAD)[0]
    both = sh.exposure_images(wfs, np.stack([a, b]), WAVELENGTH_M)
    mean = 0.5 * (sh.exposure_images(wfs, a[None], WAVELENGTH_M) + sh.exposure_images(wfs, b[None], WAVELENGTH_M))
    np.testing.assert_allclose(both, mean, atol=1e-6)
    slopes = measure_slopes(wfs, np.stack([a, a]), WAVELENGTH_M)
    again = measure_slopes(wfs, np.stack([a, a]), WAVELENGTH_M)
    np.testing.assert_array_equal(slopes, again)


def test_centroid_noise_follows_photon_and_read_noise_theory():
    """Centre of gravity of an image with expected counts n_i = N p_i, Poisson photon
    noise and Gaussian read noise s per pixel: to first order in the noise,
    Var(x_c) = sum_i (x_i - x_c)^2 (N p_i + s^2) / N^2, N the sub-aperture's detected
    photons (fewer in partly illuminated sub-apertures). Checked per sub-aperture
    over 4000 draws (standard error of a variance: sqrt(2/4000) = 2.2 %)."""
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M)
    phase = tilt_phase(wfs, 0.1 * ARCSEC_RAD, 0.0)[0]
    images = sh.exposure_images(wfs, np.stack([phase, phase]), WAVELENGTH_M)
    photons, read_noise_e, draws = 400.0, 1.0, 4000
    rng = np.random.default_rng(1)
    x_rad = wfs.pixel_centres_rad
    centroids = np.stack(
        [centroids_rad(wfs, add_noise(images, photons, read_noise_e, rng)) for _ in range(draws)]
    )  # (draw, beacon, axis, valid)
    flux = photons * images[0].sum(axis=(-1, -2))  # (valid,) detected photons
    p = images[0] / images[0].sum(axis=(-1, -2), keepdims=True)  # (valid, y, x)
    x_c = np.einsum("vyx,x->v", p, x_rad)
    dx2 = (x_rad[None, None, :] - x_c[:, None, None]) ** 2
    expected = np.sum(dx2 * (flux[:, None, None] * p + read_noise_e**2), axis=(-1, -2)) / flux**2
    measured = centroids[:, 0, 0].var(axis=0)
    np.testing.assert_allclose(measured.mean() / expected.mean(), 1.0, atol=0.03)
    assert np.all(np.abs(measured / expected - 1) < 0.12)  # each sub-aperture: > 5 sigma


def test_elongated_spot_grows_along_the_launch_direction():
    """Range-gate elongation b dH / H^2 widens spots radially, not tangentially."""
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M, n_pixels=16, pixel_scale_arcsec=0.21)
    elongation = sh.lgs_elongation_otf(wfs, LgsConfig.rayleigh())
    downlink = np.zeros((1, 1) + wfs.grid.xy_m[0].shape)
    point = sh.exposure_images(wfs, downlink, WAVELENGTH_M)[0]
    long = sh.exposure_images(wfs, downlink, WAVELENGTH_M, elongation=elongation)[0]
    xy = wfs.subaperture_xy_m
    # outermost sub-aperture on the x axis: elongation along x
    k = np.argmax(np.where(np.abs(xy[:, 1]) < wfs.subaperture_m, xy[:, 0], -np.inf))
    c = wfs.pixel_centres_rad

    def width(image, axis):
        profile = image.sum(axis=axis)
        profile = profile / profile.sum()
        mean = profile @ c
        return profile @ (c - mean) ** 2

    extent = xy[k, 0] * 1500.0 / 22e3**2  # b dH / H^2
    grown_x = width(long[k], 0) - width(point[k], 0)
    grown_y = width(long[k], 1) - width(point[k], 1)
    # uniform line of length L adds L^2/12 to the variance (the pixels and the
    # periodic field bias this by less than 15% here)
    assert abs(grown_x / (extent**2 / 12) - 1) < 0.15
    assert abs(grown_y) < 0.05 * extent**2 / 12


@pytest.mark.parametrize("n_sub", [8, 16, 32])
def test_fused_kernel_equals_the_step_by_step_model(n_sub):
    """The compiled exposure kernel computes the same images as the documented
    step-by-step model (fields, FFT intensity, OTF products, pixel integration)."""
    telescope = Telescope(4.2, 1.2)
    wfs = sh.ShackHartmann(telescope, n_sub, 532e-9)
    config = LgsConfig.rayleigh()
    rng = np.random.default_rng(n_sub)
    n, n_l = wfs.grid.n_pix, wfs.launch_grid.n_pix
    down = rng.normal(0, 2.0, (2, 4, n, n)).astype(np.float32)
    up = rng.normal(0, 0.5, (2, 4, n_l, n_l)).astype(np.float32)
    elongation = sh.lgs_elongation_otf(wfs, config)
    fast = sh.exposure_images(wfs, down, 532e-9, elongation, up)
    reference = reference_exposure_images(wfs, down, 532e-9, elongation, up)
    np.testing.assert_allclose(fast, reference, atol=1e-6 * reference.max())


def float64_exposure_images(wfs, downlink, phase_wavelength_m, elongation, uplink):
    """The model of :func:`sh.exposure_images` in float64 numpy (Goodman ch. 4 far
    fields, OTF products, exact pixel integrals), as a precision reference."""
    m, n_s = wfs.fft_size, wfs.samples_per_subaperture
    ratio = phase_wavelength_m / wfs.wavelength_m
    intensity = sum(
        np.abs(np.fft.fft2(wfs.amplitude * np.exp(1j * ratio * wfs._split(step)), s=(m, m))) ** 2
        for step in downlink.astype(float)
    )
    spectra = np.fft.rfft2(intensity) / (m * m * n_s**2 * len(downlink))
    spot = np.abs(np.fft.fft2(wfs.launch_mask * np.exp(1j * ratio * uplink.astype(float)), s=(m, m))) ** 2
    otf = np.fft.rfft2(spot.sum(axis=0))
    spectra *= elongation * (otf / otf[:, :1, :1].real)[:, None]
    e_y, e_x = (e.astype(complex) for e in wfs._pixel_integrals)
    return np.matmul(np.matmul(e_y, spectra), e_x.T).real


@pytest.mark.parametrize("n_sub", [8, 16, 32])
def test_fused_kernel_is_at_least_as_precise_as_the_step_by_step_model(n_sub):
    """Against the model in float64, the fused float32 kernel errs less than the
    step-by-step float32 chain (and both stay at float32 rounding level)."""
    wfs = sh.ShackHartmann(TELESCOPE, n_sub, WAVELENGTH_M)
    rng = np.random.default_rng(n_sub + 1)
    n, n_l = wfs.grid.n_pix, wfs.launch_grid.n_pix
    down = rng.normal(0, 2.0, (2, 4, n, n)).astype(np.float32)
    up = rng.normal(0, 0.5, (2, 4, n_l, n_l)).astype(np.float32)
    elongation = sh.lgs_elongation_otf(wfs, LgsConfig.rayleigh())
    exact = float64_exposure_images(wfs, down, WAVELENGTH_M, elongation, up)

    def error(images):
        return np.abs(images - exact).max() / exact.max()

    fused = error(sh.exposure_images(wfs, down, WAVELENGTH_M, elongation, up))
    reference = error(reference_exposure_images(wfs, down, WAVELENGTH_M, elongation, up))
    assert fused <= reference < 1e-6


def test_writable_elongation_is_read_at_every_call():
    """The lane layout of a read-only elongation OTF is kept between calls; a
    writable one may change in place, so it is read again."""
    wfs = sh.ShackHartmann(TELESCOPE, 8, WAVELENGTH_M)
    elongation = sh.lgs_elongation_otf(wfs, LgsConfig.rayleigh())
    assert not elongation.flags.writeable
    phase = tilt_phase(wfs, 0.1 * ARCSEC_RAD, 0.0)
    long = sh.exposure_images(wfs, phase, WAVELENGTH_M, elongation)
    np.testing.assert_array_equal(sh.exposure_images(wfs, phase, WAVELENGTH_M, elongation), long)
    writable = elongation.copy()
    np.testing.assert_array_equal(sh.exposure_images(wfs, phase, WAVELENGTH_M, writable), long)
    writable[:] = 1.0
    np.testing.assert_array_equal(
        sh.exposure_images(wfs, phase, WAVELENGTH_M, writable), sh.exposure_images(wfs, phase, WAVELENGTH_M)
    )


@pytest.mark.parametrize("n_fft, n_in, n_out", [(32, 16, 32), (32, 32, 23), (16, 8, 16), (8, 3, 5)])
def test_dft_codelet_matches_numpy_fft(n_fft, n_in, n_out):
    """The generated split-radix statements (inputs beyond ``n_in`` pruned as zeros,
    only the outputs |q| < (n_out + 1) / 2 kept) compute the DFT."""
    codelet = Codelet()
    inputs = [(codelet.input(f"xr{i}"), codelet.input(f"xi{i}")) if i < n_in else (None, None) for i in range(n_fft)]
    half = (n_out + 1) // 2
    wanted = [dft(codelet, inputs)[q % n_fft] for q in range(1 - half, half)]
    x = np.random.default_rng(n_fft).normal(size=(2, n_in))
    namespace = {
        "np": np,
        **{f"xr{i}": x[0, i] for i in range(n_in)},
        **{f"xi{i}": x[1, i] for i in range(n_in)},
        **codelet.constants,
    }
    exec("\n".join(codelet.source([t for v in wanted for t in v], "")), namespace)  # noqa: S102
    got = [eval(term_value(re), namespace) + 1j * eval(term_value(im), namespace) for re, im in wanted]
    expected = np.fft.fft(x[0] + 1j * x[1], n_fft)[np.arange(1 - half, half) % n_fft]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6 * np.abs(expected).max())
