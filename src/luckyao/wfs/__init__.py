"""Laser guide stars and their open-loop Shack-Hartmann sensors: beacons, spot model,
compiled exposure kernels (plain reference beside them) and the sensor of the time loop.

Public objects, by module --
beacons: LgsConfig, altitude_profile, elongation_offsets_rad; shack_hartmann: ShackHartmann,
exposure_images, reference_exposure_images, measure_slopes; sensor: LgsSensor.
"""
