"""Image metrics against theory: Airy pattern with central obscuration, Gaussians, Marechal."""

import numpy as np
import pytest
from scipy import integrate, optimize, special

from luckyao.lucky import radial_sums
from luckyao.lucky.metrics import (
    EncircledEnergy,
    centroid_px,
    fwhm_arcsec,
    interpolant_patch,
    strehl,
)
from luckyao.optics.imaging import Camera, Imager
from luckyao.optics.pupil import Telescope, TiltRemover
from luckyao.units import ARCSEC_RAD

from reference import d50_arcsec

D_M, OBSCURATION_M = 4.2, 1.2
EPS = OBSCURATION_M / D_M


def annular_amplitude(x, eps=EPS):
    """Obscured Airy amplitude 2J1(x)/x - eps^2 2J1(eps x)/(eps x), x = pi D theta / lambda."""
    central = 2 * special.j1(eps * x) / (eps * x) if eps > 0 else 1.0
    return 2 * special.j1(x) / x - eps**2 * central


def airy_half_maximum_x(eps=EPS):
    """x at which the intensity falls to half its axial value (1 - eps^2)^2."""
    return optimize.brentq(lambda x: (annular_amplitude(x, eps) / (1 - eps**2)) ** 2 - 0.5, 0.5, 2.5)


def airy_ee(x, eps=EPS):
    """Encircled energy fraction within x: radial integral over the total 2 (1 - eps^2)."""
    return integrate.quad(lambda t: annular_amplitude(t, eps) ** 2 * t, 0, x, limit=200)[0] / (2 * (1 - eps**2))


def airy_ee_mahajan(x, eps=EPS):
    """Closed form of the annular encircled energy (Mahajan, JOSA A 3, 470, 1986, eq. 13)."""
    tail = integrate.quad(lambda t: special.j1(t) * special.j1(eps * t) / t, 0, x, limit=200)[0]
    return (
        1
        - special.j0(x) ** 2
        - special.j1(x) ** 2
        + eps**2 * (1 - special.j0(eps * x) ** 2 - special.j1(eps * x) ** 2)
        - 4 * eps * tail
    ) / (1 - eps**2)


def airy_d50_x(eps=EPS):
    return optimize.brentq(lambda x: airy_ee(x, eps) - 0.5, 0.5, 5.0)


def test_airy_references_match_textbook_values():
    """The references the metrics are held to, checked against published numbers:
    unobscured Airy FWHM 1.029 lambda/D and 83.8 % of the energy inside the first
    dark ring at x = 3.8317 (Born & Wolf, Principles of Optics, 8.5.2); with the
    obscuration, the radial integral agrees with Mahajan's closed form, the core
    narrows (FWHM below 1.029 lambda/D) and energy moves to the rings (d50 grows)."""
    assert 2 * airy_half_maximum_x(0.0) / np.pi == pytest.approx(1.029, abs=5e-4)
    assert airy_ee(3.8317, 0.0) == pytest.approx(0.838, abs=5e-4)
    for x in (1.0, airy_d50_x(), 4.0):
        assert airy_ee(x) == pytest.approx(airy_ee_mahajan(x), abs=1e-7)
    assert airy_half_maximum_x() < airy_half_maximum_x(0.0)
    assert airy_d50_x() > airy_d50_x(0.0)


# Two samplings of the 800 nm image, both band-limited (Imager oversampling 1):
# 5/256"/pixel (just finer than lambda/2D) and 5/512"/pixel (twice finer).
CAMERAS = [Camera(800e-9, 256, 5 / 256), Camera(800e-9, 256, 5 / 512)]


@pytest.fixture(scope="module", params=CAMERAS, ids=["nyquist", "nyquist_x2"])
def imager(request):
    imager = Imager(Telescope(D_M, OBSCURATION_M), request.param)
    assert imager.oversampling == 1
    return imager


def lambda_over_d_arcsec(camera):
    return camera.wavelength_m / D_M / ARCSEC_RAD


def test_diffraction_limited_strehl_is_one(imager):
    image = imager.diffraction_limited
    assert strehl(image, imager.diffraction_limited_peak) == pytest.approx(1.0, abs=1e-6)
    # equal flux: the photon number does not change the Strehl ratio
    assert strehl(1000.0 * image, imager.diffraction_limited_peak) == pytest.approx(1.0, abs=1e-6)


# Tolerance 0.5%: the image is that of the pupil sampled by Imager (128 or 64 samples
# across 4.2 m, sample centres inside the annulus); its area differs from the annulus
# by ~0.1-0.2%, so the width of its core differs from the continuous theory by about
# that much. The metrics themselves are exact for band-limited images (errors < 1e-4);
# treating pixels as points would be off by several per cent at 2-4 pixels per d50.
TOLERANCE = 0.005


def test_diffraction_limited_fwhm_matches_obscured_airy(imager):
    theory_arcsec = 2 * airy_half_maximum_x() / np.pi * lambda_over_d_arcsec(imager.camera)
    measured = fwhm_arcsec(imager.diffraction_limited, imager.camera.pixel_scale_arcsec)
    assert measured == pytest.approx(theory_arcsec, rel=TOLERANCE)


def test_diffraction_limited_d50_matches_obscured_airy(imager):
    theory_arcsec = 2 * airy_d50_x() / np.pi * lambda_over_d_arcsec(imager.camera)
    # the d50 spans only 2.4 (nyquist) or 4.7 (nyquist_x2) pixels
    measured = d50_arcsec(imager.diffraction_limited, imager.camera.pixel_scale_arcsec)
    assert measured == pytest.approx(theory_arcsec, rel=TOLERANCE)


def test_strehl_of_small_defocus_follows_marechal():
    """S = |<exp(i phi)>|^2 ~ exp(-sigma^2) for sigma = 0.2 rad rms (error O(sigma^4) < 2e-3)."""
    imager = Imager(Telescope(D_M, OBSCURATION_M), CAMERAS[0])
    x, y = imager.grid.xy_m
    r2 = (x**2 + y**2)[imager.mask]
    focus = r2 - r2.mean()
    sigma_rad = 0.2
    phase = sigma_rad * focus / np.sqrt(np.mean(focus**2))
    image = imager.image(phase[None, :].astype(np.float32))[0]
    assert strehl(image, imager.diffraction_limited_peak) == pytest.approx(np.exp(-(sigma_rad**2)), abs=3e-3)


def gaussian_images(n, centres_yx, sigma_px):
    """Circular Gaussians (k, n, n) of unit flux at centres (k, 2) [pixel]."""
    idx = np.arange(n)
    c = np.asarray(centres_yx, dtype=float)
    gy = np.exp(-((idx[None, :] - c[:, :1]) ** 2) / (2 * sigma_px**2))
    gx = np.exp(-((idx[None, :] - c[:, 1:]) ** 2) / (2 * sigma_px**2))
    images = gy[:, :, None] * gx[:, None, :]
    return (images / images.sum(axis=(-2, -1), keepdims=True)).astype(np.float32)


def test_centroid_of_gaussians_is_their_centre():
    """A sampled Gaussian of sigma 2 px has its centre of gravity at its centre (Poisson sum)."""
    centres = np.array([[32.0, 32.0], [20.3, 40.75], [40.5, 25.1], [31.9, 30.2], [33, 29.6], [25.25, 35.5]])
    images = gaussian_images(64, centres, 2.0).reshape(2, 3, 64, 64)
    assert centroid_px(images).shape == (2, 3, 2)
    np.testing.assert_allclose(centroid_px(images).reshape(-1, 2), centres, atol=1e-4)


def test_gaussian_d50_and_fwhm():
    """Circular Gaussian: EE = 1 - exp(-r^2 / 2 sigma^2), so d50 = FWHM = 2 sigma sqrt(2 ln 2).

    Sub-pixel centres check that the disc is centred on the centre of gravity.
    sigma = 1.2 px: the Gaussian's spectrum at 1/2 cycle per pixel is exp(-7), so the
    band-limited treatment is accurate to ~1e-3 (tolerance 0.3%).
    """
    sigma_px = 1.2
    centres = np.array([[32.0, 32.0], [30.37, 33.81], [34.5, 29.5]])
    images = gaussian_images(64, centres, sigma_px)
    theory_px = 2 * sigma_px * np.sqrt(2 * np.log(2))
    np.testing.assert_allclose(d50_arcsec(images, 1.0), theory_px, rtol=3e-3)
    np.testing.assert_allclose(fwhm_arcsec(images, 1.0), theory_px, rtol=3e-3)


def test_encircled_energy_of_uniform_image_is_disc_area():
    """A constant image has energy (flux / n^2) pi R^2 within R (exact, f = 0 term only)."""
    n = 32
    ee = EncircledEnergy(n)
    fractions = ee.fractions(np.ones((2, n, n), dtype=np.float32))
    np.testing.assert_allclose(
        fractions, np.broadcast_to(np.pi * ee.radii_px**2 / n**2, fractions.shape), rtol=1e-5, atol=1e-7
    )
    assert np.allclose(ee.radius_px(np.ones((n, n))), np.sqrt(0.5 * n**2 / np.pi), rtol=1e-6)


def test_metrics_do_not_mutate_and_zero_flux_is_nan():
    images = gaussian_images(32, [[16, 16], [15.2, 17.7]], 1.5)
    before = images.copy()
    centroid_px(images), strehl(images, 0.1), d50_arcsec(images, 0.02), fwhm_arcsec(images, 0.02)
    np.testing.assert_array_equal(images, before)
    zero = np.zeros((1, 32, 32), dtype=np.float32)
    assert np.isnan(strehl(zero, 0.1)).all() and np.isnan(d50_arcsec(zero, 0.02)).all()


def test_tilt_removed_rms_is_the_rms_of_the_least_squares_residual():
    """Piston and tilt add nothing; a defocus keeps the rms of its part orthogonal
    to [1, x, y] on the annulus (an annulus is symmetric, so that part is the
    defocus minus its mean)."""
    telescope = Telescope(4.2, 1.2)
    grid = telescope.grid_for(0.033)
    mask = telescope.mask(grid)
    x, y = (c[mask] for c in grid.xy_m)
    remover = TiltRemover.for_mask(grid, mask)
    r2 = x**2 + y**2
    defocus = 3.0 * r2
    for tilt in (0.0, 40.0):  # rad per m: +-84 rad of tilt over the pupil
        phase = (17.0 + tilt * x - 0.5 * tilt * y + defocus).astype(np.float32)
        expected = 3.0 * np.std(r2)
        assert remover.rms(phase[None])[0] == pytest.approx(expected, rel=1e-5)
    assert remover.rms((5.0 - 7.0 * x + 3.0 * y).astype(np.float32)) == pytest.approx(0.0, abs=1e-3)


def test_binned_encircled_energy_is_the_same_sum():
    """fractions_binned groups the terms of equal |f| (one kernel value each, float64): the
    same sum as fractions (float32 matrix product) to float32 rounding, on Gaussians and on
    noisy images; its d50 meets the Gaussian's theory (as test_gaussian_d50_and_fwhm)."""
    ee = EncircledEnergy(64)
    centres = np.array([[32.0, 32.0], [30.37, 33.81], [34.5, 29.5]])
    images = gaussian_images(64, centres, 1.2)
    noisy = (
        np.random.default_rng(4).poisson(500 * images) + np.random.default_rng(5).normal(0, 1, images.shape)
    ).astype(np.float32)
    for frames in (images, noisy):
        c = centroid_px(frames)
        np.testing.assert_allclose(ee.fractions_binned(frames, c), ee.fractions(frames, c), atol=2e-5)
    theory_px = 2 * 1.2 * np.sqrt(2 * np.log(2))
    np.testing.assert_allclose(2 * ee.radius_px_binned(images, centroid_px(images)), theory_px, rtol=3e-3)
    np.testing.assert_allclose(ee.radius_px_binned(images, centroid_px(images)), ee.radius_px(images), rtol=1e-5)


def test_radial_sums_about_several_centres_give_each_centres_encircled_energy():
    """radial_sums_about reads each image's spectrum once for several centres, its phases by
    recurrence: the energies of its sums (energies_of) are those energies_binned gives about each
    centre (to 1e-12 of the largest), whose fractions are fractions' (float32 rounding); the radial
    sums of a sum of images are the sum of theirs."""
    ee = EncircledEnergy(64)
    rng = np.random.default_rng(6)
    images = gaussian_images(64, np.array([[32.0, 32.0], [30.37, 33.81], [34.5, 29.5]]), 1.7)
    centres = rng.uniform(24, 40, (3, 5, 2))  # 5 centres per image
    about = ee.energies_of(ee.radial_sums_about(images, centres))
    for m in range(5):
        one = ee.energies_binned(images, centres[:, m])
        np.testing.assert_allclose(about[:, m], one, rtol=0, atol=1e-12 * np.abs(one).max())
        np.testing.assert_allclose(
            ee.fractions_of(one, images.sum(axis=(1, 2), dtype=np.float64)),
            ee.fractions(images, centres[:, m]),
            atol=2e-5,
        )
    same_centre = np.repeat(centres[:1, :1], 3, axis=0)
    summed = ee.radial_sums_about(images.sum(axis=0, keepdims=True), same_centre[:1])
    each = ee.radial_sums_about(images, same_centre)[:, 0].sum(axis=0)
    np.testing.assert_allclose(summed[0, 0], each, rtol=0, atol=1e-6 * np.abs(each).max())  # float32 FFTs
    np.testing.assert_array_equal(
        ee.radial_sums_about(images, centres, which=[2]), ee.radial_sums_about(images, centres)[2:]
    )


def test_radial_sums_of_a_centre_are_the_same_alone_or_among_others():
    """The kernel vectorises over a row's frequencies for a few centres and over the centres for
    many (radial_sums.RADIAL_CENTRES_INNER): the same operations on each term, so a centre's sums are
    bit for bit the same alone, among a few or among many."""
    ee = EncircledEnergy(64)
    image = (
        np.random.default_rng(7).poisson(300 * gaussian_images(64, np.array([[31.2, 32.6]]), 1.5)).astype(np.float32)
    )
    centres = np.random.default_rng(8).uniform(26, 38, (1, 2 * radial_sums.RADIAL_CENTRES_INNER + 3, 2))
    many = ee.radial_sums_about(image, centres)[0]
    for m in (1, 3, radial_sums.RADIAL_CENTRES_INNER - 1, radial_sums.RADIAL_CENTRES_INNER):
        np.testing.assert_array_equal(ee.radial_sums_about(image, centres[:, :m])[0], many[:m])


@pytest.mark.parametrize("shape, up", [((32, 32), 4), ((33, 31), 3), ((16, 21), 5), ((64, 48), 16), ((7, 8), 2)])
def test_interpolant_patch_is_the_matrix_fourier_transform(shape, up):
    """The Dirichlet-kernel form of the trigonometric interpolant (two real products, the
    Nyquist terms' rank-one part apart) equals the matrix Fourier transform of the DFT
    (numpy's frequencies, -n/2 kept for even n) to rounding, on and off whole pixels,
    outside the frame too (periodic)."""
    ny, nx = shape
    image = np.random.default_rng(1).standard_normal(shape) + 3.0
    jy = np.arange(-2 * up, (ny + 3) * up)
    jx = np.arange(-up - 1, (nx + 2) * up)
    ky, kx = np.fft.fftfreq(ny) * ny, np.fft.fftfreq(nx) * nx
    ey = np.exp(2j * np.pi * np.outer(jy / up, ky) / ny)
    ex = np.exp(2j * np.pi * np.outer(kx, jx / up) / nx)
    expected = (ey @ (np.fft.fft2(image) / image.size) @ ex).real
    patch = interpolant_patch(image, jy, jx, up)
    np.testing.assert_allclose(patch, expected, rtol=0, atol=1e-13 * np.abs(expected).max())
    whole = patch[2 * up :: up, up + 1 :: up][:ny, :nx]  # (y, x) = whole pixels 0.., 0..
    np.testing.assert_allclose(whole, image, rtol=0, atol=1e-13 * np.abs(image).max())


def test_fwhm_of_batches_is_per_image():
    """fwhm_arcsec of a stack is that of each image alone (no state carried between images)."""
    images = gaussian_images(64, [[32.0, 32.0], [30.37, 33.81], [34.5, 29.5]], 1.7).reshape(3, 1, 64, 64)
    together = fwhm_arcsec(images, 0.5)
    assert together.shape == (3, 1)
    np.testing.assert_array_equal(together[:, 0], [fwhm_arcsec(image[0], 0.5) for image in images])


def test_component_and_dilation_kernels_match_scipy():
    """The compiled connected component (4-connected, as scipy.ndimage.label's default) and
    3 x 3 dilation used by fwhm_arcsec give scipy.ndimage's masks."""
    from scipy import ndimage

    from luckyao.lucky.image_helpers import component, dilate

    rng = np.random.default_rng(3)
    for _ in range(20):
        values = ndimage.uniform_filter(rng.random((40, 37)), 3)
        seed = np.unravel_index(np.argmax(values), values.shape)
        threshold = np.quantile(values, 0.6)
        labels, _ = ndimage.label(values >= threshold)
        expected = labels == labels[seed]
        inside, near = np.empty(values.shape, bool), np.empty(values.shape, bool)
        count, r0, r1, c0, c1 = component(values, threshold, *seed, inside)
        rows, cols = np.nonzero(expected)
        np.testing.assert_array_equal(inside, expected)
        assert (count, r0, r1, c0, c1) == (expected.sum(), rows.min(), rows.max(), cols.min(), cols.max())
        dilate(inside, near)
        np.testing.assert_array_equal(near, ndimage.binary_dilation(expected, structure=np.ones((3, 3), bool)))


@pytest.mark.parametrize("diameter_m", [2.5, 8.2, 10.4])
def test_airy_metrics_at_the_sampling_derived_for_each_diameter(diameter_m):
    """The lucky camera and pupil the study derives for each telescope size (studyspec/scaling.py:
    obscuration 2/7 D, about 2 pixels per lambda/D at 800 nm over 5", pupil samples of
    lambda / 5" = 3.3 cm, 76 to 316 across): unit Strehl, and the FWHM and d50 of the
    obscured Airy pattern (eps = obscuration / D) to the 0.5 % of the pupil's sampled area."""
    from luckyao.studyspec.scaling import camera_pixels

    obscuration_m = round(2 / 7 * diameter_m, 3)
    n_pixels = camera_pixels(diameter_m, 800e-9, 5.0, 2.0)
    imager = Imager(Telescope(diameter_m, obscuration_m), Camera(800e-9, n_pixels, 5.0 / n_pixels))
    assert imager.oversampling == 1
    eps = obscuration_m / diameter_m
    lambda_over_d = 800e-9 / diameter_m / ARCSEC_RAD
    image = imager.diffraction_limited
    assert strehl(image, imager.diffraction_limited_peak) == pytest.approx(1.0, abs=1e-6)
    assert fwhm_arcsec(image, imager.camera.pixel_scale_arcsec) == pytest.approx(
        2 * airy_half_maximum_x(eps) / np.pi * lambda_over_d, rel=TOLERANCE
    )
    assert d50_arcsec(image, imager.camera.pixel_scale_arcsec) == pytest.approx(
        2 * airy_d50_x(eps) / np.pi * lambda_over_d, rel=TOLERANCE
    )
