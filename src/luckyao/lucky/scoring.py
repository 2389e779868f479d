"""Scores of lucky imaging: per-frame measures, and the integrated images of the partial sums.

Every score is :mod:`.metrics`'s (one home per formula); here they are applied to the
detected frames of a chunk (:func:`frame_sums`, :class:`MatchedStrehl`), to the partial
sums of :class:`.accumulation.PartialSums` (:func:`integrated_images`,
:func:`score_partial_sums`) and to the frames' values near the axis (:func:`value_at_peak`).
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import noise_streams
from .metrics import relative_to_diffraction_limit, strehl_from


def frame_sums(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row and column sums (k, n) float64 and peaks (k,) float32 of frames (k, n, n) float32
    (:func:`luckyao.lucky.noise_streams.frame_sums`; the noisy frames get them from their detection)."""
    k, n = frames.shape[:2]
    rows, cols, peak = np.empty((k, n)), np.empty((k, n)), np.empty(k, np.float32)
    noise_streams.frame_sums(frames, rows, cols, peak)
    return rows, cols, peak


@dataclass(frozen=True, eq=False)
class MatchedStrehl:
    """A frame's Strehl from its matched-filtered peak (``lucky.frame_strehl: matched_filter``):
    ``S = max(K * frame) / (F max(K * I_dl))``, ``K`` the Gaussian of the diffraction-limited
    core's FWHM (:class:`.registration.Registration` ``peak``'s filter), ``I_dl`` the unit-flux
    diffraction-limited image, ``F`` the frame's flux. The filter averages the read and photon
    noise over the core, so the bias of the single brightest pixel of a noisy frame (the
    maximum of many noisy pixels) shrinks; 1 for the diffraction-limited image."""

    registration: object
    """The ``peak`` :class:`.registration.Registration` whose filter is used."""
    filtered_peak: float
    """``max(K * I_dl)`` of the unit-flux diffraction-limited image."""

    @classmethod
    def of(cls, diffraction_limited: np.ndarray, core_fwhm_px: float) -> "MatchedStrehl":
        from .registration import Registration

        registration = Registration("peak", diffraction_limited, core_fwhm_px)
        unit = (diffraction_limited / diffraction_limited.sum()).astype(np.float32)[None]
        return cls(registration, float(registration.filtered(unit).max()))

    def __call__(self, frames: np.ndarray, flux: np.ndarray, spectra=None) -> np.ndarray:
        """Strehl ratios (k,) of frames (k, n, n) of flux (k,), their ``spectra`` if known
        (:class:`.registration.FrameSpectra`); NaN where the flux is not positive."""
        peaks = self.registration.filtered(frames, spectra).max(axis=(1, 2)).astype(np.float64)
        return strehl_from(peaks, flux, self.filtered_peak)


def integrated_images(partial: np.ndarray, n_crit: int, n_bins: int, last_bin: np.ndarray) -> np.ndarray:
    """Integrated images (criterion, fraction, det, \\*item) of the (det, criterion x bin, \\*item)
    partial sums (an item: a whole frame (n, n), or a sub-pixel method's vector,
    :class:`.cropped.CroppedFrames`): fraction ``k``'s is the sum of bins ``0..last_bin[k]``
    (cumulative sums made in place: ``partial`` is overwritten). Contiguous, so the d50's batches
    need no copy."""
    n_det, item = partial.shape[0], partial.shape[2:]
    cumulative = partial.reshape(n_det, n_crit, n_bins, *item)
    for b in range(1, n_bins):  # np.cumsum's sums, in place
        cumulative[:, :, b] += cumulative[:, :, b - 1]
    images = np.empty((n_crit, len(last_bin), n_det, *item))
    for i in range(n_det):
        images[:, :, i] = cumulative[i][:, last_bin]
    return images


def score_partial_sums(
    partial: np.ndarray,
    n_crit: int,
    n_bins: int,
    last_bin: np.ndarray,
    score: Callable,
    expected_flux: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """The :func:`integrated_images` of partial sums (``partial`` is overwritten) and their
    Strehl, FWHM [arcsec] and d50 [arcsec] (criterion, fraction, det) by ``score`` (the
    accumulation's: :class:`.accumulation.WholeFrames`, :class:`.cropped.CroppedFrames`), the
    Strehl over ``expected_flux`` (criterion, fraction, det) where not NaN (:func:`expected_fluxes`).
    One code path for the noisy and the noiseless sums, so equal sums give bit-identical scores."""
    images = integrated_images(partial, n_crit, n_bins, last_bin)
    return (images, *(score(images) if expected_flux is None else score(images, expected_flux)))


def expected_fluxes(flux_estimate: np.ndarray, bins: np.ndarray, last_bin: np.ndarray) -> np.ndarray:
    """The expected flux (criterion, fraction, det) of each integrated image: the sum of its
    frames' ``flux_estimate`` (det, frame) (:func:`.metrics.strehl_flux`; NaN for a noiseless
    detector, whose rows stay NaN), the frames of ``bins`` (det, criterion, frame) ``0..last_bin[k]``
    for fraction ``k`` (:func:`.ranking.selection_bins`)."""
    n_det, n_crit, _ = bins.shape
    n_bins = int(np.max(last_bin)) + 1
    out = np.full((n_crit, len(last_bin), n_det), np.nan)
    for i in range(n_det):
        if np.isnan(flux_estimate[i]).all():
            continue
        for c in range(n_crit):
            selected = bins[i, c] >= 0
            per_bin = np.bincount(bins[i, c][selected], weights=flux_estimate[i][selected], minlength=n_bins)
            out[c, :, i] = np.cumsum(per_bin)[last_bin]
    return out


def value_at_peak(
    frame_window: np.ndarray,
    window: np.ndarray,
    long_images: np.ndarray,
    frame_flux: np.ndarray,
    diffraction_limited_peak: float,
) -> np.ndarray:
    """Per detector and frame, ``frame[p] / (flux P_dl)`` at the brightest pixel ``p`` of
    the long exposure (``long_images`` (det, n, n)) among the pixels ``window`` (flat
    indices, around the axis), from the frames' values there (``frame_window``); ``frame_flux``
    (det, frame): the frames' Strehl fluxes (:func:`.metrics.strehl_flux`). When ``p`` is the
    long exposure's peak and the fluxes are equal (or the long exposure's is their sum), their
    mean is its Strehl (:func:`.metrics.strehl`)."""
    out = np.empty(frame_flux.shape)
    for i, image in enumerate(long_images):
        k = np.argmax(image.ravel()[window])
        out[i] = relative_to_diffraction_limit(frame_window[i, :, k], frame_flux[i], diffraction_limited_peak)
    return out
