"""Registration of lucky frames: where each frame's image is, and the shift that recentres it.

A method gives each frame a position ``(y, x)`` [pixel] (pixel centres at integer
coordinates, index ``[y, x]``); the frame is then shifted by ``n/2 - position`` so that
position lands on the axis pixel ``(n/2, n/2)``. NaN: the method cannot register the frame
(``cog``: no positive flux; the others: no positive peak of the filtered frame, or no positive
flux in ``windowed_cog``'s disc); such a frame is not shifted and is counted.

Methods (:data:`REGISTRATIONS`):

* ``cog``: the centre of gravity of the whole frame, whole-pixel shifts (the study's
  baseline, as before registration methods were added). Its noise: with ``N`` photons and
  read noise ``sigma_rn`` over pixels at ``x`` from the centre, ``var = sigma_rn^2 sum x^2 / N^2
  + sigma_psf^2 / N`` per axis (``sigma_psf^2`` the image's variance): 1.9 px rms at N = 1000
  and 0.1 e- on 256 x 256 pixels.
* ``windowed_cog``: the centre of gravity of the frame in a disc of radius
  :data:`WINDOW_RADIUS_FWHM` core widths about the peak of the matched-filtered frame
  (the frame convolved with a Gaussian of the diffraction-limited core's FWHM), the disc
  moved onto the result and the centre of gravity taken again (:data:`WINDOW_ITERATIONS`).
* ``peak``: the brightest speckle, the peak of the matched-filtered frame (same Gaussian),
  refined by a parabola through it and its neighbours along each axis.
* ``xcorr``: the peak of the cross-correlation with the diffraction-limited PSF (rings and
  central obscuration included), refined by the same parabola. The reference is the
  diffraction-limited PSF, not the integrated image of the frames seen so far: it is free
  of noise and fixed, so a frame's noise does not feed back into the reference (a running
  shift-and-add reference would collect each frame's noise peak on the axis and bias the
  Strehl up), and it is the matched filter of the diffraction-limited speckle that the
  selected frames hold.

The sub-pixel methods filter and search only the central :data:`SEARCH_ARCSEC` square of the
frame (the search box, periodic over itself: the star's wander stays well inside), as a
pipeline looks for the star where it can be. Their shifts are split into a whole-pixel part
(a roll) and a remainder in (-1/2, 1/2] applied as a Fourier shift (:func:`fourier_shift`):
it conserves the flux, and a whole-pixel shift gives exactly the roll (the remainder is then
zero and the frame untouched); :mod:`.cropped` applies both to the central crop that such a
method adds up.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pyfftw
import scipy.fft

from . import image_helpers
from .accumulation import recentring_shifts_px

REGISTRATIONS = ("cog", "windowed_cog", "peak", "xcorr")
"""The registration methods, ``cog`` (the baseline) first."""

WINDOW_RADIUS_FWHM = 2.0
"""Radius of ``windowed_cog``'s disc [diffraction-limited core FWHM]: the core and the first ring."""

WINDOW_ITERATIONS = 2
"""Centres of gravity ``windowed_cog`` takes, each in the disc about the previous position."""

SEARCH_ARCSEC = 2.5
"""Side of the search box about the axis [arcsec] in which the sub-pixel methods look for the star
(the filtered frame's peak): +-1.25", five times the wander an LGS system leaves uncorrected
(tip-tilt, ~0.25" rms). A quarter of the 5" camera's pixels: fewer noise peaks to mistake for the
star at low signal, and filters a quarter the size (:func:`search_px`)."""


def search_px(n_pixels: int, pixel_scale_arcsec: float) -> int:
    """Pixels across the search box of frames of ``n_pixels`` square at ``pixel_scale_arcsec``:
    the number of the frame's parity spanning at least :data:`SEARCH_ARCSEC`, at most the frame
    (128 for the 4.2 m camera's 256 pixels over 5")."""
    m = int(np.ceil(SEARCH_ARCSEC / pixel_scale_arcsec))
    return min(n_pixels, m + (m - n_pixels) % 2)


def gaussian_kernel(n_pixels: int, fwhm_px: float) -> np.ndarray:
    """Unit-sum Gaussian (n, n) of FWHM ``fwhm_px`` centred on pixel (0, 0) (periodic)."""
    d = np.fft.fftfreq(n_pixels, 1.0 / n_pixels)
    sigma = fwhm_px / (2 * np.sqrt(2 * np.log(2)))
    g = np.exp(-0.5 * (d / sigma) ** 2)
    kernel = g[:, None] * g[None, :]
    return kernel / kernel.sum()


class _Transforms:
    """FFTW's real 2-D transforms of one n x n float32 frame, both ways (FFTW_ESTIMATE: chosen
    without timing, so the rounding is the same in every process, and the same as
    :meth:`.metrics.EncircledEnergy.fractions_binned`'s). Not thread-safe."""

    def __init__(self, n: int):
        self.frame = pyfftw.empty_aligned((n, n), dtype=np.float32)
        self.spectrum = pyfftw.empty_aligned((n, n // 2 + 1), dtype=np.complex64)
        self.forward = pyfftw.FFTW(self.frame, self.spectrum, axes=(0, 1), flags=("FFTW_ESTIMATE",), threads=1)
        self.backward = pyfftw.FFTW(
            self.spectrum,
            self.frame,
            axes=(0, 1),
            direction="FFTW_BACKWARD",
            flags=("FFTW_ESTIMATE", "FFTW_DESTROY_INPUT"),
            threads=1,
        )

    def transform(self, frame: np.ndarray, out: np.ndarray) -> None:
        """``out`` (n, n/2 + 1) = the real FFT of ``frame``: in place of copies where both are
        C-contiguous and aligned as the plan's arrays (FFTW's new-array execute: the same plan, the
        same bits), else through them."""
        if aligned(frame) and aligned(out):
            self.forward.update_arrays(frame, out)
            self.forward.execute()
            return
        self.frame[:] = frame
        self.forward.update_arrays(self.frame, self.spectrum)
        self.forward.execute()
        out[:] = self.spectrum

    def filter(self, spectrum: np.ndarray, kernel_ft: np.ndarray, out: np.ndarray) -> None:
        """``out`` = the periodic convolution of the frame of ``spectrum`` with the kernel of spectrum ``kernel_ft``."""
        self.spectrum[:] = spectrum
        self.spectrum *= kernel_ft
        self.backward()  # normalised by FFTW's interface (1 / n^2)
        out[:] = self.frame


def aligned(array: np.ndarray) -> bool:
    """Whether ``array`` is C-contiguous and aligned as FFTW's plans here (``pyfftw.simd_alignment``)."""
    return array.flags.c_contiguous and array.ctypes.data % pyfftw.simd_alignment == 0


def empty_aligned(shape: tuple, dtype) -> np.ndarray:
    """An uninitialised array aligned for FFTW's plans (:func:`aligned`, when its items are too)."""
    return pyfftw.empty_aligned(shape, dtype=dtype)


@lru_cache(maxsize=4)
def _transforms(n: int) -> _Transforms:
    return _Transforms(n)


class FrameSpectra:
    """The real FFTs (FFTW float32) of a chunk of frames (k, n, n), and of their central squares
    (:meth:`box_spectrum`: a registration's search box), each made once when first needed, and
    shared by what is made of them: the frames filtered by a registration's kernel (made once per
    kernel: ``windowed_cog`` and ``peak`` share theirs) and their encircled energy
    (:meth:`.metrics.EncircledEnergy.energies_binned`). The same values as transforming each
    frame again for each use. :meth:`reset` holds another chunk (the buffers reused)."""

    def __init__(self, frames: np.ndarray | None = None):
        self.frames, self._spectra, self._done, self._buffers, self._filtered = None, None, None, {}, {}
        self._flux, self._boxes, self._box_chunk = None, {}, {}
        if frames is not None:
            self.reset(frames)

    def reset(self, frames: np.ndarray) -> "FrameSpectra":
        """Hold the spectra of ``frames`` (k, n, n) float32 (the previous chunk's forgotten)."""
        k, n = len(frames), frames.shape[-1]
        if self._spectra is None or len(self._spectra) < k or self._spectra.shape[1] != n:
            self._spectra = empty_aligned((k, n, n // 2 + 1), np.complex64)
            self._done, self._buffers, self._boxes = np.zeros(k, bool), {}, {}
        self.frames = frames
        self._done[:] = False
        self._filtered, self._flux = {}, None
        return self

    def spectrum(self, j: int) -> np.ndarray:
        """Frame ``j``'s real FFT (n, n/2 + 1) complex64."""
        if not self._done[j]:
            _transforms(self.frames.shape[-1]).transform(self.frames[j], self._spectra[j])
            self._done[j] = True
        return self._spectra[j]

    def box_spectrum(self, j: int, m: int) -> np.ndarray:
        """The real FFT (m, m/2 + 1) complex64 of frame ``j``'s central ``m`` square (rows and
        columns ``n/2 - m/2 ..``; the whole frame's :meth:`spectrum` if ``m`` is ``n``)."""
        n = self.frames.shape[-1]
        if m == n:
            return self.spectrum(j)
        boxes = self._boxes.get(m)
        if boxes is None or len(boxes[0]) < len(self._spectra):
            boxes = self._boxes[m] = (
                np.empty((len(self._spectra), m, m // 2 + 1), np.complex64),
                np.zeros(len(self._spectra), bool),
            )
        spectra, done = boxes
        if self._box_chunk.get(m) is not self.frames:  # another chunk: forget this size's spectra
            done[:] = False
            self._box_chunk[m] = self.frames
        if not done[j]:
            lo = n // 2 - m // 2
            _transforms(m).transform(self.frames[j, lo : lo + m, lo : lo + m], spectra[j])
            done[j] = True
        return spectra[j]

    def filtered(self, key, kernel_ft: np.ndarray) -> np.ndarray:
        """The frames' central ``m`` squares (k, m, m) float32 (``m`` the kernel's size, at most n)
        convolved, periodically over the square, with the kernel of spectrum ``kernel_ft`` (m, m/2 + 1)
        (made once per ``key``, which names the kernel; read only)."""
        if key not in self._filtered:
            k, m = len(self.frames), kernel_ft.shape[0]
            buffer = self._buffers.get(key)
            if buffer is None or len(buffer) < k:
                buffer = self._buffers[key] = np.empty((len(self._spectra), m, m), np.float32)
            transforms = _transforms(m)
            for j in range(k):
                transforms.filter(self.box_spectrum(j, m), kernel_ft, buffer[j])
            self._filtered[key] = buffer[:k]
        return self._filtered[key]

    def flux(self) -> np.ndarray:
        """The frames' fluxes (k,) (float64 sums; made once per chunk)."""
        if self._flux is None:
            self._flux = self.frames.sum(axis=(1, 2), dtype=np.float64)
        return self._flux


FOURIER_SHIFT_BATCH = 64
"""Frames transformed at once by :func:`fourier_shift` (FFTW plans of powers of two up to it)."""


class _BatchTransforms:
    """FFTW's real 2-D transforms of ``b`` frames (b, n, n) float32 at once, both ways, in place of
    their buffers (FFTW_ESTIMATE, as :class:`_Transforms`). Not thread-safe."""

    def __init__(self, b: int, n: int):
        self.frames = pyfftw.zeros_aligned((b, n, n), dtype=np.float32)
        self.spectra = pyfftw.zeros_aligned((b, n, n // 2 + 1), dtype=np.complex64)
        self.forward = pyfftw.FFTW(self.frames, self.spectra, axes=(1, 2), flags=("FFTW_ESTIMATE",), threads=1)
        self.backward = pyfftw.FFTW(
            self.spectra,
            self.frames,
            axes=(1, 2),
            direction="FFTW_BACKWARD",
            flags=("FFTW_ESTIMATE", "FFTW_DESTROY_INPUT"),
            threads=1,
        )


@lru_cache(maxsize=16)
def _batch_transforms(b: int, n: int) -> _BatchTransforms:
    return _BatchTransforms(b, n)


def fourier_shift(frames: np.ndarray, shifts_px: np.ndarray) -> np.ndarray:
    """Frames (k, n, n) float32 shifted by ``shifts_px`` (k, 2) (y, x) [pixel], periodic:
    ``out(r) = frame(r - s)`` for the band-limited frame, by the phase ramp
    ``exp(-2 pi i k.s / n)`` on its real FFT (FFTW, float32, :data:`FOURIER_SHIFT_BATCH` frames at a
    time; the ramp :func:`.image_helpers.phase_ramps`; the Nyquist terms made real by the inverse
    transform). Conserves the flux (the zero frequency is untouched); a whole-pixel shift equals
    ``np.roll`` to float rounding."""
    frames = np.asarray(frames, dtype=np.float32)
    shifts_px = np.ascontiguousarray(shifts_px, dtype=np.float64)
    k, n = len(frames), frames.shape[-1]
    out = np.empty(frames.shape, np.float32)
    for start in range(0, k, FOURIER_SHIFT_BATCH):
        m = min(FOURIER_SHIFT_BATCH, k - start)
        batch = _batch_transforms(1 << (m - 1).bit_length(), n)  # the other frames of the batch: ignored
        batch.frames[:m] = frames[start : start + m]
        batch.forward()
        image_helpers.phase_ramps(batch.spectra[:m], shifts_px[start : start + m])
        batch.backward()  # normalised by FFTW's interface (1 / n^2)
        out[start : start + m] = batch.frames[:m]
    return out


def parabola_offset(below: np.ndarray, at: np.ndarray, above: np.ndarray) -> np.ndarray:
    """Vertex offset in [-1/2, 1/2] of the parabola through ``(-1, below), (0, at), (1, above)``:
    ``(below - above) / (2 (below - 2 at + above))``, 0 where that curvature is not negative."""
    curvature = below - 2 * at + above
    with np.errstate(invalid="ignore", divide="ignore"):
        offset = np.where(curvature < 0, 0.5 * (below - above) / curvature, 0.0)
    return np.clip(offset, -0.5, 0.5)


@dataclass(frozen=True, eq=False)
class Registration:
    """A registration method (:data:`REGISTRATIONS`) for frames of ``n_pixels`` square.

    ``diffraction_limited`` (n, n): the unit-flux diffraction-limited image, peak on
    (n/2, n/2) (``Imager.diffraction_limited``; ``xcorr``'s reference); ``core_fwhm_px``:
    the FWHM of its core [pixel] (the matched filter of ``windowed_cog`` and ``peak``);
    ``search_px``: the side of the central square (the search box, :func:`search_px`) in which
    the sub-pixel methods look for the filtered frame's peak (None: the whole frame).
    """

    name: str
    diffraction_limited: np.ndarray | None = None
    core_fwhm_px: float = 0.0
    search_px: int | None = None

    def __post_init__(self):
        if self.name not in REGISTRATIONS:
            raise ValueError(f"registration {self.name!r}: must be one of {REGISTRATIONS}")
        if self.name != "cog" and (self.diffraction_limited is None or not self.core_fwhm_px > 0):
            raise ValueError(f"registration {self.name!r} needs the diffraction-limited image and core FWHM")
        if self.name != "cog":
            n = self.diffraction_limited.shape[-1]
            m = n if self.search_px is None else self.search_px
            if not (0 < m <= n and (n - m) % 2 == 0):
                raise ValueError(f"search_px must be in 1..{n}, of the parity of {n}: got {self.search_px}")
            if self.name == "xcorr":  # correlation with the reference (its central m square): its conjugate spectrum
                lo = n // 2 - m // 2
                reference = np.roll(
                    self.diffraction_limited[lo : lo + m, lo : lo + m], (-(m // 2), -(m // 2)), axis=(0, 1)
                )  # axis at 0
                kernel_ft = np.conj(scipy.fft.rfft2(reference / reference.sum()))
            else:
                kernel_ft = scipy.fft.rfft2(gaussian_kernel(m, self.core_fwhm_px))
            object.__setattr__(self, "_kernel_ft", kernel_ft.astype(np.complex64))

    @property
    def subpixel(self) -> bool:
        """Whether the shifts have a sub-pixel part (every method but ``cog``)."""
        return self.name != "cog"

    @property
    def filter_key(self) -> tuple:
        """Names the method's kernel (:meth:`FrameSpectra.filtered`): the Gaussian of the core's FWHM
        over the search box (``windowed_cog``, ``peak``), or this method's reference (``xcorr``)."""
        if self.name == "xcorr":
            return "xcorr", id(self)
        return "gaussian", self.core_fwhm_px, self._kernel_ft.shape[0]

    def filtered(self, frames: np.ndarray, spectra: FrameSpectra | None = None) -> np.ndarray:
        """The frames' search boxes (k, m, m) correlated with the method's kernel (float32; read
        only; the whole frames without a search box), from their ``spectra`` if given (of these frames)."""
        spectra = FrameSpectra(np.asarray(frames, dtype=np.float32)) if spectra is None else spectra
        return spectra.filtered(self.filter_key, self._kernel_ft)

    def positions_px(
        self, frames: np.ndarray, centroids_px: np.ndarray, spectra: FrameSpectra | None = None
    ) -> np.ndarray:
        """Positions (k, 2) (y, x) [pixel] of frames (k, n, n) whose centres of gravity are
        ``centroids_px`` (k, 2) (``cog``'s positions), the frames' ``spectra`` if known
        (:class:`FrameSpectra`); NaN where the method cannot register a frame."""
        if self.name == "cog":
            return np.asarray(centroids_px, dtype=np.float64)
        filtered = self.filtered(frames, spectra)
        k, m, _ = filtered.shape
        lo = frames.shape[-1] // 2 - m // 2  # the search box's first row and column in the frame
        flat = filtered.reshape(k, -1)
        best = np.argmax(flat, axis=1)
        iy, ix = best // m, best % m
        j = np.arange(k)
        ok = flat[j, best] > 0  # a peak (a noisy frame's total flux may be negative and its peak still clear)
        if self.name == "windowed_cog":
            position = self._windowed_cog(frames, lo + np.stack([iy, ix], axis=1).astype(np.float64))
        else:
            dy = parabola_offset(filtered[j, (iy - 1) % m, ix], filtered[j, iy, ix], filtered[j, (iy + 1) % m, ix])
            dx = parabola_offset(filtered[j, iy, (ix - 1) % m], filtered[j, iy, ix], filtered[j, iy, (ix + 1) % m])
            position = lo + np.stack([iy + dy, ix + dx], axis=1).astype(np.float64)
        return np.where(ok[:, None] & np.isfinite(position), position, np.nan)

    def _windowed_cog(self, frames: np.ndarray, start_px: np.ndarray) -> np.ndarray:
        """Centres of gravity (k, 2) of frames in discs about ``start_px`` (module docstring);
        NaN where a disc holds no positive flux."""
        k, n, _ = frames.shape
        radius = WINDOW_RADIUS_FWHM * self.core_fwhm_px
        half = int(np.ceil(radius)) + 1
        d = np.arange(-half, half + 1)
        position = start_px.copy()
        j = np.arange(k)[:, None, None]
        for _ in range(WINDOW_ITERATIONS):
            centre = np.floor(position + 0.5)
            ok = np.isfinite(centre).all(axis=1)
            centre = np.where(ok[:, None], centre, 0).astype(np.int64)
            py, px = centre[:, 0, None, None] + d[None, :, None], centre[:, 1, None, None] + d[None, None, :]
            y, x = py.astype(np.float64), np.broadcast_to(px, (k, len(d), len(d))).astype(np.float64)
            inside = (y - position[:, 0, None, None]) ** 2 + (x - position[:, 1, None, None]) ** 2 <= radius**2
            values = np.where(inside, frames[j, py % n, px % n], 0.0).astype(np.float64)
            total = values.sum(axis=(1, 2))
            with np.errstate(invalid="ignore", divide="ignore"):
                new = np.stack([(values * y).sum(axis=(1, 2)), (values * x).sum(axis=(1, 2))], axis=1) / total[:, None]
            position = np.where((ok & (total > 0))[:, None], new, np.nan)
        return position


COG = Registration("cog")
"""The baseline: whole-frame centre of gravity, whole-pixel shifts."""


def shifts_of(positions_px: np.ndarray, n_pixels: int, subpixel: bool) -> tuple[np.ndarray, np.ndarray]:
    """The shifts that bring ``positions_px`` (..., 2) to the axis pixel (n/2, n/2): whole pixels
    (..., 2) int64 ``floor(n/2 - p + 1/2)`` and, if ``subpixel``, the remainder (..., 2) in
    (-1/2, 1/2] (else 0); no shift where a position is not finite."""
    positions = np.asarray(positions_px, dtype=np.float64)
    whole = recentring_shifts_px(positions, n_pixels)
    if not subpixel:
        return whole, np.zeros(whole.shape)
    return whole, np.where(np.isfinite(positions), n_pixels // 2 - positions - whole, 0.0)
