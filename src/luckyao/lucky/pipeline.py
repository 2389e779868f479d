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

Alongside, the noiseless frames (the input, as float32) get the same detector's shifts
and the same bins into a second set of partial sums: the ``*_noiseless`` scores separate a
wrong selection or recentring from the noise in the final image. The sums are float64
throughout, frame by frame (:func:`.kernels.add_recentred`); a noiseless detector's second
set is its first, copied, so its ``*_noiseless`` values equal the others bit for bit.
Memory: the two sets of partial sums, float64 (2 x detectors x criteria x distinct counts x
n x n), plus a chunk's work arrays (~1 kB per pixel and frame of a chunk) and, when scoring,
the integrated images (criteria x fractions x detectors x n x n) of one set at a time (the
cumulative sums are made in place).

Monte-Carlo errors (``n_blocks`` >= 2): the frames are cut into ``n_blocks`` time blocks of
``n_frames // n_blocks`` frames (the remainder left out), each block is selected, recentred
and scored on its own as a short run (the same fractions of its frames, ranked within it),
and the standard error of a value is the standard deviation of its block values over
``sqrt(n_blocks)`` (batch means: the blocks are independent when longer than the
turbulence's correlation time; compare ``tests/test_errors.py``). The blocks' partial sums
are extra rows of the same sums (:class:`.accumulation.PartialSums`), scored and cleared
after the chunk that ends the block; with guessed bins, the image criteria's rows of every
block stay until pass 2 (detectors x 2 x blocks x distinct counts x n x n float64: 1.7 GB
for the paper's sweep).
"""

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..progress import Progress, log
from ..seeds import detector_key
from . import kernels
from .accumulation import PartialSums, TimeBlocks, axis_window, recentring_shifts_px, window_values
from .dataset import (add_block_scores, add_images, add_noiseless_scores, add_recentred_strehl, add_registration,
                      result_dataset)
from .detector import Detector, KeyedNoise
from .guesses import GuessedBins
from .metrics import EncircledEnergy, centroid_from_sums, score_images
from .ranking import IMAGE_CRITERIA, ExternalCriterion, criterion_bins, fraction_counts
from .registration import COG, Registration, fourier_shift, shifts_of
from .scoring import MatchedStrehl, frame_sums, measure_frames, score_partial_sums, value_at_peak

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


def run_lucky(iter_chunks: Chunks, n_frames: int, detectors: Sequence[Detector], fractions: Sequence[float],
              diffraction_limited_peak: float, pixel_scale_arcsec: float, seed: int,
              criteria_external: Sequence[ExternalCriterion] = (),
              image_crop_px: int | None = 64, reference: ImageReference | None = None,
              n_blocks: int = 0, progress_interval_s: float = 5.0,
              registration: Registration = COG, matched_strehl: MatchedStrehl | None = None) -> xr.Dataset:
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
    run = _LuckyRun(iter_chunks, n_frames, list(detectors), fractions, diffraction_limited_peak,
                    pixel_scale_arcsec, seed, list(criteria_external), reference, n_blocks, progress_interval_s,
                    registration, matched_strehl)
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
            self.buffer = np.empty((self.noise.max_frames, n, n), np.float32)
        return self.noise.prepare(unit)


class _FrameValues:
    """Per detector and frame: flux, centre of gravity, registered position, Strehl, d50 [pixel],
    recentring shift (whole pixels and the sub-pixel remainder) and the recentred frame's values
    in the window around the axis."""

    def __init__(self, n_det: int, n_frames: int, reference: ImageReference | None, registration: Registration):
        self.strehl = np.full((n_det, n_frames), np.nan)
        self.d50_px = np.full((n_det, n_frames), np.nan)
        self.centroid = np.full((n_det, n_frames, 2), np.nan)
        self.registered = np.full((n_det, n_frames, 2), np.nan)
        self.flux = np.full((n_det, n_frames), np.nan)
        self.reference, self.registration = reference, registration
        self.shifts = self.remainder = self.window = self.in_window = self.buffer = None
        self.n_pixels = 0

    def allocate(self, n_pixels: int) -> None:
        n_det, n_frames = self.flux.shape
        self.n_pixels = n_pixels
        self.window = axis_window(n_pixels)  # 7 x 7 pixels around the axis
        self.in_window = np.empty((n_det, n_frames, self.window.size), dtype=np.float32)
        self.remainder = np.zeros((n_det, n_frames, 2))
        if self.reference is not None:
            self.registered[:] = self.reference.centroid_px
            self.shifts, self.remainder[:] = shifts_of(self.registered, n_pixels, self.registration.subpixel)
        else:
            self.shifts = np.zeros((n_det, n_frames, 2), dtype=np.int64)

    def d50_arcsec(self, pixel_scale_arcsec: float) -> np.ndarray:
        return self.d50_px * pixel_scale_arcsec

    def record(self, i: int, sl: slice, measures: Sequence[np.ndarray]) -> None:
        """Detector ``i``'s frames ``sl``: their flux and, without a reference, their measures
        (:meth:`_LuckyRun._measured`) and shifts."""
        self.flux[i, sl] = measures[0]
        if self.reference is None:
            centroids, self.strehl[i, sl], self.d50_px[i, sl], registered = measures[1:]
            self.centroid[i, sl], self.registered[i, sl] = centroids, registered
            if self.registration.subpixel:
                self.shifts[i, sl], self.remainder[i, sl] = shifts_of(registered, self.n_pixels, True)
            else:
                self.shifts[i, sl] = recentring_shifts_px(centroids, self.n_pixels)

    def shifted(self, frames: np.ndarray, i: int, sl: slice, which: np.ndarray | None = None,
                slot: int = 0) -> np.ndarray:
        """Frames ``sl`` of detector ``i`` (k, n, n) shifted by their sub-pixel remainders
        (:func:`.registration.fourier_shift`; the frames themselves when every remainder is 0),
        those of ``which`` (k,) bool only (the others' values undefined), in buffer ``slot``
        (0 or 1: valid until that slot's next use)."""
        remainder = self.remainder[i, sl]
        moving = np.any(remainder != 0, axis=1)
        if which is not None:
            moving &= which
        if not moving.any():
            return frames
        k = len(frames)
        if self.buffer is None or self.buffer.shape[1] < k:
            self.buffer = np.empty((2, *frames.shape), np.float32)
        out = self.buffer[slot, :k]
        out[~moving] = frames[~moving]
        out[moving] = fourier_shift(frames[moving], remainder[moving])
        return out

    def unregistered(self) -> np.ndarray:
        """Frames (per detector) not registered (no position, no shift): no flux, or no peak."""
        return np.count_nonzero(~np.isfinite(self.registered).all(axis=2), axis=1)


class _LuckyRun:
    """One :func:`run_lucky`: its criteria, bins, partial sums and per-frame values, and its passes."""

    def __init__(self, iter_chunks: Chunks, n_frames: int, detectors: list[Detector], fractions,
                 diffraction_limited_peak: float, pixel_scale_arcsec: float, seed: int,
                 criteria_external: list[ExternalCriterion], reference: ImageReference | None, n_blocks: int,
                 progress_interval_s: float, registration: Registration, matched_strehl: MatchedStrehl | None):
        self.iter_chunks, self.n_frames, self.detectors, self.fractions = iter_chunks, n_frames, detectors, fractions
        self.peak, self.scale, self.seed = diffraction_limited_peak, pixel_scale_arcsec, seed
        self.criteria_external, self.progress_interval_s = criteria_external, progress_interval_s
        self.counts = fraction_counts(n_frames, fractions)
        self.criteria = list(IMAGE_CRITERIA) + [(c.name, bool(c.larger_is_better)) for c in criteria_external]
        self.larger = [larger for _, larger in self.criteria]
        n_det, n_crit = len(detectors), len(self.criteria)
        _check(n_frames, detectors, criteria_external, reference)
        # criteria known before the frames are read: the external ones, and with a reference
        # the image ones too; their bins (and the reference's shifts) serve pass 1
        self.values = np.full((n_crit, n_det, n_frames), np.nan)  # (criterion, detector, frame)
        for j, c in enumerate(criteria_external):
            self.values[2 + j] = np.asarray(c.values, dtype=np.float64)[None, :]
        if reference is not None:
            self.values[0], self.values[1] = reference.strehl, reference.d50_arcsec
        self.early = list(range(2 if reference is None else 0, n_crit))  # criteria binned before pass 1
        self.late = [c for c in range(n_crit) if c not in self.early]  # the image criteria of the frames themselves
        self.bins = np.full((n_det, n_crit, n_frames), -1, dtype=np.int64)  # run bins (detector, criterion, frame)
        # a noisy detector's frames are added to guessed bins of the late criteria in pass 1
        self.guessing = bool(self.late) and not all(d.noiseless for d in detectors)
        self.blocks = TimeBlocks(n_frames, n_blocks, fractions, n_det, n_crit)
        self.sums = PartialSums(n_det, n_crit, self.counts, self.blocks, resident=self.late if self.guessing else ())
        self.registration, self.matched_strehl = registration, matched_strehl
        self.frames = _FrameValues(n_det, n_frames, reference, registration)
        self.noise = _ChunkNoise(detectors)
        self.long_none = self.encircled = self.clean = self.guessed = None
        self.drawn_again = np.zeros(n_det, dtype=np.int64)

    def _chunks(self, name: str) -> Iterator[tuple[slice, np.ndarray]]:
        """The frames' chunks ``(frames' slice, frames)``, the work arrays made at the first, with progress."""
        progress = Progress(f"lucky {name}", self.n_frames, self.progress_interval_s)
        for start, k, unit in _chunks(self.iter_chunks, self.n_frames):
            if self.encircled is None:
                self.encircled = EncircledEnergy(unit.shape[-1])
            yield slice(start, start + k), unit
            progress.update(start + k)

    def _assign(self, crits) -> None:
        """Run and block bins of criteria ``crits`` from their values."""
        for i in range(len(self.detectors)):
            for c in crits:
                self.bins[i, c] = criterion_bins(self.values[c, i], self.larger[c], self.counts)
        self.blocks.assign(self.values, self.larger, crits)

    def _measured(self, frames, rows, cols, peak) -> tuple[np.ndarray, ...]:
        """The frames' measures (:func:`measure_frames` and the registered positions), or with a
        reference only their flux."""
        if self.frames.reference is not None:
            return (rows.sum(axis=1),)
        return self._measures(frames, rows, cols, peak)

    def _measures(self, frames, rows, cols, peak) -> tuple[np.ndarray, ...]:
        """Flux, centre of gravity, Strehl (of the brightest pixel, or matched-filtered), d50 [pixel]
        (about the registered position but with ``cog``) and registered position of frames (k, n, n)."""
        registration = self.registration
        if not registration.subpixel:
            measures = measure_frames(frames, rows, cols, peak, self.encircled, self.peak)
            registered = measures[1]
        else:
            flux = rows.sum(axis=1)
            registered = registration.positions_px(frames, centroid_from_sums(rows, cols, flux))
            measures = measure_frames(frames, rows, cols, peak, self.encircled, self.peak, centres_px=registered)
        if self.matched_strehl is not None:
            measures = (measures[0], measures[1], self.matched_strehl(frames, measures[0]), measures[3])
        return (*measures, registered)

    def measure_noiseless(self) -> None:
        """Pass 0 (guessing only): the noiseless frames' measures, the guesses' predictor (and the
        noiseless detectors' measures)."""
        if not self.guessing:
            return
        n = self.n_frames
        clean = tuple(np.full(shape, np.nan) for shape in (n, (n, 2), n, n, (n, 2)))
        for sl, unit in self._chunks("pass 0/2: noiseless frames"):
            for whole, part in zip(clean, self._measures(unit, *frame_sums(unit))):
                whole[sl] = part
        self.clean = clean
        self.guessed = GuessedBins(self.bins.shape, self.counts, self.blocks, {
            0: (clean[2], self.larger[0]), 1: (clean[3], self.larger[1])})

    def detect_and_add(self) -> None:
        """Pass 1: detected frames, per-frame measures and shifts, the long exposures; the frames
        added to the bins of the criteria binned early and, for noisy detectors, to guessed bins."""
        sums, early, late, guessed, frames = self.sums, self.early, self.late, self.guessed, self.frames
        self._assign(early)
        for sl, unit in self._chunks("pass 1/2: frames"):
            k, n = unit.shape[:2]
            if self.long_none is None:
                self.long_none = np.zeros((len(self.detectors), n, n))
                sums.allocate(n, k)
                frames.allocate(n)
            chunk = self.noise.prepare(unit)
            for i, detector in enumerate(self.detectors):
                if not detector.noiseless:
                    detected, rows, cols, peak = chunk.detect(detector, self.seed, sl.start, self.noise.buffer)
                    frames.record(i, sl, self._measured(detected, rows, cols, peak))
                elif self.clean is not None:  # measured in pass 0
                    detected = unit
                    frames.record(i, sl, [x[sl] for x in self.clean])
                else:
                    detected = unit
                    frames.record(i, sl, self._measured(unit, *frame_sums(unit)))
                kernels.add_frames(detected, self.long_none[i])
                shifts = frames.shifts[i, sl]
                detected = frames.shifted(detected, i, sl)  # the sub-pixel part of the shifts
                # the early criteria and the recentred long exposure: shifts known now
                rows_early = np.concatenate([sums.run_rows(early, self.bins[i, early, sl]),
                                             np.full((k, 1), sums.long_exposure_row)], axis=1)  # (k, early + 1)
                rows_block = sums.block_rows(early, sl, self.blocks.bins[i, early, sl])
                rows_guessed = rows_guessed_block = np.empty((k, 0), dtype=np.int64)
                if guessed is not None and not detector.noiseless:
                    for c, per_frame in zip(late, (frames.strehl[i, sl], frames.d50_px[i, sl])):
                        guessed.guess(i, c, sl, per_frame, self.larger[c])
                    rows_guessed = sums.run_rows(late, guessed.run[i, late, sl])
                    rows_guessed_block = sums.block_rows(late, sl, guessed.block[i, late, sl])
                kernels.add_recentred(detected, shifts, np.concatenate(
                    [rows_early, rows_block, rows_guessed, rows_guessed_block], axis=1), sums.detected_rows[i], 1.0)
                if not detector.noiseless:  # a noiseless detector's noiseless sums are its sums (copied when scoring)
                    kernels.add_recentred(frames.shifted(unit, i, sl, slot=1), shifts, np.concatenate(
                        [rows_early[:, :-1], rows_guessed], axis=1), sums.noiseless_rows[i], 1.0)
                window_values(detected, shifts, frames.window, frames.in_window[i, sl])
            self._score_blocks(sl, early)

    def move_guessed_wrong(self) -> None:
        """Pass 2 (image criteria of the frames themselves): rank them; noiseless frames into their
        partial sums; a noisy detector's frames whose guessed bins were wrong drawn again (the same
        noise) and moved."""
        late, sums, frames, guessed = self.late, self.sums, self.frames, self.guessed
        if not late:
            return
        self.values[0], self.values[1] = frames.strehl, frames.d50_arcsec(self.scale)
        self._assign(late)
        for sl, unit in self._chunks("pass 2/2: frames"):
            chunk = self.noise.prepare(unit)
            for i, detector in enumerate(self.detectors):
                shifts = frames.shifts[i, sl]
                final_rows = np.concatenate([sums.run_rows(late, self.bins[i, late, sl]),
                                             sums.block_rows(late, sl, self.blocks.bins[i, late, sl])], axis=1)
                if detector.noiseless:
                    kernels.add_recentred(frames.shifted(unit, i, sl), shifts, final_rows, sums.detected_rows[i], 1.0)
                    continue
                guessed_rows = np.concatenate([sums.run_rows(late, guessed.run[i, late, sl]),
                                               sums.block_rows(late, sl, guessed.block[i, late, sl])], axis=1)
                moved = final_rows != guessed_rows  # (k, late [+ late]): rows differ where bins do
                drawn = moved.any(axis=1)
                if not drawn.any():
                    continue
                self.drawn_again[i] += np.count_nonzero(drawn)
                detected, rows, _, _ = chunk.detect(detector, self.seed, sl.start, self.noise.buffer, drawn)
                if not np.array_equal(rows[drawn].sum(axis=1), frames.flux[i, sl][drawn]):
                    raise RuntimeError(f"frames {sl.start}.. differ between the two passes")
                out_of, into = np.where(moved, guessed_rows, -1), np.where(moved, final_rows, -1)
                for slot, (frames_of, partial, m) in enumerate(((detected, sums.detected_rows[i], moved.shape[1]),
                                                                (unit, sums.noiseless_rows[i], len(late)))):
                    frames_of = frames.shifted(frames_of, i, sl, drawn, slot)
                    kernels.add_recentred(frames_of, shifts, out_of[:, :m], partial, -1.0)
                    kernels.add_recentred(frames_of, shifts, into[:, :m], partial, 1.0)
            self._score_blocks(sl, late)
        if guessed is not None:
            log.info("lucky pass 2/2: frames drawn again (guessed bins wrong) per noisy detector: %s", ", ".join(
                f"{d.name} {n / self.n_frames:.1%}" for d, n in zip(self.detectors, self.drawn_again)
                if not d.noiseless))

    def _score_blocks(self, sl: slice, crits) -> None:
        """Score the rows of criteria ``crits`` (contiguous) of every block the chunk ``sl`` completes."""
        blocks = self.blocks
        for block, rows in self.sums.completed_blocks(sl, crits):
            _, *scores = score_partial_sums(rows, len(crits), blocks.n_bins, blocks.last_bin, self.encircled,
                                            self.peak, self.scale)
            for values, score in zip(blocks.values, scores):
                values[block, crits[0]:crits[-1] + 1] = score

    def score(self, image_crop_px: int | None) -> xr.Dataset:
        """Score the integrated images (cumulative sums of bins) and the long exposures: the dataset."""
        sums, frames, n_crit = self.sums, self.frames, len(self.criteria)
        lc = sums.long_exposure_row
        long_cog = sums.detected[:, lc]
        frame_recentred_strehl = value_at_peak(frames.in_window, frames.window, long_cog, frames.flux, self.peak)
        scoring = (n_crit, sums.n_bins, sums.last_bin, self.encircled, self.peak, self.scale)
        for i, detector in enumerate(self.detectors):
            if detector.noiseless:
                sums.noiseless[i] = sums.detected[i, :lc]
        noiseless_scores = score_partial_sums(sums.noiseless, *scoring)[1:]
        sums.noiseless = sums.noiseless_rows = None
        long_images = np.stack([self.long_none, long_cog])  # (recentring, det, n, n)
        images, *run_scores = score_partial_sums(sums.detected[:, :lc], *scoring)
        sums.detected = sums.detected_rows = long_cog = None
        long_scores = score_images(long_images, self.peak, self.scale, self.encircled)
        ds = result_dataset(self.detectors, self.criteria, self.criteria_external, self.fractions, self.counts,
                            self.n_frames, *run_scores, *long_scores, frames.strehl, frames.d50_arcsec(self.scale),
                            frames.centroid, self.values)
        add_noiseless_scores(ds, *noiseless_scores)
        add_block_scores(ds, self.blocks)
        add_recentred_strehl(ds, frame_recentred_strehl)
        add_registration(ds, self.registration.name, frames.registered, frames.unregistered())
        if image_crop_px != 0:
            ds = add_images(ds, images, long_images, image_crop_px)
        ds.attrs.update(pixel_scale_arcsec=self.scale, diffraction_limited_peak=self.peak, seed=self.seed,
                        n_pixels=frames.n_pixels, frames_drawn_again=self.drawn_again)
        return ds


def _check(n_frames: int, detectors: list[Detector], criteria_external, reference) -> None:
    """Refuse external criteria or a reference of the wrong shape, and equal detector names."""
    for c in criteria_external:
        if np.shape(c.values) != (n_frames,):
            raise ValueError(f"criterion {c.name}: values must have shape ({n_frames},)")
    n_det = len(detectors)
    names = [d.name for d in detectors]
    if len(set(names)) != n_det or len({detector_key(name) for name in names}) != n_det:
        raise ValueError(f"detector names must be distinct (and their crc32 too): {names}")
    if reference is not None and (np.shape(reference.centroid_px) != (n_det, n_frames, 2)
                                  or np.shape(reference.strehl) != (n_det, n_frames)
                                  or np.shape(reference.d50_arcsec) != (n_det, n_frames)):
        raise ValueError(f"reference: centroids {np.shape(reference.centroid_px)} and criteria "
                         f"{np.shape(reference.strehl)} do not match (detector, frame) = {(n_det, n_frames)}")
