"""Registration on several stars: a frame's shift from the positions of N stars in the field.

Each star's frames are detected with its own flux (its detectors' photons per frame scaled by its
flux ratio to the brightest star; its own noise, keyed by its target's seed) and registered by
the method in use (:func:`star_positions`). Each star's position then estimates the target's
with two independent errors: its noise (variance ``sigma_noise^2``, measured per star, detector
and method as the mean square of its noisy minus its noiseless positions: :func:`noise_variance_px2`)
and the tilt anisoplanatism between the star and the target (variance ``sigma_aniso^2``, from the
case's turbulence profile: :mod:`luckyao.atmosphere.tilt_anisoplanatism`). The frame's position is
the inverse-variance mean of its stars' positions, ``w_i = 1 / (sigma_noise,i^2 + sigma_aniso,i^2)``
(:func:`combined_positions`); a star that cannot register a frame (NaN) drops out of it. With
equal stars and no anisoplanatism the mean of N stars has 1/N the variance of one.

The anisoplanatic errors of several stars are correlated (each is a difference to the same target),
which the weights leave out: with stars on all sides of the target they partly cancel, and the
weights are then conservative.
"""

from collections.abc import Callable, Iterable, Sequence

import numpy as np

from .detector import Detector, KeyedNoise
from .metrics import centroid_from_sums
from .registration import FrameSpectra, Registration, empty_aligned
from .scoring import frame_sums

Chunks = Callable[[], Iterable[tuple[int, np.ndarray]]]


def star_positions(
    iter_chunks: Chunks, n_frames: int, detectors: Sequence[Detector], seed: int, registrations: Sequence[Registration]
) -> np.ndarray:
    """Registered positions (method, detector, frame, 2) (y, x) [pixel] of a star's frames, in one
    pass: ``iter_chunks()`` gives ``(start, frames)`` of (k, n, n) float32 unit-flux noiseless images in
    order; each detector's noise is keyed by ``seed`` (as :func:`.pipeline.run_lucky`'s, whose
    ``frame_registered_px`` they equal); NaN where a method cannot register a frame."""
    out = np.full((len(registrations), len(detectors), n_frames, 2), np.nan)
    noise = buffer = None
    spectra = FrameSpectra()
    seen = 0
    for start, frames in iter_chunks():
        unit = np.ascontiguousarray(frames, dtype=np.float32)
        k, n = unit.shape[:2]
        if start != seen:
            raise ValueError(f"chunk at {start}, expected {seen}")
        seen += k
        if noise is None or noise.max_frames < k:
            noise = KeyedNoise(n, max(k, 64))
            buffer = empty_aligned((noise.max_frames, n, n), np.float32)
        chunk = noise.prepare(unit) if not all(d.noiseless for d in detectors) else None
        for i, detector in enumerate(detectors):
            if detector.noiseless:
                detected, (rows, cols, _) = unit, frame_sums(unit)
            else:
                detected, rows, cols, _ = chunk.detect(detector, seed, start, buffer)
            spectra.reset(detected)
            centroids = centroid_from_sums(rows, cols, rows.sum(axis=1))
            for m, registration in enumerate(registrations):
                out[m, i, start : start + k] = registration.positions_px(spectra.frames, centroids, spectra)
    if seen != n_frames:
        raise ValueError(f"chunks cover {seen} frames, expected {n_frames}")
    return out


def noise_variance_px2(noisy_px: np.ndarray, noiseless_px: np.ndarray) -> np.ndarray:
    """Per axis, the mean square [pixel^2] of noisy minus noiseless positions (..., frame, 2) over the
    frames both register: (..., 2). Zero for a noiseless detector."""
    return np.nanmean((np.asarray(noisy_px) - np.asarray(noiseless_px)) ** 2, axis=-2)


def star_weights(noise_variance_px2: np.ndarray, aniso_variance_px2: np.ndarray) -> np.ndarray:
    """Inverse-variance weights ``1 / (sigma_noise^2 + sigma_aniso^2)`` (broadcast; star first, axis
    last), normalised to sum 1 over the stars (axis 0)."""
    inverse = 1.0 / (np.asarray(noise_variance_px2) + np.asarray(aniso_variance_px2))
    return inverse / inverse.sum(axis=0)


def combined_positions(positions_px: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The weighted mean (..., frame, 2) of the stars' positions (star, ..., frame, 2) with
    ``weights`` (star, ..., 2) per axis (:func:`star_weights`): per frame over the stars that register
    it (their weights normalised again); NaN where none does."""
    positions = np.asarray(positions_px, dtype=np.float64)
    registered = np.isfinite(positions).all(axis=-1, keepdims=True)
    w = np.where(registered, np.asarray(weights, dtype=np.float64)[..., None, :], 0.0)
    total = w.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (np.where(registered, positions, 0.0) * w).sum(axis=0) / total
    return np.where(total > 0, mean, np.nan)
