"""Minimum-variance (MAP) LGS tomography in slope space, and the lgs_rms criterion.

Public objects, by module --
prior: TurbulencePrior; slopes: SlopeGeometry, slope_covariance, cross_covariance;
reconstructor: target_reconstructor, layer_reconstructor; criterion: lgs_rms_nm, lucky_frame_rms_nm.
"""
