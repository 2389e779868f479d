"""Lucky imaging of one target's frame cube: detect, select, shift and add, score.

Method (Basden 2014, sec. "Shift and add"): every frame gets a scalar quality per
criterion (image Strehl, 50%-energy diameter d50, or an external per-frame value such as
the LGS tilt-removed wavefront rms); frames are ranked over the whole cube
(:mod:`.ranking`); for each fraction ``f`` the best ``n_f = max(1, round(f n))`` frames are
registered (:mod:`.registration`: by default on their centre of gravity, by a whole number
of pixels; else on a matched-filtered position, whole pixels plus a Fourier shift of the
remainder) and added (:mod:`.accumulation`). The integrated images are scored by Strehl, FWHM and d50
(:mod:`.scoring`, :mod:`.metrics`).

Frames are ``(k, n, n)`` float32 unit-flux noiseless images indexed ``[y, x]`` with the
optical axis on pixel ``(n/2, n/2)``; detector noise (:class:`.detector.KeyedNoise`) is
applied here, so one simulated cube serves every detector model. A noisy detector's draws
for frame ``f`` are keyed by ``(seed, detector_key(name), f)`` (:mod:`luckyao.seeds`): they
depend on the seed, the detector's name and the frame only, not on the chunking or the other
detectors (names must be distinct), and drawing them again gives the same frames. A
noiseless detector's frames are the input as float32.

Several registration methods share one run (:func:`run_lucky_methods`): each chunk is read
and each detector's noise drawn once per pass, the frames' flux, centre of gravity and Strehl
measured once, and every method (:class:`.method_run.MethodRun`) registers, measures and adds
them into sums of its own, receiving the same operations in the same order as a run of that
method alone (its results bit for bit the same). Pass 2 draws again the frames any method
guessed wrong, once.

The passes over the frames, in order (:class:`_LuckyRun`):

0. (only when guessing, below) measure the noiseless frames: the guesses' predictor, and the
   noiseless detectors' measures.
1. Detect each chunk for each detector; measure per-frame Strehl, d50
   (:meth:`.metrics.EncircledEnergy.radius_px_binned`) and centre of gravity (from the
   frame's row and column sums); sum the long exposure without recentring; since each
   frame's shift is known then (its own centroid, or the reference's), recentre it
   (:func:`.accumulation.recentring_shifts_px`, np.roll semantics) into the recentred long
   exposure and into the (criterion, bin) partial sums of the criteria ranked before pass 1:
   the external ones, and with a reference all. Without a reference the image criteria
   are ranked only after pass 1: a noisy detector's frames go now to bins guessed from the
   frames seen so far and the noiseless frames (:class:`.guesses.GuessedBins`).
2. Rank the image criteria; add a noiseless detector's frames to their bins; draw again
   only the noisy frames whose final bin (of the run or of their time block) differs from
   the guess (the same draws; checked by their flux) and move them, so the noise of most
   frames is drawn once (its sums equal direct ones to float64 rounding). The count drawn
   again is the result's ``frames_drawn_again`` attribute.
3. Score: each fraction's image is the cumulative sum of its bins.

With Fourier lucky imaging (``fourier_fractions``, :mod:`.fourier`), pass 1 also streams each
registered frame's crop amplitudes per detector and method, pass 2 draws every noisy frame again
(not only those guessed wrong) and adds each frame's complex values where the threshold keeps them;
the other sums receive the same operations as without it.

A noisy detector's Strehl ratios (a frame's, its criterion; an integrated image's; a time
block's; the long exposures') are over the frames' expected flux, ``N`` times the noiseless
frame's flux summed over the frames an image adds up (:func:`.metrics.strehl_flux`,
:func:`.scoring.expected_fluxes`), not over the image's noisy sum, which read noise drives to
zero at a few photons a frame; a noiseless detector's over its own flux.

Alongside, the noiseless frames (the input, as float32) get the same detector's shifts
and the same bins into a second set of partial sums: the ``*_noiseless`` scores separate a
wrong selection or recentring from the noise in the final image. The sums are float64
throughout, frame by frame (:func:`.adds.add_recentred`); a noiseless detector's second
set is its first, copied, so its ``*_noiseless`` values equal the others bit for bit. The
sub-pixel methods add, instead of whole frames, each registered frame's central crop, its
encircled energy's radial sums about the axis and its flux (:mod:`.cropped`: an eighth of the
memory and its traffic), from which their integrated images are scored.
Memory: per method, the two sets of partial sums, float64 (2 x detectors x criteria x distinct
counts x n x n; a sub-pixel method's ~1/8 of that), plus a chunk's work arrays (~1 kB per
pixel and frame of a chunk) and, when scoring, the integrated images (criteria x fractions x
detectors x n x n) of one set of one method at a time (the cumulative sums are made in place).

Monte-Carlo errors (``n_blocks`` >= 2): the frames are cut into ``n_blocks`` time blocks of
``n_frames // n_blocks`` frames (the remainder left out), each block is selected, recentred
and scored on its own as a short run (the same fractions of its frames, ranked within it),
and the standard error of a value is the standard deviation of its block values over
``sqrt(n_blocks)`` (batch means: the blocks are independent when longer than the
turbulence's correlation time; compare ``tests/test_errors.py``). The blocks' partial sums
are extra rows of the same sums (:class:`.accumulation.PartialSums`), scored and cleared
after the chunk that ends the block; with guessed bins, the image criteria's rows of every
block stay until pass 2 (detectors x 2 x blocks x distinct counts x n x n float64: 1.7 GB
for the paper's sweep, per method).
"""

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..progress import Progress, log
from ..seeds import detector_key
from . import adds, cropped
from .detector import Detector, KeyedNoise
from .method_run import MethodRun
from .metrics import EncircledEnergy, centroid_from_sums, strehl_from
from .ranking import IMAGE_CRITERIA, ExternalCriterion, fraction_counts
from .registration import COG, FrameSpectra, Registration, empty_aligned
from .scoring import MatchedStrehl, frame_sums

Chunks = Callable[[], Iterable[tuple[int, np.ndarray]]]


@dataclass(frozen=True, eq=False)
class ImageReference:
    """Per-frame image measurements of another target's detected frames (e.g. the on-axis
    star) that select and recentre a target: ``strehl`` and ``d50_arcsec`` (detector, frame)
    replace the target's own image criteria, ``centroid_px`` (detector, frame, 2) its own
    registered positions for the shifts (same detectors, in the same order; with ``cog``, the
    centres of gravity)."""

    strehl: np.ndarray
    d50_arcsec: np.ndarray
    centroid_px: np.ndarray

    @classmethod
    def of(cls, result: xr.Dataset) -> "ImageReference":
        """The reference given by another target's :func:`run_lucky` result (of the same registration)."""
        return cls(result.frame_strehl.values, result.frame_d50_arcsec.values, result.frame_registered_px.values)


def run_lucky(
    iter_chunks: Chunks,
    n_frames: int,
    detectors: Sequence[Detector],
    fractions: Sequence[float],
    diffraction_limited_peak: float,
    pixel_scale_arcsec: float,
    seed: int,
    criteria_external: Sequence[ExternalCriterion] = (),
    image_crop_px: int | None = 64,
    reference: ImageReference | None = None,
    n_blocks: int = 0,
    progress_interval_s: float = 5.0,
    registration: Registration = COG,
    matched_strehl: MatchedStrehl | None = None,
    crop_px: int | None = None,
    fourier_fractions: Sequence[float] | None = None,
) -> xr.Dataset:
    """Lucky imaging of one frame cube for several detectors, criteria and fractions (module docstring).

    ``iter_chunks()`` returns a fresh iterator of ``(start, frames)``: ``frames``
    (k, n, n) float32 noiseless unit-flux images of frames ``start..start+k-1``, in
    order; it is called once to three times. ``diffraction_limited_peak``: the Strehl reference
    (``Imager.diffraction_limited_peak``) for unit flux at this sampling;
    ``pixel_scale_arcsec`` [arcsec/pixel]. Criteria: ``strehl`` and ``d50`` of each
    noisy frame, then ``criteria_external`` (each (n_frames,)). With a ``reference``
    (:class:`ImageReference`, e.g. the on-axis star's frames), the image criteria and the
    recentring shifts come from it instead of from these frames, whose own per-frame
    Strehl, d50 and centroid are then not computed: ``frame_strehl``,
    ``frame_d50_arcsec`` and ``frame_centroid_px`` are NaN (their flux, the long
    exposures and ``frame_recentred_strehl`` are computed). ``registration``
    (:mod:`.registration`): where each frame is and how it is shifted (default ``cog``, the
    whole-frame centre of gravity and whole pixels); its positions are
    ``frame_registered_px`` (detector, frame, axis) (NaN: not registered, not shifted; their
    count ``unregistered_frames`` (detector)) and, for every method but ``cog``, a frame's d50
    is about its registered position. With ``matched_strehl`` (:class:`.scoring.MatchedStrehl`),
    a frame's Strehl (its criterion) is that of its matched-filtered peak, not of its brightest pixel.
    A noisy detector's every Strehl ratio is over the frames' expected flux (``photons_per_frame``
    times the noiseless frames' flux; module docstring).
    ``crop_px``: a sub-pixel method's crop (:mod:`.cropped`; default :func:`.cropped.crop_px`, 1.25").
    ``fourier_fractions``: Fourier lucky imaging too (:func:`run_lucky_methods`).

    Returns a CF-style :class:`xarray.Dataset`: ``strehl``, ``fwhm_arcsec``,
    ``d50_arcsec`` (criterion, fraction, detector) and the same of the noiseless frames
    with the same selection and shifts, ``strehl_noiseless``, ``fwhm_arcsec_noiseless``,
    ``d50_arcsec_noiseless``; ``long_exposure_strehl``,
    ``long_exposure_fwhm_arcsec``, ``long_exposure_d50_arcsec`` (recentring,
    detector); per-frame ``frame_strehl``, ``frame_d50_arcsec``,
    ``frame_centroid_px`` (detector, frame[, axis]), ``frame_criterion``
    (criterion, detector, frame) and ``frame_recentred_strehl`` (detector, frame); unless
    ``image_crop_px`` is 0, the central ``image_crop_px`` square (None: whole frame) of the
    integrated images normalised to unit flux, ``image`` (criterion, fraction, detector, y, x)
    and ``long_exposure_image`` (recentring, detector, y, x); with blocks, ``strehl_block``,
    ``fwhm_arcsec_block``, ``d50_arcsec_block`` (block, criterion, fraction, detector)
    and the errors ``strehl_error``, ``fwhm_arcsec_error``, ``d50_arcsec_error``. Attribute
    ``frames_drawn_again`` (per detector): the noisy frames drawn again in pass 2.
    """
    return run_lucky_methods(
        iter_chunks,
        n_frames,
        detectors,
        fractions,
        diffraction_limited_peak,
        pixel_scale_arcsec,
        seed,
        criteria_external,
        image_crop_px,
        None if reference is None else [reference],
        n_blocks,
        progress_interval_s,
        [registration],
        matched_strehl,
        crop_px,
        fourier_fractions,
    )[0]


def run_lucky_methods(
    iter_chunks: Chunks,
    n_frames: int,
    detectors: Sequence[Detector],
    fractions: Sequence[float],
    diffraction_limited_peak: float,
    pixel_scale_arcsec: float,
    seed: int,
    criteria_external: Sequence[ExternalCriterion] = (),
    image_crop_px: int | None = 64,
    references: Sequence[ImageReference] | None = None,
    n_blocks: int = 0,
    progress_interval_s: float = 5.0,
    registrations: Sequence[Registration] = (COG,),
    matched_strehl: MatchedStrehl | None = None,
    crop_px: int | None = None,
    fourier_fractions: Sequence[float] | None = None,
) -> list[xr.Dataset]:
    """:func:`run_lucky` of every registration method of ``registrations`` (distinct) in the same
    passes over the frames: each chunk is read and each detector's noise drawn once for all of
    them. ``references``: None, or one :class:`ImageReference` per method (that method's, e.g. the
    star's result of the same method). Returns one dataset per method, in order, each bit for bit
    that of :func:`run_lucky` with that method (and reference) alone. ``fourier_fractions``: each
    method's Fourier lucky imaging too (:mod:`.fourier`) at these fractions, on its registered
    frames' central ``image_crop_px`` square (0: :func:`.cropped.crop_px`'s), into each dataset's
    ``fourier_*`` variables (:func:`.fourier.add_fourier`); the other variables are unchanged bit for
    bit. Not with ``references``."""
    run = _LuckyRun(
        iter_chunks,
        n_frames,
        list(detectors),
        fractions,
        diffraction_limited_peak,
        pixel_scale_arcsec,
        seed,
        list(criteria_external),
        references,
        n_blocks,
        progress_interval_s,
        list(registrations),
        matched_strehl,
        crop_px,
        fourier_fractions,
        image_crop_px,
    )
    run.measure_noiseless()
    run.detect_and_add()
    run.move_guessed_wrong()
    return run.score(image_crop_px)


def _chunks(iter_chunks: Chunks, n_frames: int) -> Iterator[tuple[int, int, np.ndarray]]:
    """Validated chunks ``(start, k, frames as C-contiguous float32)``: contiguous, covering
    frames 0..n_frames-1, square frames."""
    expected = 0
    for start, frames in iter_chunks():
        frames = np.asarray(frames)
        if start != expected or frames.ndim != 3 or frames.shape[1] != frames.shape[2]:
            raise ValueError(f"chunk at {start} (expected {expected}), shape {frames.shape}")
        expected += len(frames)
        yield start, len(frames), np.ascontiguousarray(frames, dtype=np.float32)
    if expected != n_frames:
        raise ValueError(f"chunks cover {expected} frames, expected {n_frames}")


class _ChunkNoise:
    """The noisy detectors' :class:`KeyedNoise`, sized for the largest chunk, and its output buffer."""

    def __init__(self, detectors: Sequence[Detector]):
        self.needed = not all(d.noiseless for d in detectors)
        self.noise = self.buffer = None

    def prepare(self, unit: np.ndarray):
        """The chunk ready to detect (None without noisy detectors)."""
        if not self.needed:
            return None
        k, n = unit.shape[:2]
        if self.noise is None or self.noise.max_frames < k:
            self.noise = KeyedNoise(n, max(k, 64))
            self.buffer = empty_aligned((self.noise.max_frames, n, n), np.float32)  # transformed in place
        return self.noise.prepare(unit)


class _LuckyRun:
    """One :func:`run_lucky_methods`: the shared passes over the frames (each chunk read, each
    detector's noise drawn, the frames' flux, centre of gravity and Strehl measured once) and the
    methods' parts (:class:`.method_run.MethodRun`) they feed."""

    def __init__(
        self,
        iter_chunks: Chunks,
        n_frames: int,
        detectors: list[Detector],
        fractions,
        diffraction_limited_peak: float,
        pixel_scale_arcsec: float,
        seed: int,
        criteria_external: list[ExternalCriterion],
        references,
        n_blocks: int,
        progress_interval_s: float,
        registrations: list[Registration],
        matched_strehl: MatchedStrehl | None,
        crop_px: int | None,
        fourier_fractions=None,
        image_crop_px: int | None = 64,
    ):
        self.iter_chunks, self.n_frames, self.detectors, self.fractions = iter_chunks, n_frames, detectors, fractions
        self.peak, self.scale, self.seed, self.n_blocks = diffraction_limited_peak, pixel_scale_arcsec, seed, n_blocks
        self.criteria_external, self.progress_interval_s = criteria_external, progress_interval_s
        self.counts = fraction_counts(n_frames, fractions)
        self.criteria = list(IMAGE_CRITERIA) + [(c.name, bool(c.larger_is_better)) for c in criteria_external]
        self.larger = [larger for _, larger in self.criteria]
        _check(n_frames, detectors, criteria_external, registrations, references)
        if fourier_fractions is not None and references is not None:
            raise ValueError("Fourier lucky imaging needs the frames' own image criteria: not with references")
        self.matched_strehl, self.crop_px = matched_strehl, crop_px
        self.fourier_fractions, self.image_crop_px = fourier_fractions, image_crop_px
        self.methods = [
            MethodRun(self, registration, None if references is None else reference)
            for registration, reference in zip(registrations, references or registrations)
        ]
        self.guessing = any(m.guessing for m in self.methods)  # the same for every method
        self.noise = _ChunkNoise(detectors)
        self.long_none = self.encircled = self.clean = None
        # a noisy detector's frames' expected flux, N times the noiseless frame's (the Strehl's
        # flux, :func:`.metrics.strehl_flux`); NaN for a noiseless detector: its measured flux
        self.flux_estimate = np.full((len(detectors), n_frames), np.nan)
        # the spectra of a detector's frames and of the noiseless ones, each made once per chunk and shared
        self.detected, self.unit = FrameSpectra(), FrameSpectra()

    def fourier_crop_px(self, n_pixels: int) -> int:
        """Pixels across the Fourier lucky imaging's crop: the integrated images' (None: the whole
        frame; 0: :func:`.cropped.crop_px`'s)."""
        if self.image_crop_px is None:
            return n_pixels
        return min(n_pixels, self.image_crop_px or cropped.crop_px(n_pixels, self.scale))

    def _chunks(self, name: str) -> Iterator[tuple[slice, np.ndarray]]:
        """The frames' chunks ``(frames' slice, frames)``, the work arrays made at the first, with progress."""
        progress = Progress(f"lucky {name}", self.n_frames, self.progress_interval_s)
        for start, k, unit in _chunks(self.iter_chunks, self.n_frames):
            if self.encircled is None:
                self.encircled = EncircledEnergy(unit.shape[-1])
            yield slice(start, start + k), unit
            progress.update(start + k)

    def common_measures(self, spectra: FrameSpectra, rows, cols, peak, expected=None) -> tuple[np.ndarray, ...]:
        """Flux, centre of gravity and Strehl (of the brightest pixel, or matched-filtered) of the
        frames (k, n, n) of ``spectra`` from their row and column sums and peaks: the same for every
        method. The Strehl is over the frames' ``expected`` flux (k,) if given (a noisy detector's:
        :func:`.metrics.strehl_flux`), else over their measured flux."""
        flux = rows.sum(axis=1)
        if self.methods[0].frames.reference is not None:
            return flux, None, None
        centroids = centroid_from_sums(rows, cols, flux)
        over = flux if expected is None else expected
        if self.matched_strehl is not None:
            return flux, centroids, self.matched_strehl(spectra.frames, over, spectra)
        return flux, centroids, strehl_from(peak, over, self.peak)

    def measures(self, spectra: FrameSpectra, common: tuple[np.ndarray, ...]) -> list[tuple[np.ndarray, ...]]:
        """Every method's measures (:meth:`.MethodRun.measures`) of the frames of ``spectra`` whose
        flux, centre of gravity and Strehl are ``common``; the sub-pixel methods' radial sums about
        their registered positions all from one reading of each frame's spectrum
        (:meth:`.metrics.EncircledEnergy.radial_sums_about`)."""
        registered = [method.registered(spectra, common) for method in self.methods]
        about = [
            j
            for j, (method, r) in enumerate(zip(self.methods, registered))
            if method.registration.subpixel and r is not None
        ]
        radial = [None] * len(self.methods)
        if about:
            centres = np.stack([registered[j] for j in about], axis=1)  # (k, methods, 2)
            for j, sums in zip(
                about, self.encircled.radial_sums_about(spectra.frames, centres, spectra).transpose(1, 0, 2)
            ):
                radial[j] = sums
        return [method.measures(spectra, common, r, sums) for method, r, sums in zip(self.methods, registered, radial)]

    def measure_noiseless(self) -> None:
        """Pass 0 (guessing only): the noiseless frames' measures by every method, the guesses'
        predictor (and the noiseless detectors' measures)."""
        if not self.guessing:
            return
        n = self.n_frames
        clean = [tuple(np.full(shape, np.nan) for shape in (n, (n, 2), n, n, (n, 2))) for _ in self.methods]
        for sl, unit in self._chunks("pass 0/2: noiseless frames"):
            spectra = self.unit.reset(unit)
            common = self.common_measures(spectra, *frame_sums(unit))
            for whole, measured in zip(clean, self.measures(spectra, common)):
                for to, part in zip(whole, measured):
                    to[sl] = part
        for method, whole in zip(self.methods, clean):
            method.keep_noiseless(whole)
        self.clean = clean

    def detect_and_add(self) -> None:
        """Pass 1: each chunk's detected frames, drawn once per detector; the long exposure without
        recentring; every method's measures, shifts and partial sums (:meth:`.MethodRun.add_detected`)."""
        for method in self.methods:
            method.assign(method.early)
        for sl, unit in self._chunks("pass 1/2: frames"):
            k, n = unit.shape[:2]
            if self.long_none is None:
                self.long_none = np.zeros((len(self.detectors), n, n))
                for method in self.methods:
                    method.allocate(n, k)
            chunk, spectra_unit = self.noise.prepare(unit), self.unit.reset(unit)
            for i, detector in enumerate(self.detectors):
                if not detector.noiseless:
                    detected, rows, cols, peak = chunk.detect(detector, self.seed, sl.start, self.noise.buffer)
                    spectra = self.detected.reset(detected)
                    self.flux_estimate[i, sl] = detector.photons_per_frame * spectra_unit.flux()
                    common = self.common_measures(spectra, rows, cols, peak, self.flux_estimate[i, sl])
                    measures = self.measures(spectra, common)
                elif self.clean is not None:  # measured in pass 0
                    spectra = spectra_unit
                    measures = [[x[sl] for x in whole] for whole in self.clean]
                else:
                    spectra = spectra_unit
                    common = self.common_measures(spectra, *frame_sums(unit))
                    measures = self.measures(spectra, common)
                adds.add_frames(spectra.frames, self.long_none[i])
                for method, measured in zip(self.methods, measures):
                    method.add_detected(i, detector, sl, spectra, measured)
            for method in self.methods:
                method.add_noiseless(sl, spectra_unit)
                method.score_blocks(sl, method.early)

    def move_guessed_wrong(self) -> None:
        """Pass 2 (image criteria of the frames themselves): rank them; noiseless frames into their
        partial sums; a noisy detector's frames whose guessed bins were wrong, for any method, drawn
        again once (the same noise) and moved in each method's sums."""
        if not self.methods[0].late:  # the same for every method: with references, none
            return
        for method in self.methods:
            method.rank_late()
            if method.fourier is not None:
                method.fourier.rank()
        for sl, unit in self._chunks("pass 2/2: frames"):
            chunk, spectra_unit = self.noise.prepare(unit), self.unit.reset(unit)
            for i, detector in enumerate(self.detectors):
                if detector.noiseless:
                    for method in self.methods:
                        method.add_noiseless_detector(i, sl, spectra_unit)
                        method.add_fourier(i, sl, None, spectra_unit)
                    continue
                wrong = [method.guessed_wrong(i, sl) for method in self.methods]
                drawn = np.logical_or.reduce([w[2] for w in wrong])
                if self.fourier_fractions is not None:
                    drawn[:] = True  # the Fourier sums take every frame
                if not drawn.any():
                    continue
                detected, rows, _, _ = chunk.detect(detector, self.seed, sl.start, self.noise.buffer, drawn)
                spectra = self.detected.reset(detected)  # only the frames drawn are transformed
                for method, w in zip(self.methods, wrong):
                    method.move(i, sl, spectra, rows, spectra_unit, w)
                    method.add_fourier(i, sl, spectra, spectra_unit, rows)
            for method in self.methods:
                method.score_blocks(sl, method.late)
        if self.guessing:
            for method in self.methods:
                log.info(
                    "lucky pass 2/2 (%s): frames drawn again (guessed bins wrong) per noisy detector: %s",
                    method.registration.name,
                    ", ".join(
                        f"{d.name} {n / self.n_frames:.1%}"
                        for d, n in zip(self.detectors, method.drawn_again)
                        if not d.noiseless
                    ),
                )

    def score(self, image_crop_px: int | None) -> list[xr.Dataset]:
        """Each method's dataset (:meth:`.MethodRun.score`), one method's integrated images at a time."""
        return [method.score(self.long_none, image_crop_px) for method in self.methods]


def _check(n_frames: int, detectors: list[Detector], criteria_external, registrations, references) -> None:
    """Refuse external criteria or references of the wrong shape or number, equal detector names and
    repeated or no registration methods."""
    for c in criteria_external:
        if np.shape(c.values) != (n_frames,):
            raise ValueError(f"criterion {c.name}: values must have shape ({n_frames},)")
    n_det = len(detectors)
    names = [d.name for d in detectors]
    if len(set(names)) != n_det or len({detector_key(name) for name in names}) != n_det:
        raise ValueError(f"detector names must be distinct (and their crc32 too): {names}")
    methods = [r.name for r in registrations]
    if not methods or len(set(methods)) != len(methods):
        raise ValueError(f"registrations must be distinct methods, at least one: {methods}")
    if references is not None and len(references) != len(registrations):
        raise ValueError(f"references: {len(references)} for {len(registrations)} registration methods (one each)")
    for reference in references or ():
        if (
            np.shape(reference.centroid_px) != (n_det, n_frames, 2)
            or np.shape(reference.strehl) != (n_det, n_frames)
            or np.shape(reference.d50_arcsec) != (n_det, n_frames)
        ):
            raise ValueError(
                f"reference: centroids {np.shape(reference.centroid_px)} and criteria "
                f"{np.shape(reference.strehl)} do not match (detector, frame) = {(n_det, n_frames)}"
            )
