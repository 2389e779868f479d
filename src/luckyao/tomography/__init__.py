"""Minimum-variance (MAP) LGS tomography in slope space, and the lgs_rms criterion."""

from ..exports import lazy_exports

EXPORTS = {
    "prior": ("TurbulencePrior",),
    "slopes": ("SlopeGeometry", "slope_covariance", "cross_covariance"),
    "reconstructor": ("target_reconstructor",),
    "criterion": ("lgs_rms_nm", "lucky_frame_rms_nm", "LgsRmsEstimator"),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
