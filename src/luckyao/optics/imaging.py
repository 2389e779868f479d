"""Science camera: Fraunhofer imaging of the pupil field onto detector pixels.

The image of a pupil field ``E = A exp(i phi)`` is ``|FFT(E)|^2`` (Goodman,
*Introduction to Fourier Optics*, ch. 4) on a grid of ``M = q * n_pixels``
samples; the pupil spacing ``dx = lambda / (n_pixels * pixel_scale)`` makes each
FFT sample ``1/q`` of a detector pixel, and ``q`` (>= 1) is the smallest odd
oversampling for which the intensity is not aliased (``M >= 2 N_pupil``).

Image conventions: the optical axis falls on pixel ``(n/2, n/2)`` (the
``fftshift`` centre), ``x`` runs along the last axis, and a wavefront tilt
``phi = 2 pi theta_x x / lambda`` moves the image by ``+theta_x``.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..units import ARCSEC_RAD
from .farfield import FarField
from .pupil import PupilGrid, Telescope


@dataclass(frozen=True)
class Camera:
    """Lucky camera: ``n_pixels`` square pixels of ``pixel_scale_arcsec`` at ``wavelength_m``."""

    wavelength_m: float
    n_pixels: int
    pixel_scale_arcsec: float

    @property
    def pixel_scale_rad(self) -> float:
        return self.pixel_scale_arcsec * ARCSEC_RAD


@dataclass(frozen=True, eq=False)
class Imager:
    """Computes camera images of pupil phases for one telescope and camera."""

    telescope: Telescope
    camera: Camera

    @cached_property
    def grid(self) -> PupilGrid:
        """Pupil sampling matched to the camera pixels."""
        dx_m = self.camera.wavelength_m / (self.camera.n_pixels * self.camera.pixel_scale_rad)
        return self.telescope.grid_for(dx_m)

    @cached_property
    def oversampling(self) -> int:
        """FFT samples per detector pixel along one axis (odd, so the axis stays centred)."""
        q = max(1, int(np.ceil(2 * self.grid.n_pix / self.camera.n_pixels)))
        return q + 1 - q % 2

    @cached_property
    def fft_size(self) -> int:
        return self.oversampling * self.camera.n_pixels

    @cached_property
    def mask(self) -> np.ndarray:
        return self.telescope.mask(self.grid)

    @cached_property
    def n_valid(self) -> int:
        return int(self.mask.sum())

    @cached_property
    def _far_field(self) -> FarField:
        return FarField(self.mask, self.fft_size)

    def accumulate(self, phase_rad: np.ndarray, out: np.ndarray, transmission: np.ndarray | None = None) -> None:
        """Add to ``out`` (k, M, M) float32 the unshifted, unbinned intensity of each phase row
        (k, n_valid) [rad] on the mask: ``|FFT_M(t exp(i phi))|^2 / (M^2 n_valid)`` (farfield),
        ``t`` the ``transmission`` (k, n_valid) of an apodised pupil (None: 1)."""
        self._far_field.accumulate(np.asarray(phase_rad, dtype=np.float32), out, transmission)

    def intensity(self, phase_rad: np.ndarray, transmission: np.ndarray | None = None) -> np.ndarray:
        """Unshifted, unbinned intensities (k, M, M) float32, each of unit total flux for the full
        pupil (``sum t^2 / n_valid`` with a ``transmission`` t)."""
        out = np.zeros((len(phase_rad), self.fft_size, self.fft_size), dtype=np.float32)
        self.accumulate(phase_rad, out, transmission)
        return out

    def to_pixels(self, intensity: np.ndarray) -> np.ndarray:
        """Centre (fftshift) and bin unshifted intensities to (k, n, n) detector pixels."""
        q = self.oversampling
        n = self.camera.n_pixels
        shifted = np.fft.fftshift(intensity, axes=(-2, -1))
        if q == 1:
            return shifted
        # odd q: the FFT sample on the axis becomes the centre of pixel n/2
        rolled = np.roll(shifted, (q - 1) // 2, axis=(-2, -1))
        return rolled.reshape(*shifted.shape[:-2], n, q, n, q).sum(axis=(-3, -1))

    def image(self, phase_rad: np.ndarray, transmission: np.ndarray | None = None) -> np.ndarray:
        """Detector images (k, n, n) float32 for phases (k, n_valid) [rad], of unit flux for the
        full pupil (see :meth:`intensity` for a ``transmission``)."""
        return self.to_pixels(self.intensity(phase_rad, transmission))

    @cached_property
    def diffraction_limited(self) -> np.ndarray:
        """Diffraction-limited image (n, n) of unit flux; its peak is at (n/2, n/2)."""
        return self.image(np.zeros((1, self.n_valid), dtype=np.float32))[0]

    @cached_property
    def diffraction_limited_peak(self) -> float:
        """Peak of the unit-flux diffraction-limited image, the Strehl reference."""
        return float(self.diffraction_limited.max())

    def axis_value(self, images: np.ndarray) -> np.ndarray:
        """The unit-flux images' (..., n, n) value on the optical axis, pixel (n/2, n/2), over the
        diffraction-limited peak, shape (...): its mean over frames is the long exposure's Strehl
        (no recentring; its peak is on the axis). In the images' precision (float32 in, float32 out)."""
        c = self.camera.n_pixels // 2
        return images[..., c, c] / self.diffraction_limited_peak
