"""The geometric LGS wavefront sensor (``wfs.model: geometric``): mean phase gradients, and
Gaussian slope noise of the elongated spot's noise-equivalent angle (NEA).

For telescopes where the physical-optics sensor (:mod:`.shack_hartmann`) costs too much (its work
per sub-aperture grows as ~n_s^4.6 with the pupil samples a wide field needs), as MAOS does for
large systems (geometric WFS, noise from the physical spot's NEA):

* **Slopes**: each valid sub-aperture's mean gradient of the downlink optical path [rad], the
  quantity the physical sensor's calibrated slopes estimate. Exactly, the mean x gradient over a
  square of side ``d`` is its right edge's mean phase less its left edge's, over ``d``; each edge
  mean is Simpson's rule on the edge's ends and mid-point (:data:`SIMPSON_WEIGHTS`), exact for
  any phase polynomial of degree <= 4, 5 % low at the sub-aperture's Nyquist frequency (the
  trapezoid on the corners alone, Fried geometry: 100 %). The phase is sampled on a node grid of
  half-sub-aperture spacing through each beacon's cone (:class:`luckyao.optics.propagation.
  Propagator`, as the physical sensor): ~4 samples per sub-aperture instead of n_s^2 (2,704 at
  39 m with the 12" field). The whole square is used, also for a partly lit sub-aperture (the
  tomography's own slope model, :mod:`luckyao.tomography.slopes`).
* **Noise** (:func:`noise_equivalent_angle_rad2`): the centre of gravity's noise on an
  untruncated spot, ``Sigma / N + sigma_e^2 p^2 n^2 (n^2 - 1) / (12 N^2) I`` per sub-aperture:
  photon noise from the spot's second moments ``Sigma`` (its Gaussian core, the long-exposure
  spot's FWHM, and the elongation's moments along the launch-to-sub-aperture baseline, from the
  backscatter profile), read noise over the field's ``n x n`` pixels of ``p``; ``N`` the
  sub-aperture's detected photons (Rousset 1999; Thomas et al. 2006). Drawn per exposure as
  correlated Gaussian x and y slopes; the tomography weighs the slopes by the same covariance
  (:func:`luckyao.studyspec.case.slope_noise_covariance_rad2`).
* **Tip-tilt**: each beacon's mean x and y slope is removed, as for the physical sensor; the
  uplink's jitter, common to a beacon's sub-apertures, is therefore not modelled.

Limits: no spot truncation by the field (the noise of the far sub-apertures' long spots is
underestimated where they overfill it), no centroid nonlinearity or gain, no uplink broadening
beyond the long-exposure spot's, no correlation of noise between exposures.
"""

import numpy as np
import scipy.optimize
import scipy.special

from ..atmosphere.screens import ScreenSet
from ..atmosphere.statistics import Layer
from ..geometry import LineOfSight
from ..optics.propagation import Propagator
from ..optics.pupil import PupilGrid
from ..seeds import wfs_noise_rng
from ..units import REFERENCE_WAVELENGTH_M
from .beacons import FWHM_PER_SIGMA, LgsConfig, altitude_profile, elongation_offsets_rad
from .calibration import BeaconSeeing
from .centroiders import subtract_tilt
from .shack_hartmann import ShackHartmann

SIMPSON_WEIGHTS = np.array([1.0, 4.0, 1.0]) / 6.0
"""An edge's mean from its end, mid and end points (Simpson's rule)."""
PROFILE_SAMPLES = 512
"""Backscatter altitudes over which the elongation's second moments are summed."""


def node_grid(wfs: ShackHartmann) -> PupilGrid:
    """The pupil nodes ``(2 N + 1)^2`` at half the sub-aperture pitch: every sub-aperture's
    corners, edge mid-points and centre."""
    return PupilGrid(n_pix=2 * wfs.n_subapertures + 1, dx_m=wfs.subaperture_m / 2)


def node_mask(wfs: ShackHartmann) -> np.ndarray:
    """The nodes of the valid sub-apertures, bool (2N+1, 2N+1): their corners and edge mid-points,
    which the slopes read, and their centres, which keep the propagator's runs of samples long."""
    n = wfs.n_subapertures
    mask = np.zeros((2 * n + 1, 2 * n + 1), dtype=bool)
    for dy in range(3):
        for dx in range(3):
            mask[dy : dy + 2 * n : 2, dx : dx + 2 * n : 2] |= wfs.valid
    return mask


def mean_gradients(wfs: ShackHartmann, node_phase: np.ndarray) -> np.ndarray:
    """Mean x and y gradients (..., 2, n_valid) of ``node_phase`` (..., 2N+1, 2N+1) [its units
    per m] over each valid sub-aperture (row-major order): edge means by Simpson's rule."""
    phase = np.asarray(node_phase, dtype=np.float64)
    w0, w1, w2 = SIMPSON_WEIGHTS
    columns = w0 * phase[..., 0:-2:2, :] + w1 * phase[..., 1:-1:2, :] + w2 * phase[..., 2::2, :]  # (N, 2N+1)
    rows = w0 * phase[..., :, 0:-2:2] + w1 * phase[..., :, 1:-1:2] + w2 * phase[..., :, 2::2]  # (2N+1, N)
    d = wfs.subaperture_m
    g_x = (columns[..., 2::2] - columns[..., 0:-2:2]) / d  # (N, N): right edge less left
    g_y = (rows[..., 2::2, :] - rows[..., 0:-2:2, :]) / d  # (N, N): top edge less bottom
    return np.stack([g_x[..., wfs.valid], g_y[..., wfs.valid]], axis=-2)


def core_fwhm_rad(wfs: ShackHartmann, lgs: LgsConfig, seeing: BeaconSeeing) -> float:
    """FWHM [rad] of the spot's core without elongation: the long-exposure spot of the down- and
    uplink seeing (``exp(-D(lambda f))``, as :func:`.calibration.reference_spot_spectra`), the
    sub-aperture's and the launch aperture's diffraction (discs of diameter ``d`` and
    ``launch_diameter_m``), from its radial OTF by a Hankel transform."""
    wavelength = lgs.wavelength_m
    cutoff = wfs.subaperture_m / wavelength  # the sub-aperture's OTF vanishes beyond [cycles/rad]
    f = np.linspace(0.0, cutoff, 4097)

    def disc_otf(diameter_m):
        u = np.clip(f * wavelength / diameter_m, 0.0, 1.0)
        return 2 / np.pi * (np.arccos(u) - u * np.sqrt(1 - u * u))

    otf = disc_otf(wfs.subaperture_m) * disc_otf(lgs.launch_diameter_m)
    otf = otf * np.exp(-seeing.structure_function(wavelength * f, wavelength))

    def spot(theta):
        return np.trapezoid(otf * scipy.special.j0(2 * np.pi * f * theta) * f, f)

    peak = spot(0.0)
    outer = 2.0 / cutoff
    while spot(outer) > peak / 2:
        outer *= 2
    return 2 * scipy.optimize.brentq(lambda t: spot(t) - peak / 2, 0.0, outer, xtol=1e-12)


def spot_moments_rad2(wfs: ShackHartmann, lgs: LgsConfig, seeing: BeaconSeeing) -> np.ndarray:
    """Second central moments (n_valid, 2, 2) [rad^2, (x, y)] of each valid sub-aperture's spot:
    its Gaussian core's (:func:`core_fwhm_rad`) plus its elongation's, the backscatter profile's
    offsets (:func:`.beacons.elongation_offsets_rad`) along the sub-aperture's baseline to the
    launch."""
    z_m, weights = altitude_profile(lgs, PROFILE_SAMPLES)
    offsets = elongation_offsets_rad(wfs.subaperture_xy_m, lgs.launch_xy_m, lgs.height_m, z_m)  # (v, z, 2)
    offsets = offsets - np.einsum("z,vza->va", weights, offsets)[:, None, :]
    elongation = np.einsum("z,vza,vzb->vab", weights, offsets, offsets)
    core = (core_fwhm_rad(wfs, lgs, seeing) / FWHM_PER_SIGMA) ** 2
    return elongation + core * np.eye(2)


def centroid_noise_rad2(
    spot_moments_rad2: np.ndarray, photons, pixel_scale_rad: float, n_pixels: int, read_noise_e: float
) -> np.ndarray:
    """Covariance (..., 2, 2) [rad^2] of the centre of gravity of an untruncated spot of second
    central moments ``spot_moments_rad2`` (..., 2, 2) on ``n_pixels`` x ``n_pixels`` pixels of
    ``pixel_scale_rad``, ``photons`` (...) detected: photon noise ``(Sigma + p^2/12 I) / N`` (each
    photon's position known to its pixel) and read noise ``sigma_e^2 sum_pixels x^2 / N^2``, i.e.
    ``sigma_e^2 p^2 n^2 (n^2 - 1) / (12 N^2)`` per axis (Rousset 1999; Thomas et al. 2006)."""
    photons = np.asarray(photons, dtype=float)[..., None, None]
    p, n = pixel_scale_rad, n_pixels
    read = read_noise_e**2 * p * p * n * n * (n * n - 1) / 12 / photons**2
    return (np.asarray(spot_moments_rad2) + p * p / 12 * np.eye(2)) / photons + read * np.eye(2)


def noise_equivalent_angle_rad2(
    wfs: ShackHartmann, lgs: LgsConfig, seeing: BeaconSeeing, photons_per_subaperture: float, read_noise_e: float
) -> np.ndarray:
    """Slope-noise covariance (n_valid, 2, 2) [rad^2, (x, y)] of each valid sub-aperture's centre
    of gravity (:func:`centroid_noise_rad2` of its spot, :func:`spot_moments_rad2`), its photons
    a full sub-aperture's times its lit fraction."""
    photons = photons_per_subaperture * wfs.illumination[wfs.valid]
    moments = spot_moments_rad2(wfs, lgs, seeing)
    return centroid_noise_rad2(moments, photons, wfs.pixel_scale_rad, wfs.n_pixels, read_noise_e)


class GeometricLgsSensor:
    """Every beacon's geometric Shack-Hartmann of one case, sampling the shared screens: the
    interface of :class:`.sensor.LgsSensor` (``sample``, ``slopes``, ``exposure_slopes``).

    ``noise_covariance_rad2`` (n_valid, 2, 2) [rad^2] (:func:`noise_equivalent_angle_rad2`) or
    None: noiseless; the noise drawn from :func:`luckyao.seeds.wfs_noise_rng` of ``seed``.
    """

    def __init__(
        self,
        lgs: LgsConfig,
        wfs: ShackHartmann,
        exposure_steps: int,
        layers: list[Layer],
        screens: ScreenSet,
        seed: int,
        noise_covariance_rad2: np.ndarray | None = None,
    ):
        self.lgs, self.wfs, self.exposure_steps = lgs, wfs, exposure_steps
        self.rng = wfs_noise_rng(seed)
        self.noise_factor = None if noise_covariance_rad2 is None else np.linalg.cholesky(noise_covariance_rad2)
        lines = [LineOfSight(tx, ty, lgs.height_m) for tx, ty in lgs.directions_rad]
        grid = node_grid(wfs)
        self._down = Propagator(layers, screens, lines, grid, mask=node_mask(wfs))
        self._buffer = np.zeros((exposure_steps, len(lines), grid.n_pix, grid.n_pix), dtype=np.float32)
        self.n_steps_max = self._down.n_steps_max
        self.n_slopes = 2 * lgs.n_beacons * wfs.n_valid

    def sample(self, steps, layer_scales) -> None:
        """Sample the beacons' downlink phases at the nodes over one exposure: its
        ``exposure_steps`` time ``steps`` and their ``layer_scales`` (k, n_layers)."""
        if len(steps) != self.exposure_steps:
            raise ValueError(f"an exposure has {self.exposure_steps} steps, got {len(steps)}")
        self._down.sample(steps, layer_scales, out=self._buffer)

    def slopes(self) -> np.ndarray:
        """Tilt-removed slopes (n_beacons, 2, n_valid) float32 [rad] of the sampled exposure: the
        mean gradient of its mean optical path, plus the noise."""
        path_m = self._buffer.mean(axis=0, dtype=np.float64) * (REFERENCE_WAVELENGTH_M / (2 * np.pi))
        slopes = mean_gradients(self.wfs, path_m)
        if self.noise_factor is not None:
            slopes += self.noise()
        return subtract_tilt(slopes).astype(np.float32)

    def noise(self) -> np.ndarray:
        """One exposure's slope noise (n_beacons, 2, n_valid) [rad]: each sub-aperture's x and y
        drawn with its NEA covariance, ``L z`` (``L`` its Cholesky factor, ``z`` normal deviates)."""
        normal = self.rng.standard_normal((self.lgs.n_beacons, 2, self.wfs.n_valid))
        return np.einsum("vab,kbv->kav", self.noise_factor, normal)

    def exposure_slopes(self, steps, layer_scales) -> np.ndarray:
        """Tilt-removed slopes (n_beacons, 2, n_valid) [rad] of the exposure of time ``steps``."""
        self.sample(steps, layer_scales)
        return self.slopes()
