"""Lucky imaging post-processing of one target's frame cube: select, shift and add, score.

Method (Basden 2014, sec. "Shift and add"): every frame gets a scalar quality (image
Strehl, 50%-energy diameter d50, or an external per-frame value such as the LGS
tilt-removed wavefront rms); frames are ranked over the whole cube; for each fraction
``f`` the best ``n_f = max(1, round(f n))`` frames are recentred on their centre of
gravity by a whole number of pixels and added. The integrated images are scored by
Strehl, FWHM and d50 (:mod:`luckyao.lucky.metrics`).

Frames are ``(k, n, n)`` float32 unit-flux noiseless images indexed ``[y, x]`` with
the optical axis on pixel ``(n/2, n/2)``; detector noise (:mod:`luckyao.lucky.detector`)
is applied here, so one simulated cube serves every detector model.
"""

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..progress import Progress, log
from . import kernels
from .detector import Detector, KeyedNoise, detector_key
from .metrics import EncircledEnergy, centroid_px, fwhm_arcsec, strehl

IMAGE_CRITERIA = (("strehl", True), ("d50", False))
"""Image criteria computed per frame: (name, larger_is_better)."""


@dataclass(frozen=True, eq=False)
class ExternalCriterion:
    """A per-frame selection criterion not computed from the image.

    ``values`` (n_frames,) in ``units``; ``larger_is_better`` orders them (e.g. the LGS
    tilt-removed wavefront rms [nm] has ``larger_is_better=False``). NaN ranks last.
    """

    name: str
    values: np.ndarray
    larger_is_better: bool
    units: str = "1"
    long_name: str = ""


@dataclass(frozen=True, eq=False)
class ImageReference:
    """Per-frame image measurements of another target's detected frames (e.g. the on-axis
    star) that select and recentre a target: ``strehl`` and ``d50_arcsec`` (detector, frame)
    replace the target's own image criteria, ``centroid_px`` (detector, frame, 2) its own
    centres of gravity for the shifts (same detectors, in the same order)."""

    strehl: np.ndarray
    d50_arcsec: np.ndarray
    centroid_px: np.ndarray

    @classmethod
    def of(cls, result: xr.Dataset) -> "ImageReference":
        """The reference given by another target's :func:`run_lucky` result."""
        return cls(result.frame_strehl.values, result.frame_d50_arcsec.values, result.frame_centroid_px.values)


def fraction_counts(n_frames: int, fractions: Sequence[float]) -> np.ndarray:
    """Frames kept per fraction, ``n_k = max(1, round(f_k n_frames))``, int64 (n_fractions,).

    ``round`` is numpy's round-half-to-even; fractions must lie in (0, 1].
    """
    fractions = np.asarray(fractions, dtype=np.float64)
    if np.any(~(fractions > 0)) or np.any(fractions > 1):
        raise ValueError(f"fractions must lie in (0, 1], got {fractions}")
    return np.maximum(1, np.rint(fractions * n_frames)).astype(np.int64)


def rank_frames(values: np.ndarray, larger_is_better: bool) -> np.ndarray:
    """Frame indices from best to worst, shape (n_frames,).

    Exact stable sort over all frames: ties keep frame-index order; NaN ranks last.
    """
    values = np.asarray(values, dtype=np.float64)
    key = -values if larger_is_better else values
    return np.argsort(key, kind="stable")


def selection_bins(order: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Assign frames to nested selection bins, for cumulative summation.

    ``order`` (n_frames,) frame indices best first (:func:`rank_frames`); ``counts``
    (n_fractions,) frames kept per fraction. With ``u`` the sorted distinct counts,
    the frame of rank ``r`` goes to bin ``b`` with ``u[b-1] <= r < u[b]`` (``u[-1]=0``),
    or -1 if ``r >= max(u)``. Returns ``(bin_of_frame (n_frames,), last_bin
    (n_fractions,))``: fraction ``k``'s selection is the union of bins ``0..last_bin[k]``.
    """
    distinct = np.unique(counts)
    bin_of_rank = np.searchsorted(distinct, np.arange(len(order)), side="right")
    bin_of_rank[bin_of_rank == len(distinct)] = -1
    bin_of_frame = np.empty(len(order), dtype=np.int64)
    bin_of_frame[order] = bin_of_rank
    return bin_of_frame, np.searchsorted(distinct, counts)


def recentring_shifts_px(centroids_px: np.ndarray, n_pixels: int) -> np.ndarray:
    """Whole-pixel shifts (..., 2) (y, x) that bring centroids (..., 2) nearest to (n/2, n/2).

    ``s = floor(n/2 - c + 1/2)`` (nearest integer, halves rounded up). Non-finite
    centroids (zero-flux frames) get no shift.
    """
    target = n_pixels // 2
    shifts = np.floor(target - np.asarray(centroids_px, dtype=np.float64) + 0.5)
    return np.where(np.isfinite(shifts), shifts, 0).astype(np.int64)


def shift_frames(frames: np.ndarray, shifts_px: np.ndarray) -> np.ndarray:
    """Frames (k, n, n) each rolled by its integer shift (k, 2) (y, x), new array.

    Circular shift with ``np.roll`` semantics, ``out[y, x] = in[(y - s_y) mod n,
    (x - s_x) mod n]``: consistent with the simulated field, which is periodic over
    the frame (a frame is the power spectrum of a sampled pupil). Four block copies a frame.
    """
    frames = np.asarray(frames)
    k, ny, nx = frames.shape
    shifts_px = np.asarray(shifts_px, dtype=np.int64).reshape(k, 2)
    out = np.empty_like(frames)
    for frame, moved, (sy, sx) in zip(frames, out, shifts_px % (ny, nx)):
        moved[sy:, sx:], moved[sy:, :sx] = frame[:ny - sy, :nx - sx], frame[:ny - sy, nx - sx:]
        moved[:sy, sx:], moved[:sy, :sx] = frame[ny - sy:, :nx - sx], frame[ny - sy:, nx - sx:]
    return out


def shift_and_add(frames: np.ndarray) -> np.ndarray:
    """Sum (n, n) float64 of frames (k, n, n) recentred on their centre of gravity.

    Each frame is rolled by :func:`recentring_shifts_px` of its own
    :func:`luckyao.lucky.metrics.centroid_px` (:func:`shift_frames`), then all are added.
    """
    frames = np.asarray(frames)
    shifts = recentring_shifts_px(centroid_px(frames), frames.shape[-1])
    return shift_frames(frames, shifts).sum(axis=0, dtype=np.float64)


def _score(partial: np.ndarray, n_crit: int, n_bins: int, last_bin: np.ndarray,
           encircled: EncircledEnergy, diffraction_limited_peak: float,
           pixel_scale_arcsec: float) -> tuple[np.ndarray, ...]:
    """Integrated images of the (det, criterion x bin, n, n) partial sums (cumulative sums
    of the bins of each fraction, made in place: ``partial`` is overwritten), as
    (criterion, fraction, det, n, n), and their Strehl, FWHM [arcsec] and d50 [arcsec]
    (criterion, fraction, det). One code path for the noisy and the noiseless sums, so
    equal sums give bit-identical scores."""
    n_det, _, ny, nx = partial.shape
    cumulative = partial.reshape(n_det, n_crit, n_bins, ny, nx)
    for b in range(1, n_bins):  # np.cumsum's sums, in place
        cumulative[:, :, b] += cumulative[:, :, b - 1]
    # (crit, fraction, det, n, n), contiguous: the d50's batches need no copy of it
    images = np.empty((n_crit, len(last_bin), n_det, ny, nx))
    for i in range(n_det):
        images[:, :, i] = cumulative[i][:, last_bin]
    del cumulative
    s_int = strehl(images, diffraction_limited_peak)
    d50_int = 2 * encircled.radius_px(images) * pixel_scale_arcsec
    fwhm_int = fwhm_arcsec(images, pixel_scale_arcsec)
    return images, s_int, fwhm_int, d50_int


def _rows(first_rows: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """Partial-sum rows ``first_rows + bins`` (k, m) of bins (k, m), -1 where a bin is -1."""
    return np.where(bins >= 0, first_rows + bins, -1)


def _window(frames: np.ndarray, shifts: np.ndarray, window: np.ndarray, out: np.ndarray) -> None:
    """Values (k, w) at the flat pixels ``window`` of frames (k, n, n) rolled by ``shifts``."""
    n = frames.shape[-1]
    wy, wx = window // n, window % n
    src_y = (wy[None, :] - shifts[:, :1]) % n
    src_x = (wx[None, :] - shifts[:, 1:]) % n
    out[:] = frames[np.arange(len(frames))[:, None], src_y, src_x]


def _chunks(iter_chunks: Callable[[], Iterable[tuple[int, np.ndarray]]],
            n_frames: int) -> Iterator[tuple[int, np.ndarray]]:
    """Validated chunks: contiguous, covering frames 0..n_frames-1, square float frames."""
    expected = 0
    for start, frames in iter_chunks():
        frames = np.asarray(frames)
        if start != expected or frames.ndim != 3 or frames.shape[1] != frames.shape[2]:
            raise ValueError(f"chunk at {start} (expected {expected}), shape {frames.shape}")
        expected += len(frames)
        yield start, frames
    if expected != n_frames:
        raise ValueError(f"chunks cover {expected} frames, expected {n_frames}")


def _crop(images: np.ndarray, crop_px: int | None) -> np.ndarray:
    """Central ``crop_px`` square around pixel (n/2, n/2) of images (..., n, n)."""
    n = images.shape[-1]
    if crop_px is None or crop_px >= n:
        return images
    lo = n // 2 - crop_px // 2
    return images[..., lo:lo + crop_px, lo:lo + crop_px]


def _attrs(units: str, long_name: str) -> dict:
    return {"units": units, "long_name": long_name}


def _measure(frames: np.ndarray, rows: np.ndarray, cols: np.ndarray, peak: np.ndarray,
             encircled: EncircledEnergy, diffraction_limited_peak: float) -> tuple[np.ndarray, ...]:
    """Flux (k,), centre of gravity (k, 2) (y, x) [pixel], Strehl (k,) and d50 [pixel] (k,) of
    frames (k, n, n) from their row and column sums (k, n) and peaks (k,)
    (:func:`luckyao.lucky.kernels.frame_sums`); NaN where the flux is not positive."""
    n = frames.shape[-1]
    flux = rows.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        centroids = np.stack([rows @ np.arange(n, dtype=np.float64) / flux,
                              cols @ np.arange(n, dtype=np.float64) / flux], axis=-1)
        strehl_ratio = np.where(flux > 0, peak / (diffraction_limited_peak * flux), np.nan)
    return flux, centroids, strehl_ratio, encircled.radius_px_binned(frames, centroids, flux=flux) * 2


def _noiseless_measures(iter_chunks, n_frames: int, encircled_of: Callable[[int], EncircledEnergy],
                        diffraction_limited_peak: float, progress_interval_s: float) -> tuple[np.ndarray, ...]:
    """:func:`_measure` of every noiseless frame: flux, centroids, Strehl, d50 [pixel] (frame[, 2])."""
    out = tuple(np.full(shape, np.nan) for shape in (n_frames, (n_frames, 2), n_frames, n_frames))
    progress = Progress("lucky pass 0/2: noiseless frames", n_frames, progress_interval_s)
    for start, frames in _chunks(iter_chunks, n_frames):
        unit = np.ascontiguousarray(frames, dtype=np.float32)
        k, n = unit.shape[:2]
        rows, cols, peak = np.empty((k, n)), np.empty((k, n)), np.empty(k, np.float32)
        kernels.frame_sums(unit, rows, cols, peak)
        for whole, part in zip(out, _measure(unit, rows, cols, peak, encircled_of(n), diffraction_limited_peak)):
            whole[start:start + k] = part
        progress.update(start + k)
    return out


class _Blocks:
    """Time blocks of a run, each selected and scored on its own (Monte-Carlo errors).

    Frame ``f`` is in block ``f // block_frames`` (none past ``n_blocks`` blocks). A
    block's (criterion, block bin) partial sums are rows of the run's partial sums:
    ``row0 + (s n_stream + j) n_bins + b`` for the ``j``-th streamed criterion, in row set
    ``s = block mod n_sets``: enough sets that the blocks a chunk of frames spans never
    share one, so the chunks are processed whole (the per-frame metrics do not depend on
    block boundaries), and each block is scored and its set cleared after the chunk that
    completes it. The ``resident`` criteria (contiguous) have rows of their own for every
    block, after the sets: their sums may be corrected until the last chunk (frames moved
    between bins, :class:`_GuessedBins`).
    """

    def __init__(self, n_frames: int, n_blocks: int, fractions, n_det: int, n_crit: int, row0: int,
                 resident: Sequence[int] = ()):
        if n_blocks == 1 or n_blocks < 0 or (n_blocks and n_frames // n_blocks < 1):
            raise ValueError(f"n_blocks must be 0 (no errors) or >= 2 with a frame each, got {n_blocks}")
        self.n_blocks, self.row0, self.n_crit = n_blocks, row0, n_crit
        self.block_frames = n_frames // n_blocks if n_blocks else 0
        self.counts = fraction_counts(max(self.block_frames, 1), fractions)
        self.n_bins = len(np.unique(self.counts)) if n_blocks else 0
        self.last_bin = np.searchsorted(np.unique(self.counts), self.counts)
        self.is_resident = np.isin(np.arange(n_crit), resident)
        if np.any(np.diff(np.flatnonzero(self.is_resident)) != 1):
            raise ValueError(f"resident criteria must be contiguous, got {resident}")
        self.slot = np.zeros(n_crit, dtype=np.int64)  # index among the streamed or the resident criteria
        for kind in (True, False):
            self.slot[self.is_resident == kind] = np.arange(np.count_nonzero(self.is_resident == kind))
        self.n_resident = int(self.is_resident.sum())
        self.n_stream = n_crit - self.n_resident
        self.n_sets = self.max_chunk = 0
        self.bins = np.full((n_det, n_crit, n_frames), -1, dtype=np.int64)
        shape = (n_blocks, n_crit, len(self.counts), n_det)
        self.values = tuple(np.full(shape, np.nan) for _ in range(3))  # Strehl, FWHM, d50

    def prepare(self, chunk_frames: int) -> int:
        """Rows needed for chunks of up to ``chunk_frames`` frames (the first chunk's)."""
        if self.n_blocks:
            self.max_chunk = chunk_frames
            self.n_sets = min(self.n_blocks, -(-chunk_frames // self.block_frames) + 1)
        return (self.n_sets * self.n_stream + self.n_blocks * self.n_resident) * self.n_bins

    def first_row(self, block, crit):
        """First row of criterion ``crit``'s bins in block ``block`` (broadcast arrays)."""
        streamed = self.row0 + ((block % max(self.n_sets, 1)) * self.n_stream + self.slot[crit]) * self.n_bins
        resident = (self.row0 + (self.n_sets * self.n_stream + block * self.n_resident + self.slot[crit])
                    * self.n_bins)
        return np.where(self.is_resident[crit], resident, streamed)

    def assign(self, values: np.ndarray, larger_is_better, crits) -> None:
        """Block bins of criteria ``crits`` from ``values`` (criterion, detector, frame)."""
        for b in range(self.n_blocks):
            sl = slice(b * self.block_frames, (b + 1) * self.block_frames)
            for i in range(values.shape[1]):
                for c in crits:
                    order = rank_frames(values[c, i, sl], larger_is_better[c])
                    self.bins[i, c, sl] = selection_bins(order, self.counts)[0]

    def rows(self, i: int, crits, sl: slice, bins: np.ndarray | None = None) -> np.ndarray:
        """Block rows (k, len(crits)) of detector ``i``'s frames ``sl`` (-1: none), of their
        bins (default), or of other block bins ``bins`` (detector, criterion, frame)."""
        if not self.n_blocks:
            return np.full((sl.stop - sl.start, 0), -1, dtype=np.int64)
        if sl.stop - sl.start > self.max_chunk:
            raise ValueError(f"a chunk of {sl.stop - sl.start} frames, more than the first's {self.max_chunk}")
        block = (np.arange(sl.start, sl.stop) // self.block_frames)[:, None]
        crits = np.asarray(crits, dtype=np.int64)
        bins = (self.bins if bins is None else bins)[i, crits, sl].T
        return np.where(bins >= 0, self.first_row(block, crits[None, :]) + bins, -1)

    def score_completed(self, sl: slice, crits, partial: np.ndarray, encircled, diffraction_limited_peak: float,
                        pixel_scale_arcsec: float) -> None:
        """Score the rows of criteria ``crits`` (contiguous) in ``partial`` (det, rows, n, n) of
        every block the chunk ``sl`` completes, then clear them."""
        if not self.n_blocks or not crits:
            return
        for block in range(sl.start // self.block_frames, min(sl.stop // self.block_frames, self.n_blocks)):
            first = int(self.first_row(block, crits[0]))
            rows = partial[:, first:first + len(crits) * self.n_bins]
            _, *scores = _score(rows, len(crits), self.n_bins, self.last_bin, encircled,
                                diffraction_limited_peak, pixel_scale_arcsec)
            for values, score in zip(self.values, scores):
                values[block, crits[0]:crits[-1] + 1] = score
            rows[:] = 0.0


def _bins_of_rank(rank: np.ndarray, distinct: np.ndarray) -> np.ndarray:
    """Bins of (possibly fractional) ranks, as :func:`selection_bins`: ``b`` with
    ``distinct[b-1] <= rank < distinct[b]``, -1 past the last."""
    bins = np.searchsorted(distinct, rank, side="right")
    bins[bins == len(distinct)] = -1
    return bins


class _GuessedBins:
    """Bins of the image criteria guessed while pass 1 detects the frames, so that a noisy
    detector's frames are added then, without a second draw of their noise.

    A frame's final rank (:func:`rank_frames`) is the number of frames of smaller key plus
    the number of earlier frames of equal key (ties, e.g. the NaN of noise-dominated frames,
    keep frame order). The second term is known when the frame is seen, all earlier frames
    having been. The first is guessed two ways, weighted by the correlation ``w`` (clipped to
    [0, 1]) of the noisy and the noiseless ranks of the frames seen so far:

    * (weight ``w``) the frames seen so far (its chunk's included) with a smaller key, plus
      those not seen yet whose noiseless key (``clean``, measured before pass 1) is below the
      noiseless key of the same rank among the seen frames (quantile mapping: exact when the
      noise reorders no frame, whatever the drift of the seeing);
    * (weight ``1 - w``, for noise-dominated detectors) its rank among the frames seen so far,
      scaled to the run's length.

    In its time block: the same, with the block's frames (the plain rank from the run's
    frames until the block has ``MIN_IN_BLOCK``) and the run's mapping. Its bin follows as in
    :func:`selection_bins`. Pass 2 draws again only the frames whose final bin differs and
    moves them: the result is the same sum as adding them to their final bins at once, to
    float64 rounding (measured for the paper's sweep: ~14% of the frames move, 6% at 1e5
    photons).
    """

    MIN_IN_BLOCK = 256

    def __init__(self, bins_shape: tuple, counts: np.ndarray, blocks: _Blocks, clean: dict):
        self.run = np.full(bins_shape, -1, dtype=np.int64)  # (detector, criterion, frame)
        self.block = np.full(bins_shape, -1, dtype=np.int64)
        self.distinct, self.blocks = np.unique(counts), blocks
        self.block_distinct = np.unique(blocks.counts)
        self.clean = {c: _key(values, larger) for c, (values, larger) in clean.items()}  # per criterion
        self.clean_sorted = {c: np.sort(key) for c, key in self.clean.items()}
        self.clean_block_sorted = {c: [np.sort(key[b * blocks.block_frames:(b + 1) * blocks.block_frames])
                                       for b in range(blocks.n_blocks)] for c, key in self.clean.items()}
        self._seen: dict = {}  # (detector, criterion) -> sorted keys of the run, of the block, block, moments
        self._clean_seen: dict = {}  # criterion -> frames seen, their sorted noiseless keys, of each block

    def _seen_clean(self, c: int, stop: int) -> tuple[np.ndarray, dict]:
        """Sorted noiseless keys of criterion ``c`` of the frames before ``stop`` (seen so far: the
        same for every detector), of the run and of each block; updated once per chunk."""
        seen, run, in_block = self._clean_seen.get(c, (0, np.empty(0), {}))
        if stop != seen:
            keys = self.clean[c][seen:stop]
            run = _merged(run, keys)
            block_of = np.arange(seen, stop) // max(self.blocks.block_frames, 1)
            for b in np.unique(block_of[block_of < self.blocks.n_blocks]):
                in_block[b] = _merged(in_block.get(b, np.empty(0)), keys[block_of == b])
            self._clean_seen[c] = (stop, run, in_block)
        return run, in_block

    def guess(self, i: int, c: int, sl: slice, values: np.ndarray, larger_is_better: bool) -> None:
        """Guess the bins of detector ``i``'s frames ``sl`` by criterion ``c`` from their ``values``."""
        key, clean = _key(values, larger_is_better), self.clean[c][sl]
        empty = np.empty(0)
        run, in_block, current, moments = self._seen.get((i, c), (empty, empty, -1, np.zeros(6)))
        run_clean, in_block_clean = self._seen_clean(c, sl.stop)
        ties = _earlier_ties(run, key)
        run = _merged(run, key)
        seen_below = np.searchsorted(run, key)
        # how far the noise keeps the noiseless order: the correlation of the ranks among the seen frames
        moments += _moments(seen_below / len(run), np.searchsorted(run_clean, clean) / len(run))
        weight = _correlation(moments)
        mapped = np.append(run_clean, np.inf)[seen_below]  # the noiseless key of the same rank
        unseen_below = np.searchsorted(self.clean_sorted[c], mapped) - np.searchsorted(run_clean, mapped)
        n_frames = len(self.clean_sorted[c])
        rank = weight * (seen_below + unseen_below) + (1 - weight) * seen_below * (n_frames / len(run))
        self.run[i, c, sl] = _bins_of_rank(rank + ties, self.distinct)
        blocks = self.blocks
        if blocks.n_blocks:
            block_of = np.arange(sl.start, sl.stop) // blocks.block_frames
            for b in np.unique(block_of[block_of < blocks.n_blocks]):
                mine = block_of == b
                if b != current:
                    in_block, current = empty, b
                ties = _earlier_ties(in_block, key[mine])
                in_block = _merged(in_block, key[mine])
                in_block_below = np.searchsorted(in_block, key[mine])
                unseen_below = (np.searchsorted(self.clean_block_sorted[c][b], mapped[mine])
                                - np.searchsorted(in_block_clean[b], mapped[mine]))
                ranked = in_block if len(in_block) >= self.MIN_IN_BLOCK else run
                plain = np.searchsorted(ranked, key[mine]) * (blocks.block_frames / len(ranked))
                rank = weight * (in_block_below + unseen_below) + (1 - weight) * plain
                self.block[i, c, np.arange(sl.start, sl.stop)[mine]] = _bins_of_rank(rank + ties, self.block_distinct)
        self._seen[(i, c)] = (run, in_block, current, moments)


def _moments(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Sums (count, x, y, x^2, y^2, x y) of paired samples, for :func:`_correlation`."""
    return np.array([len(x), x.sum(), y.sum(), x @ x, y @ y, x @ y])


def _correlation(moments: np.ndarray) -> float:
    """Pearson correlation of the samples of ``moments`` (:func:`_moments`), clipped to [0, 1]
    (0 without spread)."""
    n, sx, sy, sxx, syy, sxy = moments
    var_x, var_y = n * sxx - sx * sx, n * syy - sy * sy
    if not (var_x > 0 and var_y > 0):
        return 0.0
    return float(np.clip((n * sxy - sx * sy) / np.sqrt(var_x * var_y), 0.0, 1.0))


def _key(values: np.ndarray, larger_is_better: bool) -> np.ndarray:
    """Sort keys of criterion values as :func:`rank_frames` ranks them (best first, NaN last)."""
    key = np.asarray(values, dtype=np.float64) * (-1.0 if larger_is_better else 1.0)
    key[np.isnan(key)] = np.inf
    return key


def _earlier_ties(seen: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Per key of ``keys`` (frames in order, after those of the sorted keys ``seen``): how many
    earlier frames have an equal key."""
    in_seen = np.searchsorted(seen, keys, side="right") - np.searchsorted(seen, keys)
    return in_seen + np.tril(keys[:, None] == keys[None, :], -1).sum(axis=1)


def _merged(sorted_keys: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``sorted_keys`` with ``new`` inserted, sorted."""
    new = np.sort(new)
    return np.insert(sorted_keys, np.searchsorted(sorted_keys, new), new)


def run_lucky(iter_chunks: Callable[[], Iterable[tuple[int, np.ndarray]]], n_frames: int,
              detectors: Sequence[Detector], fractions: Sequence[float],
              diffraction_limited_peak: float, pixel_scale_arcsec: float, seed: int,
              criteria_external: Sequence[ExternalCriterion] = (),
              image_crop_px: int | None = 64, reference: ImageReference | None = None,
              n_blocks: int = 0, progress_interval_s: float = 5.0) -> xr.Dataset:
    """Lucky imaging of one frame cube for several detectors, criteria and fractions.

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
    exposures and ``frame_recentred_strehl`` are computed).

    Noise: a noisy detector's frames come from :class:`luckyao.lucky.detector.KeyedNoise`,
    whose draws for frame ``f`` are keyed by ``(seed, detector_key(name), f)``
    (:func:`detector_key`): they depend on the seed, the detector's name and the frame
    only, not on the chunking or the other detectors (names must be distinct), and
    drawing them again gives the same frames. A noiseless detector's frames are the input
    as float32.

    Pass 1 detects each chunk for each detector, measures per-frame Strehl, d50
    (:meth:`EncircledEnergy.radius_px_binned`, the encircled energy summed by radial bins)
    and centre of gravity (from the frame's row and column sums), sums the long exposure
    without recentring, and, since each frame's shift is known then (its own centroid, or
    the reference's), recentres it (:func:`recentring_shifts_px`, np.roll semantics) into
    the recentred long exposure and into the (criterion, bin) partial sums of the criteria
    ranked before pass 1: the external ones, and with a reference all. Frames are ranked
    per criterion (:func:`rank_frames`) and assigned to nested bins
    (:func:`selection_bins`). Without a reference, the image criteria are ranked after
    pass 1: pass 2 adds a noiseless detector's frames to their partial sums; a noisy
    detector's frames went in pass 1 to bins guessed from the frames seen so far and the
    noiseless frames (:class:`_GuessedBins`; pass 0 measures the noiseless frames first),
    and pass 2 draws again only those whose final bin (of the run or of their time block)
    differs (the same draws; checked by their flux) and moves them, so the noise of most
    frames is drawn once (its sums equal direct ones to float64 rounding). Each
    fraction's image is the cumulative sum of its bins. Alongside, the noiseless frames
    (the input, as float32) get the same detector's shifts and the same bins into a
    second set of partial sums: the ``*_noiseless`` scores separate a wrong selection or
    recentring from the noise in the final image. The sums are float64 throughout, frame
    by frame (:func:`luckyao.lucky.kernels.add_recentred`); a noiseless detector's second
    set is its first, copied, so its ``*_noiseless`` values equal the others bit for bit.
    Memory: the two sets of partial sums, float64
    (2 x detectors x criteria x distinct counts x n x n), plus a chunk's work arrays
    (~1 kB per pixel and frame of a chunk) and, when scoring, the integrated images
    (criteria x fractions x detectors x n x n) of one set at a time (the cumulative
    sums are made in place).

    Monte-Carlo errors (``n_blocks`` >= 2): the frames are cut into ``n_blocks`` time
    blocks of ``n_frames // n_blocks`` frames (the remainder left out), each block is
    selected, recentred and scored on its own as a short run (the same fractions of its
    frames, ranked within it), and the standard error of a value is the standard
    deviation of its block values over ``sqrt(n_blocks)`` (batch means: the blocks are
    independent when longer than the turbulence's correlation time; compare
    ``tests/test_errors.py``). The blocks' partial sums are extra rows of the same
    sums (:class:`_Blocks`), scored and cleared after the chunk that ends the block; with
    guessed bins, the image criteria's rows of every block stay until pass 2 (detectors x
    2 x blocks x distinct counts x n x n float64: 1.7 GB for the paper's sweep).

    Returns a CF-style :class:`xarray.Dataset`: ``strehl``, ``fwhm_arcsec``,
    ``d50_arcsec`` (criterion, fraction, detector) and the same of the noiseless frames
    with the same selection and shifts, ``strehl_noiseless``, ``fwhm_arcsec_noiseless``,
    ``d50_arcsec_noiseless``; ``long_exposure_strehl``,
    ``long_exposure_fwhm_arcsec``, ``long_exposure_d50_arcsec`` (recentring,
    detector); per-frame ``frame_strehl``, ``frame_d50_arcsec``,
    ``frame_centroid_px`` (detector, frame[, axis]) and ``frame_criterion``
    (criterion, detector, frame); unless ``image_crop_px`` is 0, the central
    ``image_crop_px`` square (None: whole frame) of the integrated images over the
    whole frame's flux (the crop sums to the fraction of the flux it holds),
    ``image`` (criterion, fraction, detector, y, x) and
    ``long_exposure_image`` (recentring, detector, y, x); with blocks, ``strehl_block``,
    ``fwhm_arcsec_block``, ``d50_arcsec_block`` (block, criterion, fraction, detector)
    and the errors ``strehl_error``, ``fwhm_arcsec_error``, ``d50_arcsec_error``.
    """
    detectors = list(detectors)
    counts = fraction_counts(n_frames, fractions)
    criteria = list(IMAGE_CRITERIA) + [(c.name, bool(c.larger_is_better))
                                       for c in criteria_external]
    for c in criteria_external:
        if np.shape(c.values) != (n_frames,):
            raise ValueError(f"criterion {c.name}: values must have shape ({n_frames},)")
    n_det, n_crit = len(detectors), len(criteria)
    names = [d.name for d in detectors]
    if len(set(names)) != n_det or len({detector_key(name) for name in names}) != n_det:
        raise ValueError(f"detector names must be distinct (and their crc32 too): {names}")
    if reference is not None and (np.shape(reference.centroid_px) != (n_det, n_frames, 2)
                                  or np.shape(reference.strehl) != (n_det, n_frames)
                                  or np.shape(reference.d50_arcsec) != (n_det, n_frames)):
        raise ValueError(f"reference: centroids {np.shape(reference.centroid_px)} and criteria "
                         f"{np.shape(reference.strehl)} do not match (detector, frame) = {(n_det, n_frames)}")

    # criteria known before the frames are read: the external ones, and with a reference
    # the image ones too; their bins (and the reference's shifts) serve pass 1
    n_bins = len(np.unique(counts))
    values = np.full((n_crit, n_det, n_frames), np.nan)
    for j, c in enumerate(criteria_external):
        values[2 + j] = np.asarray(c.values, dtype=np.float64)[None, :]
    if reference is not None:
        values[0], values[1] = reference.strehl, reference.d50_arcsec
    early = list(range(2 if reference is None else 0, n_crit))  # criteria binned before pass 1
    bin_of_frame = np.full((n_det, n_crit, n_frames), -1, dtype=np.int64)
    last_bin = np.searchsorted(np.unique(counts), counts)

    late = [c for c in range(n_crit) if c not in early]  # the image criteria of the frames themselves
    # a noisy detector's frames are added to guessed bins of the late criteria in pass 1
    guessing = bool(late) and not all(d.noiseless for d in detectors)
    blocks = _Blocks(n_frames, n_blocks, fractions, n_det, n_crit, row0=n_crit * n_bins + 1,
                     resident=late if guessing else ())
    encircled = None

    def encircled_of(n):
        nonlocal encircled
        if encircled is None:
            encircled = EncircledEnergy(n)
        return encircled

    # pass 0 (guessing only): the noiseless frames' measures, the guesses' predictor (and the
    # noiseless detectors' measures)
    clean = _noiseless_measures(iter_chunks, n_frames, encircled_of, diffraction_limited_peak,
                                progress_interval_s) if guessing else None
    guessed = _GuessedBins(bin_of_frame.shape, counts, blocks, {
        0: (clean[2], criteria[0][1]), 1: (clean[3], criteria[1][1])}) if guessing else None

    def assign_bins(crits):
        for i in range(n_det):
            for c in crits:
                bin_of_frame[i, c] = selection_bins(rank_frames(values[c, i], criteria[c][1]), counts)[0]
        blocks.assign(values, [larger for _, larger in criteria], crits)

    assign_bins(early)
    shifts = None

    # pass 1: detected frames, per-frame metrics and centroids, long exposure without
    # recentring; the criteria binned early are accumulated already
    frame_strehl = np.full((n_det, n_frames), np.nan)
    frame_d50_px = np.full((n_det, n_frames), np.nan)
    frame_centroid = np.full((n_det, n_frames, 2), np.nan)
    frame_flux = np.full((n_det, n_frames), np.nan)
    long_none = partial = partial_noiseless = partial_rows = noiseless_rows = None
    noise = buffer = None
    frame_window = window = None

    def prepare_noise(unit):
        """The noise of a chunk of unit-flux frames made ready for the noisy detectors, if any."""
        nonlocal noise, buffer
        if all(d.noiseless for d in detectors):
            return
        k, n = unit.shape[:2]
        if noise is None or noise.max_frames < k:
            noise = KeyedNoise(n, max(k, 64))
            buffer = np.empty((noise.max_frames, n, n), np.float32)
        noise.prepare(unit)

    lc = n_crit * n_bins  # row of the recentred long exposure (all frames) in partial
    row_of = np.arange(n_crit) * n_bins  # first row of each criterion
    progress = Progress("lucky pass 1/2: frames", n_frames, progress_interval_s)
    for start, frames in _chunks(iter_chunks, n_frames):
        k, n = len(frames), frames.shape[-1]
        if long_none is None:
            encircled = encircled_of(n)
            long_none = np.zeros((n_det, n, n))
            # images n^2 + 8 apart (not a power of two: no cache-set conflicts), viewed (n, n)
            n_rows = lc + 1 + blocks.prepare(k)
            partial_rows = np.zeros((n_det, n_rows, n * n + 8))
            noiseless_rows = np.zeros((n_det, lc, n * n + 8))
            partial = partial_rows[..., :n * n].reshape(n_det, n_rows, n, n)
            partial_noiseless = noiseless_rows[..., :n * n].reshape(n_det, lc, n, n)
            around = n // 2 + np.arange(-3, 4)
            window = (around[:, None] * n + around).ravel()  # 7 x 7 pixels around the axis
            frame_window = np.empty((n_det, n_frames, window.size), dtype=np.float32)
            if reference is not None:
                shifts = recentring_shifts_px(reference.centroid_px, n)
            else:
                shifts = np.zeros((n_det, n_frames, 2), dtype=np.int64)
        sl = slice(start, start + k)
        unit = np.ascontiguousarray(frames, dtype=np.float32)
        prepare_noise(unit)
        for i, detector in enumerate(detectors):
            if detector.noiseless and clean is not None:  # measured in pass 0
                detected, measures = unit, [x[sl] for x in clean]
            else:
                if detector.noiseless:
                    detected = unit
                    rows, cols, peak = np.empty((k, n)), np.empty((k, n)), np.empty(k, np.float32)
                    kernels.frame_sums(unit, rows, cols, peak)
                else:
                    detected, rows, cols, peak = noise.detect(detector, seed, start, buffer)
                measures = (_measure(detected, rows, cols, peak, encircled, diffraction_limited_peak)
                            if reference is None else [rows.sum(axis=1)])
            flux = measures[0]
            if reference is None:
                centroids, frame_strehl[i, sl], frame_d50_px[i, sl] = measures[1:]
            kernels.add_frames(detected, long_none[i])
            frame_flux[i, sl] = flux
            if reference is None:
                frame_centroid[i, sl] = centroids
                shifts[i, sl] = recentring_shifts_px(centroids, n)
            # the early criteria and the recentred long exposure: shifts known now
            rows_early = np.concatenate([_rows(row_of[early], bin_of_frame[i, early, sl].T),
                                         np.full((k, 1), lc)], axis=1)  # (k, early + 1)
            rows_block = blocks.rows(i, early, sl)
            rows_guessed = rows_guessed_block = np.empty((k, 0), dtype=np.int64)
            if guessed is not None and not detector.noiseless:
                for c, per_frame in zip(late, (frame_strehl[i, sl], frame_d50_px[i, sl])):
                    guessed.guess(i, c, sl, per_frame, criteria[c][1])
                rows_guessed = _rows(row_of[late], guessed.run[i, late, sl].T)
                rows_guessed_block = blocks.rows(i, late, sl, guessed.block)
            kernels.add_recentred(detected, shifts[i, sl], np.concatenate(
                [rows_early, rows_block, rows_guessed, rows_guessed_block], axis=1), partial_rows[i], 1.0)
            if not detector.noiseless:  # a noiseless detector's noiseless sums are its sums (copied when scoring)
                kernels.add_recentred(unit, shifts[i, sl], np.concatenate([rows_early[:, :-1], rows_guessed], axis=1),
                                      noiseless_rows[i], 1.0)
            _window(detected, shifts[i, sl], window, frame_window[i, sl])
        blocks.score_completed(sl, early, partial, encircled, diffraction_limited_peak, pixel_scale_arcsec)
        progress.update(sl.stop)
    frame_d50_arcsec = frame_d50_px * pixel_scale_arcsec

    # ranking of the image criteria of the frames themselves
    if late:
        values[0], values[1] = frame_strehl, frame_d50_arcsec
        assign_bins(late)
        # pass 2: noiseless frames into the late criteria's partial sums; a noisy detector's
        # frames whose guessed bins were wrong drawn again (the same noise) and moved
        progress = Progress("lucky pass 2/2: frames", n_frames, progress_interval_s)
        n_drawn = np.zeros(n_det, dtype=np.int64)
        for start, frames in _chunks(iter_chunks, n_frames):
            k = len(frames)
            sl = slice(start, start + k)
            unit = np.ascontiguousarray(frames, dtype=np.float32)
            prepare_noise(unit)
            for i, detector in enumerate(detectors):
                rows_late = _rows(row_of[late], bin_of_frame[i, late, sl].T)  # (k, late)
                rows_block = blocks.rows(i, late, sl)
                final_rows = np.concatenate([rows_late, rows_block], axis=1)
                if detector.noiseless:
                    kernels.add_recentred(unit, shifts[i, sl], final_rows, partial_rows[i], 1.0)
                    continue
                guessed_rows = np.concatenate([_rows(row_of[late], guessed.run[i, late, sl].T),
                                               blocks.rows(i, late, sl, guessed.block)], axis=1)
                moved = final_rows != guessed_rows  # (k, late [+ late]): rows differ where bins do
                drawn = moved.any(axis=1)
                if not drawn.any():
                    continue
                n_drawn[i] += np.count_nonzero(drawn)
                detected, rows, _, _ = noise.detect(detector, seed, start, buffer, drawn)
                if not np.array_equal(rows[drawn].sum(axis=1), frame_flux[i, sl][drawn]):
                    raise RuntimeError(f"frames {start}.. differ between the two passes")
                out_of, into = np.where(moved, guessed_rows, -1), np.where(moved, final_rows, -1)
                for frames_of, sums, m in ((detected, partial_rows[i], moved.shape[1]),
                                           (unit, noiseless_rows[i], len(late))):
                    kernels.add_recentred(frames_of, shifts[i, sl], out_of[:, :m], sums, -1.0)
                    kernels.add_recentred(frames_of, shifts[i, sl], into[:, :m], sums, 1.0)
            blocks.score_completed(sl, late, partial, encircled, diffraction_limited_peak, pixel_scale_arcsec)
            progress.update(sl.stop)
        if guessed is not None:
            log.info("lucky pass 2/2: frames drawn again (guessed bins wrong) per noisy detector: %s", ", ".join(
                f"{d.name} {n / n_frames:.1%}" for d, n in zip(detectors, n_drawn) if not d.noiseless))
    long_cog = partial[:, lc]
    frame_recentred_strehl = _value_at_peak(frame_window, window, long_cog, frame_flux,
                                            diffraction_limited_peak)

    # integrated images: cumulative sums of bins, scored
    scoring = (n_crit, n_bins, last_bin, encircled, diffraction_limited_peak, pixel_scale_arcsec)
    for i, detector in enumerate(detectors):
        if detector.noiseless:
            partial_noiseless[i] = partial[i, :lc]
    _, s_nl, fwhm_nl, d50_nl = _score(partial_noiseless, *scoring)
    del partial_noiseless, noiseless_rows
    long_images = np.stack([long_none, long_cog])  # (recentring, det, n, n)
    images, s_int, fwhm_int, d50_int = _score(partial[:, :lc], *scoring)
    block_values = blocks.values
    del partial, partial_rows, long_cog
    s_long = strehl(long_images, diffraction_limited_peak)
    d50_long = 2 * encircled.radius_px(long_images) * pixel_scale_arcsec
    fwhm_long = fwhm_arcsec(long_images, pixel_scale_arcsec)

    ds = _dataset(detectors, criteria, criteria_external, fractions, counts, n_frames,
                  s_int, fwhm_int, d50_int, s_long, fwhm_long, d50_long,
                  frame_strehl, frame_d50_arcsec, frame_centroid, values)
    same = "of the integrated image of the same selection and shifts applied to the noiseless frames"
    sel = ("criterion", "fraction", "detector")
    ds["strehl_noiseless"] = (sel, s_nl, _attrs("1", f"Strehl ratio {same}"))
    ds["fwhm_arcsec_noiseless"] = (sel, fwhm_nl, _attrs("arcsec", f"FWHM {same}"))
    ds["d50_arcsec_noiseless"] = (sel, d50_nl, _attrs(
        "arcsec", f"diameter enclosing 50% of the energy {same}"))
    if blocks.n_blocks:
        block_dims = ("block", "criterion", "fraction", "detector")
        for metric, values_b in zip(("strehl", "fwhm_arcsec", "d50_arcsec"), block_values):
            ds[f"{metric}_block"] = (block_dims, values_b, _attrs(
                ds[metric].attrs["units"], f"{ds[metric].attrs['long_name']}, each time block selected on its own "
                                           f"({blocks.block_frames} frames)"))
            ds[f"{metric}_error"] = (sel, values_b.std(axis=0, ddof=1) / np.sqrt(blocks.n_blocks), _attrs(
                ds[metric].attrs["units"], f"Monte-Carlo standard error of {metric}, from {blocks.n_blocks} "
                                           "time blocks (batch means)"))
    ds["frame_recentred_strehl"] = (("detector", "frame"), frame_recentred_strehl, _attrs(
        "1", "recentred frame's value at the recentred long exposure's peak pixel (within 3 pixels of the axis) "
             "over its flux and the diffraction-limited peak (their mean is that long exposure's Strehl)"))
    if image_crop_px != 0:
        with np.errstate(invalid="ignore", divide="ignore"):
            # the crop of the image over its flux (elementwise: as cropping after dividing)
            unit = _crop(images, image_crop_px) / images.sum(axis=(-2, -1), keepdims=True)
            unit_long = _crop(long_images, image_crop_px) / long_images.sum(axis=(-2, -1), keepdims=True)
        m = unit.shape[-1]
        offsets = np.arange(m) - m // 2
        ds = ds.assign_coords(
            y=("y", offsets, _attrs("pixel", "row offset from the optical axis pixel (n/2)")),
            x=("x", offsets, _attrs("pixel", "column offset from the optical axis pixel (n/2)")))
        held = f"the central {m} x {m} pixels of the whole frame" if m < n else "the whole frame"
        ds["image"] = (("criterion", "fraction", "detector", "y", "x"), unit.astype(np.float32), _attrs(
            "1", f"integrated image over the whole frame's flux: {held} (their sum is the fraction of the flux "
                 "they hold)"))
        ds["long_exposure_image"] = (("recentring", "detector", "y", "x"), unit_long.astype(np.float32), _attrs(
            "1", f"long exposure (all frames) over the whole frame's flux: {held}"))
    ds.attrs.update(pixel_scale_arcsec=pixel_scale_arcsec,
                    diffraction_limited_peak=diffraction_limited_peak, seed=seed,
                    n_pixels=n)
    return ds


def _value_at_peak(frame_window: np.ndarray, window: np.ndarray, long_images: np.ndarray,
                   frame_flux: np.ndarray, diffraction_limited_peak: float) -> np.ndarray:
    """Per detector and frame, ``frame[p] / (flux P_dl)`` at the brightest pixel ``p`` of
    the long exposure (``long_images`` (det, n, n)) among the pixels ``window`` (flat
    indices, around the axis), from the frames' values there (``frame_window``). When
    ``p`` is the long exposure's peak and the fluxes are equal, their mean is its
    Strehl (:func:`.metrics.strehl`)."""
    out = np.empty(frame_flux.shape)
    for i, image in enumerate(long_images):
        k = np.argmax(image.ravel()[window])
        with np.errstate(invalid="ignore", divide="ignore"):
            out[i] = frame_window[i, :, k] / (frame_flux[i] * diffraction_limited_peak)
    return out


def _dataset(detectors, criteria, criteria_external, fractions, counts, n_frames,
             s_int, fwhm_int, d50_int, s_long, fwhm_long, d50_long,
             frame_strehl, frame_d50_arcsec, frame_centroid, values) -> xr.Dataset:
    """Assemble the CF-style result dataset of :func:`run_lucky`."""
    external = {c.name: c for c in criteria_external}
    criterion_units = ["1", "arcsec"] + [external[name].units for name, _ in criteria[2:]]
    photons = [np.nan if d.photons_per_frame is None else d.photons_per_frame for d in detectors]
    coords = {
        "criterion": ("criterion", [name for name, _ in criteria],
                      _attrs("1", "frame selection criterion")),
        "larger_is_better": ("criterion", np.array([int(lb) for _, lb in criteria], np.int8),
                             {**_attrs("1", "criterion ranks larger values first"),
                              "flag_values": np.array([0, 1], np.int8),
                              "flag_meanings": "smaller_is_better larger_is_better"}),
        "criterion_units": ("criterion", criterion_units, _attrs("1", "units of the criterion")),
        "fraction": ("fraction", np.asarray(fractions, dtype=np.float64),
                     _attrs("1", "fraction of frames selected")),
        "n_frames_selected": ("fraction", counts, _attrs("1", "number of frames selected")),
        "detector": ("detector", [d.name for d in detectors], _attrs("1", "detector model")),
        "photons_per_frame": ("detector", np.array(photons, np.float64),
                              _attrs("photon", "detected photons per frame (NaN: noiseless)")),
        "read_noise_e": ("detector", np.array([d.read_noise_e for d in detectors], np.float64),
                         _attrs("electron", "read noise rms per pixel")),
        "recentring": ("recentring", ["none", "cog"],
                       _attrs("1", "recentring of the long exposure: none or centre of gravity")),
        "frame": ("frame", np.arange(n_frames), _attrs("1", "frame index")),
        "axis": ("axis", ["y", "x"], _attrs("1", "image axis")),
    }
    sel = ("criterion", "fraction", "detector")
    data = {
        "strehl": (sel, s_int, _attrs("1", "Strehl ratio of the integrated image")),
        "fwhm_arcsec": (sel, fwhm_int, _attrs("arcsec", "FWHM of the integrated image")),
        "d50_arcsec": (sel, d50_int, _attrs(
            "arcsec", "diameter enclosing 50% of the energy of the integrated image")),
        "long_exposure_strehl": (("recentring", "detector"), s_long,
                                 _attrs("1", "Strehl ratio of the long exposure")),
        "long_exposure_fwhm_arcsec": (("recentring", "detector"), fwhm_long,
                                      _attrs("arcsec", "FWHM of the long exposure")),
        "long_exposure_d50_arcsec": (("recentring", "detector"), d50_long, _attrs(
            "arcsec", "diameter enclosing 50% of the energy of the long exposure")),
        "frame_strehl": (("detector", "frame"), frame_strehl,
                         _attrs("1", "Strehl ratio of the detected frame")),
        "frame_d50_arcsec": (("detector", "frame"), frame_d50_arcsec, _attrs(
            "arcsec", "diameter enclosing 50% of the energy of the detected frame")),
        "frame_centroid_px": (("detector", "frame", "axis"), frame_centroid, _attrs(
            "pixel", "centre of gravity of the detected frame (pixel index)")),
        "frame_criterion": (("criterion", "detector", "frame"), values, _attrs(
            "1", "per-frame criterion value (units: criterion_units)")),
    }
    return xr.Dataset(data, coords=coords)
