"""Frame ranking and selection bins (Basden 2014, sec. "Shift and add").

Every frame gets a scalar quality per criterion; frames are ranked over the whole cube
(or over a time block); for each fraction ``f`` the best ``n_f = max(1, round(f n))``
frames are kept. The kept sets are nested, so they are sums of disjoint *bins* of ranks:
fraction ``k``'s selection is the union of bins ``0..last_bin[k]``.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

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


def sort_key(values: np.ndarray, larger_is_better: bool) -> np.ndarray:
    """Sort keys of criterion values as :func:`rank_frames` ranks them (best first, NaN last)."""
    key = np.asarray(values, dtype=np.float64) * (-1.0 if larger_is_better else 1.0)
    key[np.isnan(key)] = np.inf
    return key


def selection_bins(order: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Assign frames to nested selection bins, for cumulative summation.

    ``order`` (n_frames,) frame indices best first (:func:`rank_frames`); ``counts``
    (n_fractions,) frames kept per fraction. With ``u`` the sorted distinct counts,
    the frame of rank ``r`` goes to bin ``b`` with ``u[b-1] <= r < u[b]`` (``u[-1]=0``),
    or -1 if ``r >= max(u)``. Returns ``(bin_of_frame (n_frames,), last_bin
    (n_fractions,))``: fraction ``k``'s selection is the union of bins ``0..last_bin[k]``.
    """
    distinct = np.unique(counts)
    bin_of_frame = np.empty(len(order), dtype=np.int64)
    bin_of_frame[order] = bins_of_rank(np.arange(len(order)), distinct)
    return bin_of_frame, last_bins(counts)


def bins_of_rank(rank: np.ndarray, distinct: np.ndarray) -> np.ndarray:
    """Bins of (possibly fractional) ranks, as :func:`selection_bins`: ``b`` with
    ``distinct[b-1] <= rank < distinct[b]``, -1 past the last."""
    bins = np.searchsorted(distinct, rank, side="right")
    bins[bins == len(distinct)] = -1
    return bins


def last_bins(counts: np.ndarray) -> np.ndarray:
    """Per fraction of ``counts`` frames kept, the last bin of its selection (:func:`selection_bins`)."""
    return np.searchsorted(np.unique(counts), counts)


def criterion_bins(values: np.ndarray, larger_is_better: bool, counts: np.ndarray) -> np.ndarray:
    """Bins (n_frames,) of frames of criterion ``values``: :func:`selection_bins` of :func:`rank_frames`."""
    return selection_bins(rank_frames(values, larger_is_better), counts)[0]
