"""Recentred accumulation: whole-pixel shifts, time blocks and the layout of the partial sums.

Each selected frame is recentred on its registered position (:mod:`.registration`; the
sub-pixel remainder, if any, applied before) by a whole number of pixels
(``np.roll`` semantics: the simulated field is periodic over the frame) and added, in
float64, to the partial sum of its (criterion, bin) (:mod:`.ranking`); a fraction's image
is the cumulative sum of its bins. :class:`PartialSums` holds every such sum of a run, of
its time blocks and of the same frames without noise, as rows of two arrays.
"""

from collections.abc import Sequence

import numpy as np

from . import adds
from .metrics import EncircledEnergy, score_images
from .ranking import criterion_bins, fraction_counts, last_bins


def block_error(block_values: np.ndarray) -> np.ndarray:
    """Monte-Carlo standard error of a value from its independent time blocks' values (block, ...):
    their standard deviation over ``sqrt(n_blocks)`` (batch means)."""
    return block_values.std(axis=0, ddof=1) / np.sqrt(len(block_values))


def batch_mean_error(values: np.ndarray, n_blocks: int) -> float:
    """Standard error of the mean of a correlated series from ``n_blocks`` batch means, the
    blocks of :class:`TimeBlocks` (valid when blocks are longer than the correlation time)."""
    usable = len(values) // n_blocks * n_blocks
    means = np.asarray(values[:usable], dtype=float).reshape(n_blocks, -1).mean(axis=1)
    return float(block_error(means))


def recentring_shifts_px(centroids_px: np.ndarray, n_pixels: int) -> np.ndarray:
    """Whole-pixel shifts (..., 2) (y, x) that bring centroids (..., 2) nearest to (n/2, n/2).

    ``s = floor(n/2 - c + 1/2)`` (nearest integer, halves rounded up). Non-finite
    centroids (zero-flux frames) get no shift.
    """
    target = n_pixels // 2
    shifts = np.floor(target - np.asarray(centroids_px, dtype=np.float64) + 0.5)
    return np.where(np.isfinite(shifts), shifts, 0).astype(np.int64)


def axis_window(n_pixels: int, half_width_px: int = 3) -> np.ndarray:
    """Flat indices of the ``(2 h + 1)^2`` pixels around the axis pixel (n/2, n/2)."""
    around = n_pixels // 2 + np.arange(-half_width_px, half_width_px + 1)
    return (around[:, None] * n_pixels + around).ravel()


def window_values(frames: np.ndarray, shifts: np.ndarray, window: np.ndarray, out: np.ndarray) -> None:
    """Values ``out`` (k, w) at the flat pixels ``window`` of frames (k, n, n) rolled by ``shifts`` (k, 2)."""
    n = frames.shape[-1]
    wy, wx = window // n, window % n
    src_y = (wy[None, :] - shifts[:, :1]) % n
    src_x = (wx[None, :] - shifts[:, 1:]) % n
    out[:] = frames[np.arange(len(frames))[:, None], src_y, src_x]


class TimeBlocks:
    """Time blocks of a run, each selected and scored on its own (Monte-Carlo errors).

    Frame ``f`` is in block ``f // block_frames`` (none past ``n_blocks`` blocks; the
    remainder of ``n_frames / n_blocks`` is left out). Each block keeps the same fractions of
    its own frames (``counts``, ``n_bins`` distinct); ``bins`` (detector, criterion, frame)
    are the frames' bins within their block, ``values`` the blocks' (Strehl, FWHM, d50)
    (block, criterion, fraction, detector). ``n_blocks`` 0: no blocks.
    """

    def __init__(self, n_frames: int, n_blocks: int, fractions, n_det: int, n_crit: int):
        if n_blocks == 1 or n_blocks < 0 or (n_blocks and n_frames // n_blocks < 1):
            raise ValueError(f"n_blocks must be 0 (no errors) or >= 2 with a frame each, got {n_blocks}")
        self.n_blocks = n_blocks
        self.block_frames = n_frames // n_blocks if n_blocks else 0
        self.counts = fraction_counts(max(self.block_frames, 1), fractions)
        self.n_bins = len(np.unique(self.counts)) if n_blocks else 0
        self.last_bin = last_bins(self.counts)
        self.bins = np.full((n_det, n_crit, n_frames), -1, dtype=np.int64)
        shape = (n_blocks, n_crit, len(self.counts), n_det)
        self.values = tuple(np.full(shape, np.nan) for _ in range(3))  # Strehl, FWHM, d50

    def block_of(self, start: int, stop: int) -> np.ndarray:
        """Block of frames ``start..stop - 1`` (may be ``n_blocks`` and beyond: in none)."""
        return np.arange(start, stop) // max(self.block_frames, 1)

    def completed(self, start: int, stop: int) -> range:
        """Blocks whose last frame is among frames ``start..stop - 1``."""
        if not self.n_blocks:
            return range(0)
        return range(start // self.block_frames, min(stop // self.block_frames, self.n_blocks))

    def assign(self, values: np.ndarray, larger_is_better: Sequence[bool], crits) -> None:
        """Block bins of criteria ``crits`` from ``values`` (criterion, detector, frame)."""
        for b in range(self.n_blocks):
            sl = slice(b * self.block_frames, (b + 1) * self.block_frames)
            for i in range(values.shape[1]):
                for c in crits:
                    self.bins[i, c, sl] = criterion_bins(values[c, i, sl], larger_is_better[c], self.counts)


class PartialSums:
    """Every partial sum of a run: the rows of two float64 arrays, per detector.

    ``detected`` (detector, rows, *item), the detected frames (an item: a whole frame, or a
    sub-pixel method's vector, :mod:`.cropped`); its rows, in order:

    * the run's (criterion, bin) sums, row ``c n_bins + b`` (:meth:`run_rows`);
    * the recentred long exposure (all frames), row ``long_exposure_row``;
    * the blocks' (criterion, block bin) sums, from ``block_row0`` (:meth:`block_rows`):
      a *streamed* criterion's rows are those of row set ``s = block mod n_sets``, enough sets
      that the blocks a chunk of frames spans never share one, so the chunks are processed
      whole and a block's set is scored and cleared after the chunk that completes it
      (:meth:`completed_blocks`); the *resident* criteria (contiguous) have rows of their own
      for every block, after the sets: their sums may be corrected until the last chunk
      (frames moved between bins, :class:`.guesses.GuessedBins`).

    ``noiseless`` (detector, run rows, *item): the run's (criterion, bin) sums of the same
    selection and shifts applied to the noiseless frames. The items are their size + 8 apart
    in memory (not a power of two: no cache-set conflicts); :meth:`allocate` makes them when
    the first chunk gives the frame size and the largest chunk.
    """

    def __init__(self, n_det: int, n_crit: int, counts: np.ndarray, blocks: TimeBlocks, resident: Sequence[int] = ()):
        self.n_det, self.n_crit, self.blocks = n_det, n_crit, blocks
        self.n_bins = len(np.unique(counts))
        self.last_bin = last_bins(counts)
        self.long_exposure_row = n_crit * self.n_bins
        self.block_row0 = self.long_exposure_row + 1
        self.is_resident = np.isin(np.arange(n_crit), resident)
        if np.any(np.diff(np.flatnonzero(self.is_resident)) != 1):
            raise ValueError(f"resident criteria must be contiguous, got {resident}")
        self.slot = np.zeros(n_crit, dtype=np.int64)  # index among the streamed or the resident criteria
        for kind in (True, False):
            self.slot[self.is_resident == kind] = np.arange(np.count_nonzero(self.is_resident == kind))
        self.n_resident = int(self.is_resident.sum())
        self.n_stream = n_crit - self.n_resident
        self.n_sets = self.max_chunk = 0
        self.detected = self.noiseless = self.detected_rows = self.noiseless_rows = None

    def allocate(self, item_shape: tuple[int, ...], chunk_frames: int) -> None:
        """Zeroed sums of items of ``item_shape`` (a whole frame's (n, n), or a vector's,
        :class:`.cropped.CroppedFrames`), for chunks of up to ``chunk_frames`` frames."""
        blocks, size = self.blocks, int(np.prod(item_shape))
        if blocks.n_blocks:
            self.max_chunk = chunk_frames
            self.n_sets = min(blocks.n_blocks, -(-chunk_frames // blocks.block_frames) + 1)
        n_block_rows = (self.n_sets * self.n_stream + blocks.n_blocks * self.n_resident) * blocks.n_bins
        n_rows = self.block_row0 + n_block_rows
        self.detected_rows = np.zeros((self.n_det, n_rows, size + 8))
        self.noiseless_rows = np.zeros((self.n_det, self.long_exposure_row, size + 8))
        self.detected = self.detected_rows[..., :size].reshape(self.n_det, n_rows, *item_shape)
        self.noiseless = self.noiseless_rows[..., :size].reshape(self.n_det, self.long_exposure_row, *item_shape)

    def run_rows(self, crits, bins: np.ndarray) -> np.ndarray:
        """Rows (k, len(crits)) of frames in run bins ``bins`` (len(crits), k) (-1: none)."""
        first = np.asarray(crits, dtype=np.int64) * self.n_bins
        bins = bins.T
        return np.where(bins >= 0, first + bins, -1)

    def block_first_row(self, block, crit):
        """First row of criterion ``crit``'s bins in block ``block`` (broadcast arrays)."""
        n_bins = self.blocks.n_bins
        streamed = self.block_row0 + ((block % max(self.n_sets, 1)) * self.n_stream + self.slot[crit]) * n_bins
        resident = self.block_row0 + (self.n_sets * self.n_stream + block * self.n_resident + self.slot[crit]) * n_bins
        return np.where(self.is_resident[crit], resident, streamed)

    def block_rows(self, crits, sl: slice, bins: np.ndarray) -> np.ndarray:
        """Rows (k, len(crits)) of frames ``sl`` in block bins ``bins`` (len(crits), k) (-1: none)."""
        k = sl.stop - sl.start
        if not self.blocks.n_blocks:
            return np.full((k, 0), -1, dtype=np.int64)
        if k > self.max_chunk:
            raise ValueError(f"a chunk of {k} frames, more than the first's {self.max_chunk}")
        block = self.blocks.block_of(sl.start, sl.stop)[:, None]
        crits = np.asarray(crits, dtype=np.int64)
        bins = bins.T
        return np.where(bins >= 0, self.block_first_row(block, crits[None, :]) + bins, -1)

    def completed_blocks(self, sl: slice, crits):
        """(block, its rows of criteria ``crits`` (contiguous) (detector, rows, *item)) of every
        block the chunk ``sl`` completes; each set of rows is cleared once the caller has it."""
        if not crits:
            return
        for block in self.blocks.completed(sl.start, sl.stop):
            first = int(self.block_first_row(block, crits[0]))
            rows = self.detected[:, first : first + len(crits) * self.blocks.n_bins]
            yield block, rows
            rows[:] = 0.0


class WholeFrames:
    """The baseline's accumulation (``cog``): each frame added whole (n x n), rolled by its
    whole-pixel shift (:func:`.adds.add_recentred`); its integrated images scored whole
    (:func:`.metrics.score_images`). The same interface as :class:`.cropped.CroppedFrames`."""

    def __init__(
        self, n_pixels: int, encircled: EncircledEnergy, diffraction_limited_peak: float, pixel_scale_arcsec: float
    ):
        self.item_shape = (n_pixels, n_pixels)
        self.window = axis_window(n_pixels)
        self.encircled, self.peak, self.scale = encircled, diffraction_limited_peak, pixel_scale_arcsec

    @staticmethod
    def prepare(spectra, shifts, remainder, flux, energies=None, which=None, out=None) -> np.ndarray:
        """The frames (k, n, n) float32 of ``spectra`` as they are (rolled when added)."""
        return spectra.frames

    @staticmethod
    def add(prepared: np.ndarray, shifts: np.ndarray, rows: np.ndarray, partial: np.ndarray, sign: float) -> None:
        adds.add_recentred(prepared, shifts, rows, partial, sign)

    def window_values(self, prepared: np.ndarray, shifts: np.ndarray, out: np.ndarray) -> None:
        window_values(prepared, shifts, self.window, out)

    @staticmethod
    def images(items: np.ndarray) -> np.ndarray:
        return items

    @staticmethod
    def flux(items: np.ndarray) -> np.ndarray:
        return items.sum(axis=(-2, -1))

    def score(self, images: np.ndarray, expected_flux: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """Strehl ratio, FWHM [arcsec] and d50 [arcsec] (about the centre of gravity) of images
        (..., n, n); the Strehl over ``expected_flux`` (...) where not NaN (:func:`.metrics.strehl_flux`)."""
        return score_images(images, self.peak, self.scale, self.encircled, expected_flux)
