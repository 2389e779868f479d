"""Adaptive-optics correction: the deformable mirror, open-loop command matrices and the
correction applied in the time loop (LTAO, GLAO; tip-tilt left alone), and the adaptive
apodisation of the science pupil."""

from ..exports import lazy_exports

EXPORTS = {
    "dm": ("DeformableMirror",),
    "control": ("command_matrix", "dm_slopes_matrix", "ground_layers"),
    "correction": ("OpenLoopCorrection", "DelayedDm"),
    "apodisation": ("SubapertureRegions", "Apodiser", "DelayedApodisation", "ApodisationSettings"),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
