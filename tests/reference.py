"""Plain reference implementations the tests check the package against (the package does not use them).

Detector noise drawn from a numpy ``Generator`` (the keyed sampler's reference), the
keyed sampler on a whole cube, shift-and-add with ``np.roll``, the d50 of images, a
layer's virtual-DM reconstructor, the LGS elongation length and the Shack-Hartmann
exposure chained from its public steps.
"""

import numpy as np

import luckyao.wfs.shack_hartmann as sh
from luckyao.lucky.accumulation import recentring_shifts_px
from luckyao.lucky.detector import Detector, KeyedNoise
from luckyao.lucky.metrics import EncircledEnergy, centroid_px, d50_from_radius
from luckyao.tomography.prior import TurbulencePrior
from luckyao.tomography.reconstructor import apply_inverse
from luckyao.tomography.slopes import SlopeGeometry, cross_covariance


def apply_detector(frames_unit_flux: np.ndarray, detector: Detector, rng: np.random.Generator) -> np.ndarray:
    """Detected frames [electron] (float32, same shape) from unit-flux frames (..., n, n).

    Each pixel: ``Poisson(N * I) + sigma * Normal(0, 1)``, ``N`` =
    ``detector.photons_per_frame``, ``sigma`` = ``detector.read_noise_e``; so the mean
    is ``N I`` and the variance ``N I + sigma^2``. Negative unit-flux values (rounding)
    are clipped to 0. A noiseless detector returns a float32 copy of the unit-flux
    frames (not scaled) and draws nothing from ``rng``. The input is never modified. The reference of
    :class:`luckyao.lucky.detector.KeyedNoise`.

    Independent Poisson pixels are drawn in one of two equivalent ways (a Poisson
    process: the total ``K ~ Poisson(N sum I)`` and, given ``K``, photons
    independently in pixel ``p`` with probability ``I_p / sum I``, e.g. Feller vol. 1,
    sec. VI.6): per photon (inverse-CDF sampling, then counting) when a frame holds fewer
    than ``n_pixels / 16`` photons (faster there: ~0.2 us per photon against ~0.05 us
    per pixel); per pixel otherwise.
    """
    frames = np.asarray(frames_unit_flux)
    if detector.noiseless:
        return np.array(frames, dtype=np.float32, copy=True)
    if frames.min() < 0:
        frames = np.maximum(frames, 0)
    if detector.photons_per_frame < frames.shape[-1] * frames.shape[-2] / 16:
        electrons = _poisson_by_photons(frames, detector.photons_per_frame, rng)
    else:
        electrons = rng.poisson(frames.astype(np.float64) * detector.photons_per_frame)
        electrons = electrons.astype(np.float32)
    if detector.read_noise_e > 0:
        electrons += np.float32(detector.read_noise_e) * rng.standard_normal(electrons.shape, dtype=np.float32)
    return electrons


def _poisson_by_photons(frames: np.ndarray, photons: float, rng: np.random.Generator) -> np.ndarray:
    """Independent Poisson counts (float32) of means ``photons * frames`` (..., n, n), frames >= 0.

    Per frame ``j``: ``K_j ~ Poisson(photons * sum frames_j)`` photons, each placed at the
    pixel whose interval of the normalised cumulative sum (float64) holds a uniform
    deviate; the CDFs of all frames are laid end to end (frame ``j`` on ``[j, j + 1]``)
    so one sorted search serves the whole batch.
    """
    shape = frames.shape
    flat = frames.reshape(-1, shape[-2] * shape[-1])
    k, m = flat.shape
    cdf = np.cumsum(flat, axis=1, dtype=np.float64)
    totals = cdf[:, -1].copy()
    n_photons = rng.poisson(photons * totals)
    with np.errstate(invalid="ignore", divide="ignore"):
        cdf /= totals[:, None]
    cdf[:, -1] = 1.0  # exact end of each frame's interval
    cdf += np.arange(k)[:, None]
    frame_of_photon = np.repeat(np.arange(k), n_photons)
    position = frame_of_photon + rng.random(frame_of_photon.size)
    position = np.minimum(position, np.nextafter(frame_of_photon + 1.0, 0.0))
    pixel = np.searchsorted(cdf.ravel(), position, side="right")
    counts = np.bincount(pixel, minlength=k * m)
    return counts.astype(np.float32).reshape(shape)


def detect(frames_unit_flux: np.ndarray, detector: Detector, seed: int, first_frame: int = 0) -> np.ndarray:
    """Detected frames (float32) of frames ``first_frame..`` (k, n, n) with the keyed
    streams of :class:`KeyedNoise` (a float32 copy for a noiseless detector)."""
    frames = np.asarray(frames_unit_flux)
    if detector.noiseless:
        return np.array(frames, dtype=np.float32, copy=True)
    return KeyedNoise(frames.shape[-1], len(frames)).prepare(frames).detect(detector, seed, first_frame)[0]


def shift_frames(frames: np.ndarray, shifts_px: np.ndarray) -> np.ndarray:
    """Frames (k, n, n) each rolled by its integer shift (k, 2) (y, x), new array.

    Circular shift with ``np.roll`` semantics, ``out[y, x] = in[(y - s_y) mod n,
    (x - s_x) mod n]``: consistent with the simulated field, which is periodic over
    the frame (a frame is the power spectrum of a sampled pupil). Four block copies a frame.
    """
    frames = np.asarray(frames)
    k, ny, nx = frames.shape
    shifts_px = np.asarray(shifts_px, dtype=np.int64).reshape(k, 2)
    out = np.empty_like(frames)
    for frame, moved, (sy, sx) in zip(frames, out, shifts_px % (ny, nx)):
        moved[sy:, sx:], moved[sy:, :sx] = frame[: ny - sy, : nx - sx], frame[: ny - sy, nx - sx :]
        moved[:sy, sx:], moved[:sy, :sx] = frame[ny - sy :, : nx - sx], frame[ny - sy :, nx - sx :]
    return out


def shift_and_add(frames: np.ndarray) -> np.ndarray:
    """Sum (n, n) float64 of frames (k, n, n) recentred on their centre of gravity.

    Each frame is rolled by :func:`recentring_shifts_px` of its own
    :func:`luckyao.lucky.metrics.centroid_px` (:func:`shift_frames`), then all are added.
    """
    frames = np.asarray(frames)
    shifts = recentring_shifts_px(centroid_px(frames), frames.shape[-1])
    return shift_frames(frames, shifts).sum(axis=0, dtype=np.float64)


def d50_arcsec(
    images: np.ndarray, pixel_scale_arcsec: float, encircled_energy: EncircledEnergy | None = None
) -> np.ndarray:
    """Diameter [arcsec] of the circle, centred on the centre of gravity, holding half the flux.

    ``images`` (..., n, n); returns shape (...). Exact for band-limited periodic
    images (see :class:`EncircledEnergy`, whose instance can be passed to reuse its
    kernel); ``2 R_50 * pixel_scale_arcsec`` with ``EE(R_50) = F / 2``.
    """
    images = np.asarray(images)
    ee = encircled_energy if encircled_energy is not None else EncircledEnergy(images.shape[-1])
    return d50_from_radius(ee.radius_px(images), pixel_scale_arcsec)


def layer_reconstructor(
    prior: TurbulencePrior,
    geometry: SlopeGeometry,
    layer_index: int,
    points_xy_m: np.ndarray,
    cholesky_lower: np.ndarray,
    n_edge: int = 2,
) -> np.ndarray:
    """Virtual-DM estimate (n_points, n_slopes) [m / rad] of layer ``layer_index``
    at layer coordinates ``points_xy_m`` [m]."""
    cross = cross_covariance(
        prior, geometry, points_xy_m, (0.0, 0.0), source_height_m=0.0, layer_indices=[layer_index], n_edge=n_edge
    )
    return apply_inverse(cholesky_lower, cross)


def elongation_length_rad(baseline_m, depth_m: float, beacon_height_m: float):
    """Small-angle elongation ``b dH / H^2`` [rad] (range gate of depth ``dH``)."""
    return np.asarray(baseline_m, dtype=float) * depth_m / beacon_height_m**2


def reference_exposure_images(
    wfs: sh.ShackHartmann,
    downlink_phase_rad: np.ndarray,
    phase_wavelength_m: float,
    elongation: np.ndarray | None = None,
    uplink_phase_rad: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`luckyao.wfs.shack_hartmann.exposure_images` by the step-by-step public functions (slow, for tests)."""
    downlink = np.asarray(downlink_phase_rad)
    if downlink.ndim != 4:
        raise ValueError("downlink phase must be (T, n_beacons, n, n)")
    n_steps = downlink.shape[0]
    intensity = sh.intensity_samples(wfs, downlink[0], phase_wavelength_m)
    for step in range(1, n_steps):  # T = 2 steps per exposure
        sh.intensity_samples(wfs, downlink[step], phase_wavelength_m, out=intensity)
    spectra = sh.intensity_spectra(wfs, intensity)
    spectra *= np.float32(1.0 / n_steps)
    if elongation is not None:
        spectra *= elongation
    if uplink_phase_rad is not None:
        uplink = sh.uplink_otf(wfs, uplink_phase_rad, phase_wavelength_m).mean(axis=0)
        spectra *= uplink[:, None]
    return sh.pixel_images(wfs, spectra)
