"""Cropped accumulation: what the integrated images of a sub-pixel registration method are scored from.

The baseline ``cog`` adds each selected frame, whole (n x n float64), into the partial sum of
every (criterion, bin) it belongs to (:class:`.accumulation.WholeFrames`): about 16 whole-frame
adds per frame and detector, memory traffic that would dominate a run with every registration
method. A sub-pixel method (:mod:`.registration`) instead adds one short vector per frame
(float64), ``[crop, radial sums, flux]``:

* ``crop``: the registered frame's central ``crop_px`` square about the axis pixel: the frame
  rolled by the whole-pixel part of its shift, cut to ``crop_px`` x ``crop_px``, then moved by
  the sub-pixel remainder (|r| <= 1/2 px) by a Fourier shift of the crop (periodic over the crop:
  the flux it holds is conserved; the ringing of the crop's edges falls off as 1/distance and
  alternates in sign, so the core, at the centre, is moved as by the whole frame's Fourier
  shift to ~1e-4 of its peak, ``tests/test_registration.py``);
* ``radial sums``: the terms of the frame's encircled energy about its registered position
  (which the Fourier shift brings exactly onto the axis) summed over each ``|f|``
  (:meth:`.metrics.EncircledEnergy.radial_sums_about`): the whole band-limited frame's, not the
  crop's; their product with the kernel (:meth:`.metrics.EncircledEnergy.energies_of`) is
  ``EE(R)`` on the d50's radii, taken once per integrated image, not per frame;
* ``flux``: the whole frame's.

All three are linear in the frame, so the sum of the vectors of a set of frames is the vector
of their integrated image, which :meth:`CroppedFrames.score` scores: Strehl from the crop's
brightest pixel over ``P_dl F`` (:func:`.metrics.strehl_from`, ``F`` the whole frames' flux, or a
noisy detector's expected flux, :func:`.metrics.strehl_flux`; the stacked image peaks at the axis,
inside the crop), FWHM from the crop
(:func:`.metrics.fwhm_arcsec`), d50 from the energies (about the axis, where the method stacks
the frames; ``cog``'s whole-frame d50 is about the integrated image's centre of gravity). A
vector is ~1/8 of a 256 x 256 frame at the default crop (:data:`CROP_ARCSEC`), and a crop's
Fourier shift ~1/20 of a whole frame's.
"""

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from . import adds, image_helpers
from .accumulation import axis_window
from .metrics import EncircledEnergy, d50_from_radius, fwhm_arcsec, strehl_flux, strehl_from
from .registration import fourier_shift

CROP_ARCSEC = 1.25
"""Width of a sub-pixel method's crop [arcsec]: the integrated image's core and its half-maximum
contour, for AO-corrected and seeing-limited images alike (FWHM <= ~0.5")."""


def crop_px(n_pixels: int, pixel_scale_arcsec: float) -> int:
    """Pixels across the crop of frames of ``n_pixels`` square at ``pixel_scale_arcsec``: the even
    number of pixels spanning at least :data:`CROP_ARCSEC`, at most the frame (64 for the 4.2 m
    camera's 256 pixels over 5")."""
    return min(n_pixels, 2 * math.ceil(CROP_ARCSEC / pixel_scale_arcsec / 2))


@dataclass(frozen=True, eq=False)
class CroppedFrames:
    """The vectors ``[crop (crop_px^2), radial sums (n_bins), flux]`` of frames of ``n_pixels``
    square (module docstring): their layout, how they are made and added, and their scores."""

    n_pixels: int
    crop_px: int
    encircled: EncircledEnergy
    diffraction_limited_peak: float
    pixel_scale_arcsec: float

    def __post_init__(self):
        if not (0 < self.crop_px <= self.n_pixels and self.crop_px % 2 == 0):
            raise ValueError(f"crop_px must be even, in 2..{self.n_pixels}, got {self.crop_px}")

    @property
    def item_shape(self) -> tuple[int]:
        """Shape of one vector."""
        return (self.crop_px**2 + self.encircled.n_bins + 1,)

    @cached_property
    def window(self) -> np.ndarray:
        """Flat indices of the crop's pixels around the axis (:func:`.accumulation.axis_window`)."""
        return axis_window(self.crop_px)

    def prepare(
        self,
        spectra,
        shifts: np.ndarray,
        remainder: np.ndarray,
        flux: np.ndarray,
        radial_sums: np.ndarray | None = None,
        which: np.ndarray | None = None,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """The vectors (k, item) float64 of the frames (k, n, n) of ``spectra``
        (:class:`.registration.FrameSpectra`) registered by whole-pixel ``shifts`` (k, 2) int
        (``np.roll`` semantics) and sub-pixel ``remainder`` (k, 2) (y, x), of flux ``flux`` (k,);
        ``radial_sums`` (k, n_bins): their encircled energy's radial sums about their registered
        positions, where known and finite (else made here, about ``n/2 - shift``: the axis pixel for
        a frame not registered, which is not shifted); ``which`` (k,) bool: only those frames (the
        others' rows undefined). Into ``out`` (>= k, item) if given."""
        frames = spectra.frames
        k, n, c = len(frames), self.n_pixels, self.crop_px
        which = np.ones(k, bool) if which is None else np.asarray(which, bool)
        out = np.empty((k, *self.item_shape)) if out is None else out[:k]
        if not which.any():
            return out
        picked = slice(None) if which.all() else np.flatnonzero(which)  # a slice: no copies
        crops = self.registered_crops(frames, shifts, remainder, which)
        out[picked, : c * c] = crops[picked].reshape(-1, c * c)
        radial = slice(c * c, c * c + self.encircled.n_bins)
        known = np.zeros(k, bool) if radial_sums is None else which & np.isfinite(radial_sums).all(axis=1)
        if known.all():
            out[:, radial] = radial_sums
        else:
            if known.any():
                out[known, radial] = radial_sums[known]
            missing = np.flatnonzero(which & ~known)
            if missing.size:
                centres = n // 2 - (shifts + remainder)[:, None]  # (k, 1, 2)
                out[missing, radial] = self.encircled.radial_sums_about(frames, centres, spectra, missing)[:, 0]
        out[picked, -1] = flux[picked]
        return out

    def registered_crops(
        self, frames: np.ndarray, shifts: np.ndarray, remainder: np.ndarray, which: np.ndarray
    ) -> np.ndarray:
        """The registered crops (k, c, c) float32 of frames (k, n, n) (module docstring), those of
        ``which`` (k,) bool only (the others undefined)."""
        c = self.crop_px
        crops = np.empty((len(frames), c, c), np.float32)
        image_helpers.crop_rolled(frames, shifts, which, crops)
        moving = which & np.any(remainder != 0, axis=1)
        if moving.all():
            crops = fourier_shift(crops, remainder)
        elif moving.any():
            crops[moving] = fourier_shift(crops[moving], remainder[moving])
        return crops

    @staticmethod
    def add(prepared: np.ndarray, shifts: np.ndarray, rows: np.ndarray, partial: np.ndarray, sign: float) -> None:
        """``partial[r] += sign prepared[j]`` for every row ``r = rows[j, c] >= 0`` (the shifts are in
        the vectors already)."""
        adds.add_rows(prepared, rows, partial, sign)

    def window_values(self, prepared: np.ndarray, shifts: np.ndarray, out: np.ndarray) -> None:
        """The registered frames' values ``out`` (k, w) at the crop's pixels :attr:`window`."""
        out[:] = prepared[:, self.window]

    def images(self, vectors: np.ndarray) -> np.ndarray:
        """The crops (..., c, c) of vectors (..., item) (a view)."""
        c = self.crop_px
        return vectors[..., : c * c].reshape(*vectors.shape[:-1], c, c)

    @staticmethod
    def flux(vectors: np.ndarray) -> np.ndarray:
        """The flux (...) of vectors (..., item)."""
        return vectors[..., -1]

    def score(self, vectors: np.ndarray, expected_flux: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """Strehl ratio, FWHM [arcsec] and d50 [arcsec] (...) of the images of vectors (..., item)
        (module docstring); the Strehl over ``expected_flux`` (...) where not NaN
        (:func:`.metrics.strehl_flux`)."""
        c2, n_bins = self.crop_px**2, self.encircled.n_bins
        images, flux = self.images(vectors), self.flux(vectors)
        strehl = strehl_from(images.max(axis=(-2, -1)), strehl_flux(flux, expected_flux), self.diffraction_limited_peak)
        radius = self.encircled.radius_px_of(self.encircled.energies_of(vectors[..., c2 : c2 + n_bins]), flux)
        return strehl, fwhm_arcsec(images, self.pixel_scale_arcsec), d50_from_radius(radius, self.pixel_scale_arcsec)
