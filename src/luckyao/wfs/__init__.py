"""Laser guide stars and their open-loop Shack-Hartmann sensors: beacons, spot model (the
optics), compiled exposure kernels (the plain step-by-step model beside them), detector noise,
slope estimators, the calibrated slope response and the sensor of the time loop, and the
geometric sensor (mean gradients, the elongated spots' NEA as noise)."""

from ..exports import lazy_exports

EXPORTS = {
    "beacons": ("LgsConfig", "altitude_profile", "elongation_offsets_rad"),
    "shack_hartmann": ("ShackHartmann", "exposure_images"),
    "detector": ("add_noise",),
    "centroiders": (
        "CentreOfGravity",
        "ThresholdedCentreOfGravity",
        "Correlation",
        "SlopeEstimator",
        "make_centroider",
    ),
    "calibration": ("BeaconSeeing", "SlopeResponse", "measure_response", "reference_spot_spectra"),
    "sensor": ("LgsSensor", "measure_slopes"),
    "geometric": ("GeometricLgsSensor", "noise_equivalent_angle_rad2"),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
