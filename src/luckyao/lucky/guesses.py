"""Bins of the image criteria guessed while the frames are detected (pass 1 of
:func:`.pipeline.run_lucky`), so that a noisy detector's frames are added then, without a
second draw of their noise; pass 2 moves those guessed wrong."""

import numpy as np

from .accumulation import TimeBlocks
from .ranking import bins_of_rank, sort_key


class GuessedBins:
    """Bins of the image criteria guessed while pass 1 detects the frames, so that a noisy
    detector's frames are added then, without a second draw of their noise.

    A frame's final rank (:func:`.ranking.rank_frames`) is the number of frames of smaller key plus
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
    :func:`.ranking.selection_bins`. Pass 2 draws again only the frames whose final bin differs and
    moves them: the result is the same sum as adding them to their final bins at once, to
    float64 rounding (measured for the paper's sweep: ~14% of the frames move, 6% at 1e5
    photons).
    """

    MIN_IN_BLOCK = 256

    def __init__(self, bins_shape: tuple, counts: np.ndarray, blocks: TimeBlocks, clean: dict):
        self.run = np.full(bins_shape, -1, dtype=np.int64)  # (detector, criterion, frame)
        self.block = np.full(bins_shape, -1, dtype=np.int64)
        self.distinct, self.blocks = np.unique(counts), blocks
        self.block_distinct = np.unique(blocks.counts)
        self.clean = {c: sort_key(values, larger) for c, (values, larger) in clean.items()}  # per criterion
        self.clean_sorted = {c: np.sort(key) for c, key in self.clean.items()}
        self.clean_block_sorted = {
            c: [np.sort(key[b * blocks.block_frames : (b + 1) * blocks.block_frames]) for b in range(blocks.n_blocks)]
            for c, key in self.clean.items()
        }
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
        key, clean = sort_key(values, larger_is_better), self.clean[c][sl]
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
        self.run[i, c, sl] = bins_of_rank(rank + ties, self.distinct)
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
                unseen_below = np.searchsorted(self.clean_block_sorted[c][b], mapped[mine]) - np.searchsorted(
                    in_block_clean[b], mapped[mine]
                )
                ranked = in_block if len(in_block) >= self.MIN_IN_BLOCK else run
                plain = np.searchsorted(ranked, key[mine]) * (blocks.block_frames / len(ranked))
                rank = weight * (in_block_below + unseen_below) + (1 - weight) * plain
                self.block[i, c, np.arange(sl.start, sl.stop)[mine]] = bins_of_rank(rank + ties, self.block_distinct)
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


def _earlier_ties(seen: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Per key of ``keys`` (frames in order, after those of the sorted keys ``seen``): how many
    earlier frames have an equal key."""
    in_seen = np.searchsorted(seen, keys, side="right") - np.searchsorted(seen, keys)
    return in_seen + np.tril(keys[:, None] == keys[None, :], -1).sum(axis=1)


def _merged(sorted_keys: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``sorted_keys`` with ``new`` inserted, sorted."""
    new = np.sort(new)
    return np.insert(sorted_keys, np.searchsorted(sorted_keys, new), new)
