"""Light from the screens to the camera: pupil, geometric propagation, far-field imaging,
and the analytic long exposure."""

from ..exports import lazy_exports

EXPORTS = {
    "pupil": ("PupilGrid", "Telescope", "TiltRemover"),
    "propagation": ("Propagator",),
    "imaging": ("Camera", "Imager"),
    "farfield": ("FarField",),
    "sincos": ("sincos", "cos_sin"),
    "long_exposure": ("long_exposure_strehl",),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
