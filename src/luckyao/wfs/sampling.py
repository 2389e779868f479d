"""The Shack-Hartmann's pupil sampling and its calibration draws' screens, without the optics'
imports (the study's resource estimates use them before any job)."""

import math

CALIBRATION_SCREEN_MAX = 8192
"""Samples across a calibration draw's screen beyond which it is 2x the pupil instead of 4x."""


def samples_per_subaperture(subaperture_m: float, n_pixels: int, pixel_scale_rad: float, wavelength_m: float) -> int:
    """``n_s``: the even number of pupil samples per sub-aperture side closest to ``d F / lambda``
    (at least 2), ``F`` the detector's field (``n_pixels`` x ``pixel_scale_rad``), so that the
    sub-aperture's FFT period ``lambda / dx`` is about ``F``: the sensor's cost grows as ``n_s^2``."""
    ideal = subaperture_m * n_pixels * pixel_scale_rad / wavelength_m
    return max(2, 2 * int(round(ideal / 2)))


def calibration_screen_size(n_pupil: int) -> int:
    """Samples across each turbulence draw's periodic screen of the WFS calibration
    (:func:`.calibration.measure_response`) for a pupil grid of ``n_pupil``: the power of two at
    least 4x the pupil (the sub-aperture scales in full) or, where that would exceed
    :data:`CALIBRATION_SCREEN_MAX` (a 39 m pupil at a 12" WFS field: 16,384^2, ~19 GB to draw),
    at least 2x: its quadrants still hold four disjoint pupils, and its side (~80 m at 39 m) is
    still several outer scales."""
    size = 1 << math.ceil(math.log2(4 * n_pupil))
    return size if size <= CALIBRATION_SCREEN_MAX else 1 << math.ceil(math.log2(2 * n_pupil))
