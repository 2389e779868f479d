"""Fourier lucky imaging (Garrel, Guyon & Baudoz 2012, PASP 124, 861): frames selected per spatial frequency.

Shift-and-add keeps, for a fraction ``f``, the best ``n_f = max(1, round(f n))`` frames by one
scalar criterion and adds them whole. Fourier lucky imaging keeps, at each spatial frequency
``q`` of the registered frames, the ``n_f`` frames whose Fourier amplitude ``|X_j(q)|`` is the
largest there, and averages their complex values: ``Y(q) = mean_{j in S_f(q)} X_j(q)``; the
integrated image is the inverse transform of ``Y``. At ``f = 1`` every frequency keeps every frame
and ``Y`` is the transform of the shift-and-add image (equal to float64 rounding,
``tests/test_fourier.py``).

What is transformed: each frame's registered central square of ``crop_px`` pixels (the integrated
images' crop, ``shared_image_crop_px``), the same square the method's shift-and-add image keeps
(:func:`registered_crops`), in float64 (FFTW's real transform: the half plane ``crop_px x (crop_px/2 + 1)``).
The amplitudes ranked are float32 (ties, in frame order). On the half plane's self-conjugate columns
(``q_x`` 0 and ``crop_px/2``) ``q`` and ``-q`` are both present: their amplitude is taken as the larger
of the two, so both keep the same frames and ``Y`` is Hermitian: the image is real.

The passes (:mod:`.pipeline`): pass 1 streams every frame's amplitudes into :class:`TopAmplitudes`
(per detector: the largest ``n_max`` amplitudes at each frequency, ``n_max`` the largest count kept
below all frames), from which each fraction's threshold ``t_f(q)`` (its ``n_f``-th largest amplitude)
and the ties at it to keep follow exactly; pass 2 (the frames read, and a noisy detector's noise
drawn, again) adds each frame's complex values where its amplitude is above the threshold (or one of
the first ties), into the sums of the detected frames and of the noiseless frames with the same
shifts and the same selection (the ``*_noiseless`` scores, as shift-and-add's). Every frequency's
kept count is checked to be ``n_f``.

Scores (:meth:`FourierSelection.scores`): the Strehl ratio is the image's peak over ``P_dl F``, ``F`` the
mean whole-frame flux of the frames kept at the zero frequency (the crop's flux is not the image's);
a noisy detector's Strehl is over their mean *expected* flux instead, as shift-and-add's
(:func:`.metrics.strehl_flux`: read noise can drive the measured one to zero);
the FWHM is :func:`.metrics.fwhm_arcsec`'s of the image; the d50 is from the image's encircled energy
about the axis pixel (where the frames are stacked; :class:`.metrics.EncircledEnergy` of the crop,
periodic over it) over ``F``; where the disc inscribed in the crop holds less than half of ``F``, the
d50 is that disc's diameter, a lower bound, flagged ``fourier_d50_beyond_crop``. Shift-and-add's d50
uses the whole frame: the two differ by the halo outside the crop (about the axis for the sub-pixel
methods; ``cog`` about the image's centre of gravity).

Memory per registration method and detector: the amplitudes kept, float32
``crop_px (crop_px/2 + 1) x 1.25 n_max`` (2,112 frequencies at 64 pixels: 2.6 MB for 250 frames
kept, 26 MB for 2,500), and the sums, complex128 ``2 x fractions x crop_px (crop_px/2 + 1)`` (100 kB).
"""

from functools import lru_cache

import numpy as np
import pyfftw
import scipy.fft
import xarray as xr

from . import image_helpers
from .accumulation import block_error
from .metrics import EncircledEnergy, d50_from_radius, fwhm_arcsec, strehl_flux, strehl_from
from .ranking import fraction_counts


def registered_crops(accumulation, frames: np.ndarray, shifts: np.ndarray, remainder: np.ndarray, crop_px: int):
    """The central ``crop_px`` squares (k, c, c) float32 of frames (k, n, n) registered as the method's
    shift-and-add stacks them: rolled by the whole-pixel ``shifts`` (k, 2) and, for a sub-pixel method
    (``accumulation`` a :class:`.cropped.CroppedFrames`), moved by the ``remainder`` (k, 2) by the
    Fourier shift of its crop (:meth:`.cropped.CroppedFrames.registered_crops`)."""
    k = len(frames)
    which = np.ones(k, bool)
    if hasattr(accumulation, "registered_crops"):
        crops = accumulation.registered_crops(frames, shifts, remainder, which)
        lo = crops.shape[-1] // 2 - crop_px // 2
        return crops[:, lo : lo + crop_px, lo : lo + crop_px]
    crops = np.empty((k, crop_px, crop_px), np.float32)
    image_helpers.crop_rolled(frames, np.ascontiguousarray(shifts, dtype=np.int64), which, crops)
    return crops


def spectra_of(crops: np.ndarray) -> np.ndarray:
    """The real FFTs (k, c, c/2 + 1) complex128 of crops (k, c, c), in float64 (FFTW, :func:`_rfft2`)."""
    frames, spectra, fft = _rfft2(*crops.shape[:2])
    np.copyto(frames, crops)
    fft.execute()
    return spectra.copy()


@lru_cache(maxsize=8)
def _rfft2(k: int, c: int) -> tuple:
    """Float64 frames (k, c, c), their spectra (k, c, c/2 + 1) and the FFTW plan between them
    (FFTW_ESTIMATE: chosen without timing, so the same rounding in both passes and every process;
    2.5x faster than ``scipy.fft`` at 64 pixels)."""
    frames = pyfftw.empty_aligned((k, c, c), np.float64)
    spectra = pyfftw.empty_aligned((k, c, c // 2 + 1), np.complex128)
    return frames, spectra, pyfftw.FFTW(frames, spectra, axes=(1, 2), flags=("FFTW_ESTIMATE",), threads=1)


def amplitudes(spectra: np.ndarray) -> np.ndarray:
    """The amplitudes ranked (k, c (c/2 + 1)) float32 of spectra (k, c, c/2 + 1): ``|X(q)|``, on the
    self-conjugate columns (``q_x`` 0 and ``c/2``) the larger of ``|X(q)|`` and ``|X(-q)|`` (module
    docstring), so that the same frames are kept at ``q`` and ``-q``."""
    amp = np.abs(spectra).astype(np.float32)
    c = spectra.shape[1]
    mirror = (-np.arange(c)) % c
    columns = [0, c // 2] if c % 2 == 0 else [0]
    amp[:, :, columns] = np.maximum(amp[:, :, columns], amp[:, mirror][:, :, columns])
    return amp.reshape(len(amp), -1)


class TopAmplitudes:
    """The ``keep`` largest amplitudes at each of ``n_freq`` frequencies over the frames streamed
    through :meth:`add` (exact: a frequency's buffer is cut to its ``keep`` largest whenever it is full,
    ``np.partition``; it holds ``keep + max(slack, keep / 4)`` values, float32)."""

    def __init__(self, keep: int, n_freq: int, slack: int):
        self.keep = keep
        self.values = np.empty((n_freq, keep + max(slack, keep // 4)), np.float32)
        self.filled = 0

    def add(self, amp: np.ndarray) -> None:
        """Stream the amplitudes (k, n_freq) of k more frames."""
        k = len(amp)
        if self.filled + k > self.values.shape[1]:
            self._cut()
            if self.filled + k > self.values.shape[1]:
                raise ValueError(f"a chunk of {k} frames, more than the first's")
        self.values[:, self.filled : self.filled + k] = amp.T
        self.filled += k

    def _cut(self) -> None:
        if self.filled > self.keep:
            held = self.values[:, : self.filled]
            held[:, : self.keep] = np.partition(held, self.filled - self.keep, axis=1)[:, self.filled - self.keep :]
            self.filled = self.keep

    def thresholds(self, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per count ``n`` of ``counts`` (each <= ``keep``, of the frames streamed): the ``n``-th largest
        amplitude at each frequency (len(counts), n_freq) and how many frames at it to keep (the
        ties: ``n`` less those strictly above it) (len(counts), n_freq) int64."""
        self._cut()
        held = self.values[:, : self.filled]
        ranked = -np.sort(-held, axis=1)  # descending
        threshold = ranked[:, np.asarray(counts) - 1].T
        above = (held[None] > threshold[:, :, None]).sum(axis=2)
        return threshold, np.asarray(counts)[:, None] - above


class FourierSelection:
    """One registration method's Fourier lucky imaging (module docstring) of ``n_det`` detectors'
    ``n_frames`` frames at ``fractions``, on the registered central ``crop_px`` square; ``chunk_frames``:
    the largest chunk (the amplitudes' buffers' slack)."""

    def __init__(self, n_det: int, n_frames: int, fractions, crop_px: int, chunk_frames: int):
        self.fractions = np.asarray(fractions, dtype=np.float64)
        self.counts = fraction_counts(n_frames, fractions)
        self.n_frames, self.crop_px = n_frames, crop_px
        self.half = (crop_px, crop_px // 2 + 1)
        n_freq = crop_px * (crop_px // 2 + 1)
        self.partial = self.counts < n_frames  # fractions that select (the others keep every frame)
        keep = int(self.counts[self.partial].max()) if self.partial.any() else 0
        self.top = [TopAmplitudes(keep, n_freq, chunk_frames) for _ in range(n_det)] if keep else None
        self.threshold = self.ties = None
        n_fr = len(self.counts)
        # (detected, noiseless): the kept complex values' sums, and the whole-frame flux kept at q = 0
        self.sums = np.zeros((2, n_det, n_fr, n_freq), np.complex128)
        self.flux = np.zeros((2, n_det, n_fr))
        self.expected = np.full((n_det, n_fr), np.nan)  # the detected frames' expected flux kept (noisy)
        self.taken = np.zeros((n_det, n_fr, n_freq), np.int64)  # ties kept so far
        self.kept = np.zeros((n_det, n_fr, n_freq), np.int64)  # frames kept so far (checked: the count)

    def observe(self, i: int, amp: np.ndarray) -> None:
        """Pass 1: detector ``i``'s amplitudes (k, n_freq) (:func:`amplitudes`) of the next frames, streamed."""
        if self.top is not None:
            self.top[i].add(amp)

    def rank(self) -> None:
        """After pass 1: each detector's thresholds and ties per selecting fraction and frequency."""
        if self.top is None:
            return
        counts = self.counts[self.partial]
        pairs = [top.thresholds(counts) for top in self.top]
        self.threshold = np.stack([p[0] for p in pairs])  # (det, selecting fractions, freq)
        self.ties = np.stack([p[1] for p in pairs])
        self.top = None  # the amplitudes' memory freed

    def masks(self, i: int, amp: np.ndarray) -> np.ndarray:
        """Pass 2: which frames (k, n_freq) of the next ``k`` of detector ``i`` (amplitudes ``amp``) each
        fraction keeps at each frequency, (fractions, k, n_freq) bool; the ties counted."""
        out = np.ones((len(self.counts), *amp.shape), bool)
        for s, j in enumerate(np.flatnonzero(self.partial)):
            threshold, ties = self.threshold[i, s], self.ties[i, s]
            equal = amp == threshold
            out[j] = amp > threshold
            at = np.flatnonzero(equal.any(axis=0))  # the frequencies with frames at their threshold
            tied = equal[:, at]
            out[j][:, at] |= tied & (np.cumsum(tied, axis=0) + self.taken[i, j, at] <= ties[at])
            self.taken[i, j, at] += tied.sum(axis=0)
        self.kept[i] += out.sum(axis=1)
        return out

    def add(
        self, i: int, spectra: np.ndarray, amp: np.ndarray, flux: np.ndarray, clean=None, clean_flux=None, expected=None
    ) -> None:
        """Pass 2: detector ``i``'s spectra (k, n_freq) of the registered crops of the next frames, their
        amplitudes ``amp`` (k, n_freq) and whole-frame ``flux`` (k,), into their sums where kept;
        ``clean``, ``clean_flux`` and ``expected``: the noiseless frames' spectra with the same shifts (a
        noisy detector), into the noiseless sums with the same selection, and the detected frames'
        expected flux (k,) (:func:`.metrics.strehl_flux`)."""
        keep = self.masks(i, amp)
        self._add(0, i, keep, spectra, flux)
        if clean is not None:
            self._add(1, i, keep, clean, clean_flux)
        if expected is not None:
            kept = np.array([expected[mask[:, 0]].sum() for mask in keep])
            self.expected[i] = np.nan_to_num(self.expected[i]) + kept  # NaN until the first

    def _add(self, which: int, i: int, keep: np.ndarray, spectra: np.ndarray, flux: np.ndarray) -> None:
        for j, mask in enumerate(keep):
            self.sums[which, i, j] += np.where(mask, spectra, 0).sum(axis=0)
            self.flux[which, i, j] += flux[mask[:, 0]].sum()

    def images(self, noiseless_detectors) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The integrated images (2, det, fractions, c, c) (detected, noiseless), their fluxes
        ``F`` (2, det, fractions) and the detected images' expected fluxes (det, fractions; NaN for a
        noiseless detector); a noiseless detector's noiseless ones its own. Checks that every
        frequency kept ``n_f`` frames."""
        if not (self.kept == self.counts[None, :, None]).all():
            raise RuntimeError("Fourier selection: a frequency kept another count of frames than its fraction's")
        for i, noiseless in enumerate(noiseless_detectors):
            if noiseless:
                self.sums[1, i], self.flux[1, i] = self.sums[0, i], self.flux[0, i]
        n = self.counts[None, None, :]
        mean = self.sums.reshape(*self.sums.shape[:3], *self.half) / n[..., None, None]
        return scipy.fft.irfft2(mean, s=(self.crop_px, self.crop_px)), self.flux / n, self.expected / n[0]

    def scores(
        self, images: np.ndarray, flux: np.ndarray, peak: float, scale: float, strehl_over=None
    ) -> tuple[np.ndarray, ...]:
        """Strehl ratio, FWHM [arcsec], d50 [arcsec] and where the d50 is beyond the crop (a lower
        bound, bool) (...) of images (..., c, c) of fluxes ``F`` (...) (module docstring; ``peak``: the
        unit-flux diffraction-limited peak, ``scale`` [arcsec/pixel]); ``strehl_over`` (...): the
        Strehl's flux where not NaN (:func:`.metrics.strehl_flux`; default ``F``)."""
        c = self.crop_px
        flat = images.reshape(-1, c, c)
        encircled = EncircledEnergy(c)
        centres = np.full((len(flat), 2), float(c // 2))
        radius = encircled.radius_px_of(encircled.energies_binned(flat, centres), flux.reshape(-1))
        radius = radius.reshape(images.shape[:-2])
        beyond = np.isnan(radius) & (flux > 0)
        over = flux if strehl_over is None else strehl_flux(flux, strehl_over)
        return (
            strehl_from(images.max(axis=(-2, -1)), over, peak),
            fwhm_arcsec(images, scale),
            d50_from_radius(np.where(beyond, c / 2, radius), scale),
            beyond,
        )


class FourierRun:
    """A registration method's Fourier lucky imaging over the whole run and over each of ``n_blocks``
    time blocks, each block selected on its own (frame ``f`` in block ``f // (n_frames // n_blocks)``,
    the remainder in none, as :class:`.accumulation.TimeBlocks`): its Monte-Carlo errors are the
    blocks' batch means, as shift-and-add's. Each frame's crop is transformed once for all."""

    def __init__(self, n_det: int, n_frames: int, fractions, crop_px: int, chunk_frames: int, n_blocks: int):
        self.crop_px = crop_px
        self.whole = FourierSelection(n_det, n_frames, fractions, crop_px, chunk_frames)
        self.block_frames = n_frames // n_blocks if n_blocks else 0
        self.blocks = [
            FourierSelection(n_det, self.block_frames, fractions, crop_px, chunk_frames) for _ in range(n_blocks)
        ]

    def _parts(self, start: int, k: int):
        """(selection, the chunk's frames in it) of the chunk of frames ``start..start + k - 1``."""
        yield self.whole, slice(0, k)
        size = self.block_frames
        for b in range(start // max(size, 1), min((start + k - 1) // max(size, 1) + 1, len(self.blocks))):
            yield self.blocks[b], slice(max(b * size, start) - start, min((b + 1) * size, start + k) - start)

    def observe(self, i: int, crops: np.ndarray, start: int) -> None:
        """Pass 1: detector ``i``'s registered crops (k, c, c) of frames ``start..``, their amplitudes streamed."""
        amp = amplitudes(spectra_of(crops))
        for selection, part in self._parts(start, len(crops)):
            selection.observe(i, amp[part])

    def rank(self) -> None:
        """After pass 1: every selection's thresholds."""
        for selection in (self.whole, *self.blocks):
            selection.rank()

    def add(
        self, i: int, crops: np.ndarray, flux: np.ndarray, start: int, clean_crops=None, clean_flux=None, expected=None
    ) -> None:
        """Pass 2: :meth:`FourierSelection.add` of detector ``i``'s registered crops (k, c, c) of frames
        ``start..`` (and of their noiseless ``clean_crops``), into the whole run's and their blocks' sums."""
        spectra = spectra_of(crops)
        amp = amplitudes(spectra)
        spectra = spectra.reshape(len(crops), -1)
        clean = None if clean_crops is None else spectra_of(clean_crops).reshape(len(crops), -1)
        for selection, p in self._parts(start, len(crops)):
            selection.add(
                i,
                spectra[p],
                amp[p],
                flux[p],
                None if clean is None else clean[p],
                None if clean_flux is None else clean_flux[p],
                None if expected is None else expected[p],
            )


def _scored(selection: FourierSelection, detectors, peak: float, scale: float):
    """A selection's integrated images (2, det, fraction, c, c), fluxes and scores (each (2, det, fraction))."""
    integrated, flux, expected = selection.images([d.noiseless for d in detectors])
    over = np.stack([expected, np.full_like(expected, np.nan)])  # the noiseless sums: their own flux
    return integrated, flux, selection.scores(integrated, flux, peak, scale, over)


def add_fourier(ds: xr.Dataset, run: FourierRun, detectors, peak: float, scale: float, images: bool):
    """``ds`` with the Fourier lucky images' scores ``fourier_strehl``, ``fourier_fwhm_arcsec``,
    ``fourier_d50_arcsec`` (fourier_fraction, detector), the same of the noiseless frames with the
    same selection (``*_noiseless``), their Monte-Carlo errors from the time blocks (``*_error``)
    and, with ``images``, ``fourier_image`` (fourier_fraction,
    detector, y, x) over ``F`` (float32; ``ds``'s y and x, the same crop)."""
    selection = run.whole
    integrated, flux, scored = _scored(selection, detectors, peak, scale)  # scores each (2, det, fraction)
    blocks = [_scored(block, detectors, peak, scale)[2] for block in run.blocks]
    dims = ("fourier_fraction", "detector")
    ds = ds.assign_coords(
        fourier_fraction=(
            "fourier_fraction",
            selection.fractions,
            {"units": "1", "long_name": "fraction of frames kept at each spatial frequency (Fourier lucky imaging)"},
        ),
        fourier_n_frames_selected=(
            "fourier_fraction",
            selection.counts,
            {"units": "1", "long_name": "number of frames kept at each spatial frequency"},
        ),
    )
    of = f"the Fourier lucky image (frames kept per spatial frequency of the central {selection.crop_px} pixels)"
    same = "of the same selection per frequency and shifts applied to the noiseless frames"
    for metric, units, name in (
        ("strehl", "1", "Strehl ratio"),
        ("fwhm_arcsec", "arcsec", "FWHM"),
        ("d50_arcsec", "arcsec", "diameter enclosing 50% of the energy (about the axis, within the crop)"),
    ):
        values = scored[("strehl", "fwhm_arcsec", "d50_arcsec").index(metric)]
        ds[f"fourier_{metric}"] = (dims, values[0].T, {"units": units, "long_name": f"{name} of {of}"})
        ds[f"fourier_{metric}_noiseless"] = (dims, values[1].T, {"units": units, "long_name": f"{name} {same}"})
        if len(blocks) > 1:
            per_block = np.stack([b[("strehl", "fwhm_arcsec", "d50_arcsec").index(metric)] for b in blocks])
            error = block_error(per_block)  # (2, det, fraction)
            for suffix, e in zip(("", "_noiseless"), error):
                ds[f"fourier_{metric}{suffix}_error"] = (
                    dims,
                    e.T,
                    {
                        "units": units,
                        "long_name": f"Monte-Carlo standard error of fourier_{metric}{suffix}, from {len(blocks)} "
                        f"time blocks of {run.block_frames} frames each selected on its own (batch means)",
                    },
                )
    for suffix, beyond in zip(("", "_noiseless"), scored[3]):
        ds[f"fourier_d50_beyond_crop{suffix}"] = (
            dims,
            beyond.T.astype(np.int8),
            {
                "units": "1",
                "long_name": f"1 where fourier_d50_arcsec{suffix} is beyond the crop: the crop's width, a lower bound",
                "flag_values": np.array([0, 1], np.int8),
                "flag_meanings": "value lower_bound",
            },
        )
    if images:
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = integrated[0] / flux[0][..., None, None]  # (det, fraction, c, c)
        ds["fourier_image"] = (
            ("fourier_fraction", "detector", "y", "x"),
            unit.transpose(1, 0, 2, 3).astype(np.float32),
            {"units": "1", "long_name": f"{of} over the kept frames' mean whole-frame flux"},
        )
    return ds
