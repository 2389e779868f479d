"""Lucky imaging of a frame cube: detector noise, image metrics, ranking, recentred
accumulation and scoring, driven by :func:`run_lucky` (module ``pipeline``); the compiled loops:
``noise_streams`` (keyed random streams, detector noise), ``radial_sums`` (encircled energy),
``adds`` (the partial sums), ``image_helpers`` (crops, shifts, the FWHM's region)."""

from ..exports import lazy_exports

EXPORTS = {
    "detector": ("Detector", "KeyedNoise"),
    "metrics": ("strehl", "fwhm_arcsec", "centroid_px", "score_images", "EncircledEnergy"),
    "ranking": ("ExternalCriterion", "fraction_counts", "rank_frames", "selection_bins"),
    "accumulation": ("recentring_shifts_px", "PartialSums", "TimeBlocks"),
    "pipeline": ("run_lucky", "run_lucky_methods", "ImageReference"),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
