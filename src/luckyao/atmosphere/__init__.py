"""Layered frozen-flow von Karman turbulence: its statistics, its phase screens and its layers' strengths in time."""

from ..exports import lazy_exports

EXPORTS = {
    "statistics": (
        "Layer",
        "R0Schedule",
        "von_karman_psd",
        "von_karman_covariance",
        "von_karman_structure_function",
        "r0_at_wavelength",
    ),
    "screens": ("StripSpec", "strip_spec", "strip_screen", "ScreenSet"),
    "intermittency": ("LayerVariability",),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
