"""Light from the screens to the camera: pupil, geometric propagation, far-field imaging,
and the analytic long exposure.

Public objects, by module --
pupil: PupilGrid, Telescope, TiltRemover; propagation: Propagator; imaging: Camera, Imager;
farfield: FarField; sincos: sincos, cos_sin; long_exposure: long_exposure_strehl.
"""
