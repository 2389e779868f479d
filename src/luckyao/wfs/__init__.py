"""Laser guide stars and their open-loop Shack-Hartmann sensors: beacons, spot model,
compiled exposure kernels (the plain step-by-step model beside them) and the sensor of the time loop."""

from ..exports import lazy_exports

EXPORTS = {
    "beacons": ("LgsConfig", "altitude_profile", "elongation_offsets_rad"),
    "shack_hartmann": ("ShackHartmann", "exposure_images", "measure_slopes"),
    "sensor": ("LgsSensor",),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
