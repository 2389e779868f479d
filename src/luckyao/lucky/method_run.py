"""One registration method's part of a lucky run (:func:`.pipeline.run_lucky_methods`).

The passes over the frames (reading them, drawing each detector's noise) are shared by the
registration methods of a run; what depends on the method is here, one :class:`MethodRun`
per method: the frames' registered positions and shifts, their d50 (about the registered
position), the image criteria's values and bins (ranked, or guessed in pass 1), the time
blocks, and the partial sums of the detected and of the noiseless frames: of whole frames for
``cog`` (:class:`.accumulation.WholeFrames`), of cropped vectors for the sub-pixel methods
(:class:`.cropped.CroppedFrames`). Each method's sums receive exactly the operations, in the
same order, that a run of that method alone gives them, so its results are bit for bit those
of a run of its own.
"""

from collections.abc import Sequence

import numpy as np
import xarray as xr

from .accumulation import PartialSums, TimeBlocks, WholeFrames, recentring_shifts_px
from .cropped import CroppedFrames, crop_px
from .dataset import (
    add_block_scores,
    add_images,
    add_noiseless_scores,
    add_recentred_strehl,
    add_registration,
    result_dataset,
)
from .detector import Detector
from .fourier import FourierRun, add_fourier, registered_crops
from .guesses import GuessedBins
from .metrics import d50_from_radius, score_images, strehl_flux
from .ranking import criterion_bins
from .registration import FrameSpectra, Registration, shifts_of
from .scoring import expected_fluxes, score_partial_sums, value_at_peak


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
        self.shifts = self.remainder = self.in_window = None
        self.n_pixels = 0

    def allocate(self, n_pixels: int, window_size: int) -> None:
        n_det, n_frames = self.flux.shape
        self.n_pixels = n_pixels
        self.in_window = np.empty((n_det, n_frames, window_size), dtype=np.float32)
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
            centroids, self.strehl[i, sl], self.d50_px[i, sl], registered = measures[1:5]
            self.centroid[i, sl], self.registered[i, sl] = centroids, registered
            if self.registration.subpixel:
                self.shifts[i, sl], self.remainder[i, sl] = shifts_of(registered, self.n_pixels, True)
            else:
                self.shifts[i, sl] = recentring_shifts_px(centroids, self.n_pixels)

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
        self.clean = self.guessed = self.accumulation = self.buffer = None
        self.pending_noiseless = []  # (noisy detector, its rows (k, m)) of the chunk's noiseless frames, to add
        self.drawn_again = np.zeros(n_det, dtype=np.int64)
        self.fourier = None  # the Fourier lucky imaging (:mod:`.fourier`), if the run asks for it

    def assign(self, crits) -> None:
        """Run and block bins of criteria ``crits`` from their values."""
        larger, counts = self.run.larger, self.run.counts
        for i in range(len(self.run.detectors)):
            for c in crits:
                self.bins[i, c] = criterion_bins(self.values[c, i], larger[c], counts)
        self.blocks.assign(self.values, larger, crits)

    def registered(self, spectra: FrameSpectra, common: tuple[np.ndarray, ...]) -> np.ndarray | None:
        """The registered positions (k, 2) of the frames (k, n, n) of ``spectra`` whose flux, centre
        of gravity and Strehl are ``common`` (:meth:`.pipeline._LuckyRun.common_measures`); None
        with a reference (its positions are the reference's)."""
        if self.frames.reference is not None:
            return None
        return self.registration.positions_px(spectra.frames, common[1], spectra)

    def measures(
        self,
        spectra: FrameSpectra,
        common: tuple[np.ndarray, ...],
        registered: np.ndarray | None,
        radial_sums: np.ndarray | None,
    ) -> tuple[np.ndarray, ...]:
        """Flux, centre of gravity, Strehl, d50 [pixel] (about the registered position; the centre
        of gravity with ``cog``) and registered position (:meth:`registered`) of the frames (k, n, n)
        of ``spectra`` whose flux, centre of gravity and Strehl are ``common`` (they do not depend on
        the method), and for a sub-pixel method the ``radial_sums`` (k, n_bins) of their encircled
        energy about the registered positions (:meth:`.metrics.EncircledEnergy.radial_sums_about`:
        its d50's, and added into its sums, :class:`.cropped.CroppedFrames`); with a reference,
        their flux only."""
        flux, centroids, strehl = common
        if self.frames.reference is not None:
            return (flux,)
        encircled = self.run.encircled
        if not self.registration.subpixel:
            radius = encircled.radius_px_binned(spectra.frames, registered, flux=flux, spectra=spectra)
            return flux, centroids, strehl, d50_from_radius(radius, 1.0), registered
        radius = encircled.radius_px_of(encircled.energies_of(radial_sums), flux)
        return flux, centroids, strehl, d50_from_radius(radius, 1.0), registered, radial_sums

    def keep_noiseless(self, clean: tuple[np.ndarray, ...]) -> None:
        """Pass 0's measures of the noiseless frames (:meth:`measures` of all frames): the guesses' predictor."""
        self.clean = clean
        larger = self.run.larger
        self.guessed = GuessedBins(
            self.bins.shape, self.run.counts, self.blocks, {0: (clean[2], larger[0]), 1: (clean[3], larger[1])}
        )

    def allocate(self, n_pixels: int, chunk_frames: int) -> None:
        """The accumulation (whole frames for ``cog``, cropped for a sub-pixel method), the partial
        sums and the per-frame arrays, once the first chunk gives their sizes."""
        run = self.run
        if self.registration.subpixel:
            size = run.crop_px if run.crop_px is not None else crop_px(n_pixels, run.scale)
            self.accumulation = CroppedFrames(n_pixels, size, run.encircled, run.peak, run.scale)
        else:
            self.accumulation = WholeFrames(n_pixels, run.encircled, run.peak, run.scale)
        self.sums.allocate(self.accumulation.item_shape, chunk_frames)
        self.frames.allocate(n_pixels, self.accumulation.window.size)
        if self.registration.subpixel:
            self.buffer = np.empty((2, chunk_frames, *self.accumulation.item_shape))
        if run.fourier_fractions is not None:
            size = min(run.fourier_crop_px(n_pixels), getattr(self.accumulation, "crop_px", n_pixels))
            self.fourier = FourierRun(
                len(run.detectors), run.n_frames, run.fourier_fractions, size, chunk_frames, run.n_blocks
            )

    def _crops(self, frames: np.ndarray, i: int, sl: slice) -> np.ndarray:
        """Detector ``i``'s frames ``sl`` (k, n, n) registered, their central crop of the Fourier lucky imaging."""
        shifts, remainder = self.frames.shifts[i, sl], self.frames.remainder[i, sl]
        return registered_crops(self.accumulation, frames, shifts, remainder, self.fourier.crop_px)

    def add_fourier(self, i: int, sl: slice, detected, unit: FrameSpectra, detected_rows=None) -> None:
        """Pass 2, the Fourier lucky imaging's sums (:meth:`.fourier.FourierSelection.add`) of detector
        ``i``'s frames ``sl``: ``detected`` (its frames drawn again, all of them, and their row sums
        ``detected_rows``) with the noiseless ``unit`` frames, or None for a noiseless detector (``unit``)."""
        if self.fourier is None:
            return
        flux = self.frames.flux[i, sl]
        if detected is None:
            self.fourier.add(i, self._crops(unit.frames, i, sl), flux, sl.start)
            return
        if not np.array_equal(detected_rows.sum(axis=1), flux):
            raise RuntimeError(f"frames {sl.start}.. differ between the two passes")
        self.fourier.add(
            i,
            self._crops(detected.frames, i, sl),
            flux,
            sl.start,
            self._crops(unit.frames, i, sl),
            unit.flux(),
            self.run.flux_estimate[i, sl],
        )

    def _prepared(
        self, spectra: FrameSpectra, i: int, sl: slice, flux: np.ndarray, energies=None, which=None, slot: int = 0
    ) -> np.ndarray:
        """Detector ``i``'s frames ``sl`` (held by ``spectra``, of flux ``flux``) ready to add
        (:meth:`.accumulation.WholeFrames.prepare`, :meth:`.cropped.CroppedFrames.prepare`), those of
        ``which`` (k,) bool only; in buffer ``slot`` (0 or 1: valid until that slot's next use)."""
        frames = self.frames
        return self.accumulation.prepare(
            spectra,
            frames.shifts[i, sl],
            frames.remainder[i, sl],
            flux,
            energies,
            which,
            None if self.buffer is None else self.buffer[slot],
        )

    def add_detected(
        self, i: int, detector: Detector, sl: slice, detected: FrameSpectra, measures: Sequence[np.ndarray]
    ) -> None:
        """Pass 1, detector ``i``'s frames ``sl`` (``detected``: their :class:`.registration.FrameSpectra`):
        their measures recorded, the frames recentred into the sums of the criteria binned early, the
        recentred long exposure and, for a noisy detector, the guessed bins of the late criteria (and
        the same rows noted for the noiseless frames, :meth:`add_noiseless`)."""
        sums, early, late, guessed, frames = self.sums, self.early, self.late, self.guessed, self.frames
        k = sl.stop - sl.start
        frames.record(i, sl, measures)
        if self.fourier is not None:
            self.fourier.observe(i, self._crops(detected.frames, i, sl), sl.start)
        shifts, add = frames.shifts[i, sl], self.accumulation.add
        radial_sums = measures[5] if len(measures) > 5 else None
        prepared = self._prepared(detected, i, sl, frames.flux[i, sl], radial_sums)
        # the early criteria and the recentred long exposure: shifts known now
        rows_early = np.concatenate(
            [sums.run_rows(early, self.bins[i, early, sl]), np.full((k, 1), sums.long_exposure_row)], axis=1
        )  # (k, early + 1)
        rows_block = sums.block_rows(early, sl, self.blocks.bins[i, early, sl])
        rows_guessed = rows_guessed_block = np.empty((k, 0), dtype=np.int64)
        if guessed is not None and not detector.noiseless:
            for c, per_frame in zip(late, (frames.strehl[i, sl], frames.d50_px[i, sl])):
                guessed.guess(i, c, sl, per_frame, self.run.larger[c])
            rows_guessed = sums.run_rows(late, guessed.run[i, late, sl])
            rows_guessed_block = sums.block_rows(late, sl, guessed.block[i, late, sl])
        add(
            prepared,
            shifts,
            np.concatenate([rows_early, rows_block, rows_guessed, rows_guessed_block], axis=1),
            sums.detected_rows[i],
            1.0,
        )
        if not detector.noiseless:  # a noiseless detector's noiseless sums are its sums (copied when scoring)
            self.pending_noiseless.append((i, np.concatenate([rows_early[:, :-1], rows_guessed], axis=1)))
        self.accumulation.window_values(prepared, shifts, frames.in_window[i, sl])

    def add_noiseless(self, sl: slice, unit: FrameSpectra) -> None:
        """Pass 1, once every detector has added its frames ``sl``: the noiseless frames (``unit``) with
        each noisy detector's shifts into that detector's noiseless sums, in the rows
        :meth:`add_detected` gave them; a sub-pixel method measures their encircled energy's radial
        sums about every detector's registered positions at once (one reading of each spectrum)."""
        pending, self.pending_noiseless = self.pending_noiseless, []
        if not pending:
            return
        frames, radial_sums = self.frames, [None] * len(pending)
        if self.registration.subpixel:
            detectors = [i for i, _ in pending]
            centres = frames.n_pixels // 2 - (frames.shifts[detectors, sl] + frames.remainder[detectors, sl])
            radial_sums = self.run.encircled.radial_sums_about(unit.frames, centres.transpose(1, 0, 2), unit)
            radial_sums = radial_sums.transpose(1, 0, 2)  # (detector, frame, bin)
        for (i, rows), about in zip(pending, radial_sums):
            self.accumulation.add(
                self._prepared(unit, i, sl, unit.flux(), about, slot=1),
                frames.shifts[i, sl],
                rows,
                self.sums.noiseless_rows[i],
                1.0,
            )

    def rank_late(self) -> None:
        """Pass 2's start: the late criteria's values from the frames' measures, ranked."""
        self.values[0], self.values[1] = self.frames.strehl, self.frames.d50_arcsec(self.run.scale)
        self.assign(self.late)

    def add_noiseless_detector(self, i: int, sl: slice, unit: FrameSpectra) -> None:
        """Pass 2, a noiseless detector ``i``'s frames ``sl`` (``unit``): into their late criteria's bins."""
        late, sums = self.late, self.sums
        final_rows = np.concatenate(
            [sums.run_rows(late, self.bins[i, late, sl]), sums.block_rows(late, sl, self.blocks.bins[i, late, sl])],
            axis=1,
        )
        self.accumulation.add(
            self._prepared(unit, i, sl, self.frames.flux[i, sl]),
            self.frames.shifts[i, sl],
            final_rows,
            sums.detected_rows[i],
            1.0,
        )

    def guessed_wrong(self, i: int, sl: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pass 2, a noisy detector ``i``'s frames ``sl``: the rows (k, late [+ late]) of their final
        and guessed bins, and which frames (k,) are in a wrong one (to draw again and move)."""
        late, sums, guessed = self.late, self.sums, self.guessed
        final_rows = np.concatenate(
            [sums.run_rows(late, self.bins[i, late, sl]), sums.block_rows(late, sl, self.blocks.bins[i, late, sl])],
            axis=1,
        )
        guessed_rows = np.concatenate(
            [sums.run_rows(late, guessed.run[i, late, sl]), sums.block_rows(late, sl, guessed.block[i, late, sl])],
            axis=1,
        )
        return final_rows, guessed_rows, (final_rows != guessed_rows).any(axis=1)

    def move(
        self,
        i: int,
        sl: slice,
        detected: FrameSpectra,
        detected_rows: np.ndarray,
        unit: FrameSpectra,
        wrong: tuple[np.ndarray, np.ndarray, np.ndarray],
    ) -> None:
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
        shifts, add = frames.shifts[i, sl], self.accumulation.add
        moved = final_rows != guessed_rows  # (k, late [+ late]): rows differ where bins do
        out_of, into = np.where(moved, guessed_rows, -1), np.where(moved, final_rows, -1)
        for slot, (frames_of, flux, partial, m) in enumerate(
            (
                (detected, frames.flux[i, sl], sums.detected_rows[i], moved.shape[1]),
                (unit, unit.flux(), sums.noiseless_rows[i], len(self.late)),
            )
        ):
            prepared = self._prepared(frames_of, i, sl, flux, which=drawn, slot=slot)
            add(prepared, shifts, out_of[:, :m], partial, -1.0)
            add(prepared, shifts, into[:, :m], partial, 1.0)

    def score_blocks(self, sl: slice, crits) -> None:
        """Score the rows of criteria ``crits`` (contiguous) of every block the chunk ``sl`` completes."""
        blocks = self.blocks
        for block, rows in self.sums.completed_blocks(sl, crits):
            in_block = slice(block * blocks.block_frames, (block + 1) * blocks.block_frames)
            expected = self._expected(blocks.bins[:, crits[0] : crits[-1] + 1, in_block], blocks.last_bin, in_block)
            _, *scores = score_partial_sums(
                rows, len(crits), blocks.n_bins, blocks.last_bin, self.accumulation.score, expected
            )
            for values, score in zip(blocks.values, scores):
                values[block, crits[0] : crits[-1] + 1] = score

    def _expected(self, bins: np.ndarray, last_bin: np.ndarray, frames: slice = slice(None)) -> np.ndarray | None:
        """The expected flux (criterion, fraction, det) of the integrated images of the frames
        ``frames`` in ``bins`` (det, criterion, frames) (:func:`.scoring.expected_fluxes`), their
        Strehl's flux; None with noiseless detectors only (every Strehl over its measured flux)."""
        estimate = self.run.flux_estimate[:, frames]
        if np.isnan(estimate).all():
            return None
        return expected_fluxes(estimate, bins, last_bin)

    def score(self, long_none: np.ndarray, image_crop_px: int | None) -> xr.Dataset:
        """Score the integrated images (cumulative sums of bins) and the long exposures (``long_none``,
        without recentring, shared by the methods): the method's dataset. Frees its partial sums."""
        run, sums, frames, accumulation = self.run, self.sums, self.frames, self.accumulation
        n_crit = len(run.criteria)
        lc = sums.long_exposure_row
        long_registered = sums.detected[:, lc]
        frame_recentred_strehl = value_at_peak(
            frames.in_window,
            accumulation.window,
            accumulation.images(long_registered),
            strehl_flux(frames.flux, run.flux_estimate),
            run.peak,
        )
        scoring = (n_crit, sums.n_bins, sums.last_bin, accumulation.score)
        long_expected = run.flux_estimate.sum(axis=1)  # (det,): every frame; NaN for a noiseless detector
        for i, detector in enumerate(run.detectors):
            if detector.noiseless:
                sums.noiseless[i] = sums.detected[i, :lc]
        noiseless_scores = score_partial_sums(sums.noiseless, *scoring)[1:]
        sums.noiseless = sums.noiseless_rows = None
        long_expected = None if np.isnan(long_expected).all() else long_expected  # noiseless only: measured
        if isinstance(accumulation, WholeFrames):  # both long exposures whole: scored together
            long_images = np.stack([long_none, long_registered])  # (recentring, det, n, n)
            long_scores = accumulation.score(
                long_images, None if long_expected is None else np.stack([long_expected] * 2)
            )
            long_flux = None
        else:
            long_images = [long_none, accumulation.images(long_registered).copy()]
            long_flux = [None, accumulation.flux(long_registered).copy()]
            long_scores = [
                np.stack(pair)
                for pair in zip(
                    score_images(long_none, run.peak, run.scale, run.encircled, long_expected),
                    accumulation.score(long_registered, long_expected),
                )
            ]
        integrated, *run_scores = score_partial_sums(
            sums.detected[:, :lc], *scoring, self._expected(self.bins, sums.last_bin)
        )
        sums.detected = sums.detected_rows = long_registered = None
        ds = result_dataset(
            run.detectors,
            run.criteria,
            run.criteria_external,
            run.fractions,
            run.counts,
            run.n_frames,
            *run_scores,
            *long_scores,
            frames.strehl,
            frames.d50_arcsec(run.scale),
            frames.centroid,
            self.values,
        )
        add_noiseless_scores(ds, *noiseless_scores)
        add_block_scores(ds, self.blocks)
        add_recentred_strehl(ds, frame_recentred_strehl)
        add_registration(ds, self.registration.name, frames.registered, frames.unregistered())
        if image_crop_px != 0:
            flux = None if isinstance(accumulation, WholeFrames) else accumulation.flux(integrated)
            ds = add_images(ds, accumulation.images(integrated), long_images, image_crop_px, flux, long_flux)
        if self.fourier is not None:
            ds = add_fourier(ds, self.fourier, run.detectors, run.peak, run.scale, image_crop_px != 0)
            self.fourier = None
        ds.attrs.update(
            pixel_scale_arcsec=run.scale,
            diffraction_limited_peak=run.peak,
            seed=run.seed,
            n_pixels=frames.n_pixels,
            frames_drawn_again=self.drawn_again,
        )
        return ds
