"""Laser guide stars and their open-loop Shack-Hartmann sensors: beacons, spot model (the
optics), compiled exposure kernels (plain reference beside them), detector noise, slope
estimators, the calibrated slope response and the sensor of the time loop.

Public objects, by module --
beacons: LgsConfig, altitude_profile, elongation_offsets_rad; shack_hartmann: ShackHartmann,
exposure_images, reference_exposure_images; detector: add_noise; centroiders: CentreOfGravity,
ThresholdedCentreOfGravity, Correlation, SlopeEstimator, make_centroider; calibration:
BeaconSeeing, SlopeResponse, measure_response, reference_spot_spectra; sensor: LgsSensor,
measure_slopes.
"""
