"""One registration method's part of a lucky run (:func:`.pipeline.run_lucky_methods`).

The passes over the frames (reading them, drawing each detector's noise) are shared by the
registration methods of a run; what depends on the method is here, one :class:`MethodRun`
per method: the frames' registered positions and shifts, their d50 (about the registered
position), the image criteria's values and bins (ranked, or guessed in pass 1), the time
blocks, and the partial sums of the detected and of the noiseless frames. Each method's
sums receive exactly the operations, in the same order, that a run of that method alone
gives them, so its results are bit for bit those of a run of its own.
"""

from collections.abc import Sequence

import numpy as np
import xarray as xr

from . import kernels
from .accumulation import PartialSums, TimeBlocks, axis_window, recentring_shifts_px, window_values
from .dataset import (add_block_scores, add_images, add_noiseless_scores, add_recentred_strehl, add_registration,
                      result_dataset)
from .detector import Detector
from .guesses import GuessedBins
from .metrics import d50_from_radius, score_images
from .ranking import criterion_bins
from .registration import FrameSpectra, Registration, shifts_of
from .scoring import score_partial_sums, value_at_peak


class FrameValues:
    """Per detector and frame: flux, centre of gravity, registered position, Strehl, d50 [pixel],
    recentring shift (whole pixels and the sub-pixel remainder) and the recentred frame's values
    in the window around the axis."""

    def __init__(self, n_det: int, n_frames: int, reference, registration: Registration):
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
        (:meth:`MethodRun.measures`) and shifts."""
        self.flux[i, sl] = measures[0]
        if self.reference is None:
            centroids, self.strehl[i, sl], self.d50_px[i, sl], registered = measures[1:]
            self.centroid[i, sl], self.registered[i, sl] = centroids, registered
            if self.registration.subpixel:
                self.shifts[i, sl], self.remainder[i, sl] = shifts_of(registered, self.n_pixels, True)
            else:
                self.shifts[i, sl] = recentring_shifts_px(centroids, self.n_pixels)

    def shifted(self, spectra: FrameSpectra, i: int, sl: slice, which: np.ndarray | None = None,
                slot: int = 0) -> np.ndarray:
        """Frames ``sl`` of detector ``i`` (k, n, n) (held by ``spectra``, :class:`.registration.FrameSpectra`)
        shifted by their sub-pixel remainders (:func:`.registration.fourier_shift`; the frames
        themselves when every remainder is 0), those of ``which`` (k,) bool only (the others' values
        undefined), in buffer ``slot`` (0 or 1: valid until that slot's next use)."""
        frames = spectra.frames
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
        return spectra.shifted(np.flatnonzero(moving), remainder[moving], out)

    def unregistered(self) -> np.ndarray:
        """Frames (per detector) not registered (no position, no shift): no flux, or no peak."""
        return np.count_nonzero(~np.isfinite(self.registered).all(axis=2), axis=1)


class MethodRun:
    """One registration method's values, bins, partial sums and steps of the shared passes.

    ``run``: the shared run (:class:`.pipeline._LuckyRun`), whose frame count, detectors,
    criteria, fractions, time blocks' count, Strehl reference, pixel scale and encircled-energy
    measure it reads; ``reference``: the :class:`.pipeline.ImageReference` of this method, or None.
    """

    def __init__(self, run, registration: Registration, reference):
        self.run, self.registration = run, registration
        n_frames, criteria_external = run.n_frames, run.criteria_external
        n_det, n_crit = len(run.detectors), len(run.criteria)
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
        self.guessing = bool(self.late) and not all(d.noiseless for d in run.detectors)
        self.blocks = TimeBlocks(n_frames, run.n_blocks, run.fractions, n_det, n_crit)
        self.sums = PartialSums(n_det, n_crit, run.counts, self.blocks, resident=self.late if self.guessing else ())
        self.frames = FrameValues(n_det, n_frames, reference, registration)
        self.clean = self.guessed = None
        self.drawn_again = np.zeros(n_det, dtype=np.int64)

    def assign(self, crits) -> None:
        """Run and block bins of criteria ``crits`` from their values."""
        larger, counts = self.run.larger, self.run.counts
        for i in range(len(self.run.detectors)):
            for c in crits:
                self.bins[i, c] = criterion_bins(self.values[c, i], larger[c], counts)
        self.blocks.assign(self.values, larger, crits)

    def measures(self, spectra: FrameSpectra, common: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """Flux, centre of gravity, Strehl, d50 [pixel] (about the registered position; the centre
        of gravity with ``cog``) and registered position of the frames (k, n, n) of ``spectra``
        whose flux, centre of gravity and Strehl are ``common``
        (:meth:`.pipeline._LuckyRun.common_measures`: they do not depend on the method); with a
        reference, their flux only."""
        flux, centroids, strehl = common
        if self.frames.reference is not None:
            return (flux,)
        frames = spectra.frames
        registered = self.registration.positions_px(frames, centroids, spectra)
        radius = self.run.encircled.radius_px_binned(frames, registered, flux=flux, spectra=spectra)
        return flux, centroids, strehl, d50_from_radius(radius, 1.0), registered

    def keep_noiseless(self, clean: tuple[np.ndarray, ...]) -> None:
        """Pass 0's measures of the noiseless frames (:meth:`measures` of all frames): the guesses' predictor."""
        self.clean = clean
        larger = self.run.larger
        self.guessed = GuessedBins(self.bins.shape, self.run.counts, self.blocks, {
            0: (clean[2], larger[0]), 1: (clean[3], larger[1])})

    def allocate(self, n_pixels: int, chunk_frames: int) -> None:
        """The partial sums and per-frame arrays, once the first chunk gives their sizes."""
        self.sums.allocate(n_pixels, chunk_frames)
        self.frames.allocate(n_pixels)

    def add_detected(self, i: int, detector: Detector, sl: slice, detected: FrameSpectra, unit: FrameSpectra,
                     measures: Sequence[np.ndarray]) -> None:
        """Pass 1, detector ``i``'s frames ``sl`` (``detected``, and the noiseless ones ``unit``: their
        :class:`.registration.FrameSpectra`): their measures recorded, the frames recentred into the
        sums of the criteria binned early, the recentred long exposure and, for a noisy detector,
        the guessed bins of the late criteria."""
        sums, early, late, guessed, frames = self.sums, self.early, self.late, self.guessed, self.frames
        k = sl.stop - sl.start
        frames.record(i, sl, measures)
        shifts = frames.shifts[i, sl]
        detected = frames.shifted(detected, i, sl)  # the sub-pixel part of the shifts
        # the early criteria and the recentred long exposure: shifts known now
        rows_early = np.concatenate([sums.run_rows(early, self.bins[i, early, sl]),
                                     np.full((k, 1), sums.long_exposure_row)], axis=1)  # (k, early + 1)
        rows_block = sums.block_rows(early, sl, self.blocks.bins[i, early, sl])
        rows_guessed = rows_guessed_block = np.empty((k, 0), dtype=np.int64)
        if guessed is not None and not detector.noiseless:
            for c, per_frame in zip(late, (frames.strehl[i, sl], frames.d50_px[i, sl])):
                guessed.guess(i, c, sl, per_frame, self.run.larger[c])
            rows_guessed = sums.run_rows(late, guessed.run[i, late, sl])
            rows_guessed_block = sums.block_rows(late, sl, guessed.block[i, late, sl])
        kernels.add_recentred(detected, shifts, np.concatenate(
            [rows_early, rows_block, rows_guessed, rows_guessed_block], axis=1), sums.detected_rows[i], 1.0)
        if not detector.noiseless:  # a noiseless detector's noiseless sums are its sums (copied when scoring)
            kernels.add_recentred(frames.shifted(unit, i, sl, slot=1), shifts, np.concatenate(
                [rows_early[:, :-1], rows_guessed], axis=1), sums.noiseless_rows[i], 1.0)
        window_values(detected, shifts, frames.window, frames.in_window[i, sl])

    def rank_late(self) -> None:
        """Pass 2's start: the late criteria's values from the frames' measures, ranked."""
        self.values[0], self.values[1] = self.frames.strehl, self.frames.d50_arcsec(self.run.scale)
        self.assign(self.late)

    def add_noiseless_detector(self, i: int, sl: slice, unit: FrameSpectra) -> None:
        """Pass 2, a noiseless detector ``i``'s frames ``sl`` (``unit``): into their late criteria's bins."""
        late, sums = self.late, self.sums
        final_rows = np.concatenate([sums.run_rows(late, self.bins[i, late, sl]),
                                     sums.block_rows(late, sl, self.blocks.bins[i, late, sl])], axis=1)
        kernels.add_recentred(self.frames.shifted(unit, i, sl), self.frames.shifts[i, sl], final_rows,
                              sums.detected_rows[i], 1.0)

    def guessed_wrong(self, i: int, sl: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pass 2, a noisy detector ``i``'s frames ``sl``: the rows (k, late [+ late]) of their final
        and guessed bins, and which frames (k,) are in a wrong one (to draw again and move)."""
        late, sums, guessed = self.late, self.sums, self.guessed
        final_rows = np.concatenate([sums.run_rows(late, self.bins[i, late, sl]),
                                     sums.block_rows(late, sl, self.blocks.bins[i, late, sl])], axis=1)
        guessed_rows = np.concatenate([sums.run_rows(late, guessed.run[i, late, sl]),
                                       sums.block_rows(late, sl, guessed.block[i, late, sl])], axis=1)
        return final_rows, guessed_rows, (final_rows != guessed_rows).any(axis=1)

    def move(self, i: int, sl: slice, detected: FrameSpectra, detected_rows: np.ndarray, unit: FrameSpectra,
             wrong: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Pass 2: detector ``i``'s frames ``sl`` guessed ``wrong`` (:meth:`guessed_wrong`), drawn
        again (``detected`` and its row sums ``detected_rows``, valid for those frames), moved from
        their guessed bins to their final ones (detected, and noiseless ``unit``)."""
        final_rows, guessed_rows, drawn = wrong
        if not drawn.any():
            return
        sums, frames = self.sums, self.frames
        self.drawn_again[i] += np.count_nonzero(drawn)
        if not np.array_equal(detected_rows[drawn].sum(axis=1), frames.flux[i, sl][drawn]):
            raise RuntimeError(f"frames {sl.start}.. differ between the two passes")
        shifts = frames.shifts[i, sl]
        moved = final_rows != guessed_rows  # (k, late [+ late]): rows differ where bins do
        out_of, into = np.where(moved, guessed_rows, -1), np.where(moved, final_rows, -1)
        for slot, (frames_of, partial, m) in enumerate(((detected, sums.detected_rows[i], moved.shape[1]),
                                                        (unit, sums.noiseless_rows[i], len(self.late)))):
            frames_of = frames.shifted(frames_of, i, sl, drawn, slot)
            kernels.add_recentred(frames_of, shifts, out_of[:, :m], partial, -1.0)
            kernels.add_recentred(frames_of, shifts, into[:, :m], partial, 1.0)

    def score_blocks(self, sl: slice, crits) -> None:
        """Score the rows of criteria ``crits`` (contiguous) of every block the chunk ``sl`` completes."""
        blocks, run = self.blocks, self.run
        for block, rows in self.sums.completed_blocks(sl, crits):
            _, *scores = score_partial_sums(rows, len(crits), blocks.n_bins, blocks.last_bin, run.encircled,
                                            run.peak, run.scale)
            for values, score in zip(blocks.values, scores):
                values[block, crits[0]:crits[-1] + 1] = score

    def score(self, long_none: np.ndarray, image_crop_px: int | None) -> xr.Dataset:
        """Score the integrated images (cumulative sums of bins) and the long exposures (``long_none``,
        without recentring, shared by the methods): the method's dataset. Frees its partial sums."""
        run, sums, frames = self.run, self.sums, self.frames
        n_crit = len(run.criteria)
        lc = sums.long_exposure_row
        long_cog = sums.detected[:, lc]
        frame_recentred_strehl = value_at_peak(frames.in_window, frames.window, long_cog, frames.flux, run.peak)
        scoring = (n_crit, sums.n_bins, sums.last_bin, run.encircled, run.peak, run.scale)
        for i, detector in enumerate(run.detectors):
            if detector.noiseless:
                sums.noiseless[i] = sums.detected[i, :lc]
        noiseless_scores = score_partial_sums(sums.noiseless, *scoring)[1:]
        sums.noiseless = sums.noiseless_rows = None
        long_images = np.stack([long_none, long_cog])  # (recentring, det, n, n)
        images, *run_scores = score_partial_sums(sums.detected[:, :lc], *scoring)
        sums.detected = sums.detected_rows = long_cog = None
        long_scores = score_images(long_images, run.peak, run.scale, run.encircled)
        ds = result_dataset(run.detectors, run.criteria, run.criteria_external, run.fractions, run.counts,
                            run.n_frames, *run_scores, *long_scores, frames.strehl, frames.d50_arcsec(run.scale),
                            frames.centroid, self.values)
        add_noiseless_scores(ds, *noiseless_scores)
        add_block_scores(ds, self.blocks)
        add_recentred_strehl(ds, frame_recentred_strehl)
        add_registration(ds, self.registration.name, frames.registered, frames.unregistered())
        if image_crop_px != 0:
            ds = add_images(ds, images, long_images, image_crop_px)
        ds.attrs.update(pixel_scale_arcsec=run.scale, diffraction_limited_peak=run.peak, seed=run.seed,
                        n_pixels=frames.n_pixels, frames_drawn_again=self.drawn_again)
        return ds
