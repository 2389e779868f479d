"""Slope estimators of a Shack-Hartmann: detector images -> spot positions [rad].

The estimators are kept apart from the optics (:mod:`.shack_hartmann` forms the
images, :mod:`.detector` adds their noise): each maps images
``(n_beacons, n_valid, p, p)`` [y, x] to spot positions ``(n_beacons, 2, n_valid)``
[rad] (axis 1 = x, y), with the pixel centres as their only geometry.

* ``cog``: centre of gravity of the pixels.
* ``tcog``: thresholded centre of gravity: each image less ``threshold`` x its
  peak, clipped at 0, then the centre of gravity (Thomas et al. 2006, MNRAS 371,
  323): fewer noisy pixels far from the spot.
* ``correlation``: the shift ``delta`` of a reference spot that fits the image best,
  ``min_(a, delta) || I - a R(delta) ||^2``, i.e. the peak of the normalised
  correlation of the image with the reference (Gauss-Newton from the centre of
  gravity; its first step is the matched filter of Gilles & Ellerbroek 2006,
  Appl. Opt. 45, 6568). ``R(delta)`` is the reference spot's exact pixel image
  when moved by ``delta``: its Fourier coefficients times ``exp(-2 pi i f . delta)``,
  integrated over the pixels (:func:`.shack_hartmann.pixel_images`). Unbiased for a
  shifted copy of the reference, whatever its elongation.

:class:`SlopeEstimator` chains a centroider, an optional calibrated response
(:class:`.calibration.SlopeResponse`) and the removal of each beacon's tilt.
"""

from dataclasses import dataclass

import numba
import numpy as np

from .kernels import centroids
from .shack_hartmann import ShackHartmann, pixel_images

CENTROIDERS = ("cog", "tcog", "correlation")


def subtract_tilt(slopes: np.ndarray) -> np.ndarray:
    """``slopes`` (n_beacons, 2, n_valid) less each beacon's mean x and y (the LGS tilt is unknown), in place."""
    slopes -= slopes.mean(axis=2, keepdims=True)
    return slopes


class CentreOfGravity:
    """Centre of gravity of the pixels (0 without flux, NaN for a NaN or negative total)."""

    name = "cog"

    def __init__(self, wfs: ShackHartmann):
        self.pixel_centres_rad = wfs.pixel_centres_rad

    def positions(self, images: np.ndarray, remove_tilt: bool = False) -> np.ndarray:
        """Spot positions (n_beacons, 2, n_valid) float32 [rad]; with ``remove_tilt`` less
        each beacon's mean (in the compiled loop)."""
        images = np.asarray(images, dtype=np.float32)
        out = np.empty((images.shape[0], 2, images.shape[1]), dtype=np.float32)
        centroids(images, self.pixel_centres_rad, remove_tilt, out)
        return out


class ThresholdedCentreOfGravity(CentreOfGravity):
    """Centre of gravity of ``max(I - threshold max(I), 0)`` per image."""

    name = "tcog"

    def __init__(self, wfs: ShackHartmann, threshold: float):
        if not 0.0 <= threshold < 1.0:
            raise ValueError(f"the threshold is a fraction of the peak in [0, 1), got {threshold}")
        super().__init__(wfs)
        self.threshold = np.float32(threshold)

    def positions(self, images: np.ndarray, remove_tilt: bool = False) -> np.ndarray:
        images = np.asarray(images, dtype=np.float32)
        peak = images.max(axis=(2, 3), keepdims=True)
        return super().positions(np.clip(images - self.threshold * peak, 0.0, None), remove_tilt)


class Correlation:
    """Least-squares fit of a moved reference spot (see the module docstring).

    ``reference_spectra`` (n_valid, M, M//2+1): Fourier coefficients of each
    sub-aperture's reference spot (the layout of
    :func:`.shack_hartmann.intensity_spectra`), centred where the slope is zero.
    """

    name = "correlation"

    def __init__(self, wfs: ShackHartmann, reference_spectra: np.ndarray, iterations: int = 4):
        if reference_spectra.shape != (wfs.n_valid, wfs.fft_size, wfs.fft_size // 2 + 1):
            raise ValueError("reference spectra must be (n_valid, M, M//2+1) of this WFS")
        self.iterations = iterations
        self._cog = CentreOfGravity(wfs)
        self._reference_cog = self._cog.positions(pixel_images(wfs, reference_spectra)[None])[0]  # (2, n_valid)
        # a sub-aperture's intensity has no harmonics beyond its n_s samples: keep |q|, p < n_s
        n_s, m = wfs.samples_per_subaperture, wfs.fft_size
        q = np.arange(1 - n_s, n_s) % m
        self.reference = np.ascontiguousarray(np.asarray(reference_spectra)[:, q, :n_s], dtype=np.complex64)
        f_y, f_x = wfs.harmonics
        self._f_x, self._f_y = f_x[:n_s].astype(np.float64), f_y[q].astype(np.float64)
        e_y, e_x = wfs._pixel_integrals  # pixel integration, P = Re(E_y D E_x^T)
        self._e_y, self._e_x = e_y[:, q], e_x[:, :n_s]

    def _model(self, delta: np.ndarray):
        """The reference images moved by ``delta`` (n_b, 2, n_valid) [rad], and their
        derivatives along x and y: 3 x (n_b, n_valid, p, p)."""
        out = np.empty((3, delta.shape[0], delta.shape[2]) + (self._e_y.shape[0],) * 2)
        _moved_reference(self.reference, self._e_y, self._e_x, self._f_y, self._f_x, delta.astype(np.float64), out)
        return out[0], out[1], out[2]

    def positions(self, images: np.ndarray, remove_tilt: bool = False) -> np.ndarray:
        images = np.asarray(images, dtype=np.float32)
        flux = images.sum(axis=(2, 3))
        delta = self._cog.positions(images) - self._reference_cog  # start: the centre of gravity
        for _ in range(self.iterations):  # Gauss-Newton on (a, delta_x, delta_y)
            model, d_x, d_y = self._model(delta)
            a = (images * model).sum(axis=(2, 3)) / np.maximum((model * model).sum(axis=(2, 3)), 1e-30)
            jacobian = np.stack([model, a[..., None, None] * d_x, a[..., None, None] * d_y], axis=-1)
            jacobian = jacobian.reshape(*jacobian.shape[:2], -1, 3).astype(np.float64)
            residual = (images - a[..., None, None] * model).reshape(*images.shape[:2], -1, 1)
            normal = np.swapaxes(jacobian, -1, -2) @ jacobian
            normal += 1e-12 * np.trace(normal, axis1=-2, axis2=-1)[..., None, None] * np.eye(3)
            step = np.linalg.solve(normal, np.swapaxes(jacobian, -1, -2) @ residual)[..., 0]
            delta = delta + np.moveaxis(step[..., 1:], -1, 1)
        out = np.where(flux[:, None, :] > 0, delta, 0.0).astype(np.float32)
        return subtract_tilt(out) if remove_tilt else out


@numba.njit(cache=True, nogil=True)
def _moved_reference(reference, e_y, e_x, f_y, f_x, delta, out):  # pragma: no cover (jit)
    """out[0, b, v] = Re(E_y (R_v x a) E_x^T), a = exp(-2 pi i (f_x dx + f_y dy)) the
    shift ``delta[b, :, v]``; out[1], out[2]: its derivatives along x and y. The shift
    is separable, so it is applied to the pixel integrals' columns."""
    n_b, n_v, n_pix = delta.shape[0], delta.shape[2], e_y.shape[0]
    n_q, n_p = f_y.size, f_x.size
    rows = np.empty((n_pix, n_p), dtype=np.complex128)
    rows_dy = np.empty((n_pix, n_p), dtype=np.complex128)
    for b in range(n_b):
        for v in range(n_v):
            a_y = np.exp(-2j * np.pi * f_y * delta[b, 1, v])
            a_x = np.exp(-2j * np.pi * f_x * delta[b, 0, v])
            for j in range(n_pix):
                for p in range(n_p):
                    total = 0j
                    total_dy = 0j
                    for q in range(n_q):
                        term = e_y[j, q] * a_y[q] * reference[v, q, p]
                        total += term
                        total_dy += term * (-2j * np.pi * f_y[q])
                    rows[j, p] = total
                    rows_dy[j, p] = total_dy
            for j in range(n_pix):
                for k in range(n_pix):
                    value = 0j
                    value_dx = 0j
                    value_dy = 0j
                    for p in range(n_p):
                        column = e_x[k, p] * a_x[p]
                        value += rows[j, p] * column
                        value_dx += rows[j, p] * column * (-2j * np.pi * f_x[p])
                        value_dy += rows_dy[j, p] * column
                    out[0, b, v, j, k] = value.real
                    out[1, b, v, j, k] = value_dx.real
                    out[2, b, v, j, k] = value_dy.real


def centroids_rad(wfs: ShackHartmann, images: np.ndarray, remove_tilt: bool = False) -> np.ndarray:
    """Centre of gravity (n_beacons, 2, n_valid) [rad] of images (n_b, n_valid, p, p);
    with ``remove_tilt``, less each beacon's mean x and y."""
    return CentreOfGravity(wfs).positions(images, remove_tilt)


@dataclass(frozen=True)
class SlopeEstimator:
    """Images -> tilt-removed slopes (n_beacons, 2, n_valid) [rad]: the centroider's
    positions, in the units the tomography assumes with a calibrated ``response``
    (None: as measured), less each beacon's tilt."""

    centroider: object
    response: object = None

    def slopes(self, images: np.ndarray) -> np.ndarray:
        if self.response is None:
            return self.centroider.positions(images, remove_tilt=True)
        return subtract_tilt(self.response.apply(self.centroider.positions(images)))


def make_centroider(name: str, wfs: ShackHartmann, threshold: float = 0.0, reference_spectra: np.ndarray | None = None):
    """The centroider called ``name`` (one of :data:`CENTROIDERS`) for ``wfs``;
    ``tcog`` takes its ``threshold``, ``correlation`` its ``reference_spectra``."""
    if name == "cog":
        return CentreOfGravity(wfs)
    if name == "tcog":
        return ThresholdedCentreOfGravity(wfs, threshold)
    if name == "correlation":
        if reference_spectra is None:
            raise ValueError("the correlation centroider needs reference spectra")
        return Correlation(wfs, reference_spectra)
    raise ValueError(f"unknown centroider {name!r}; known: {CENTROIDERS}")
