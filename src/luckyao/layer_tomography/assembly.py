"""The layer-space tomography of one system, assembled from what the dense path is built from:
the prior (:class:`luckyao.tomography.prior.TurbulencePrior`), the WFS
(:class:`luckyao.wfs.shack_hartmann.ShackHartmann`), the beacons and the slope noise."""

import numpy as np

from .grids import LayerGrids
from .noise import SlopeNoise, SubapertureNoise
from .operators import MeasurementOperator
from .preconditioner import FourierPreconditioner
from .prior import BiharmonicPrior
from .solver import LayerTomography

DEFAULT_RTOL = 3e-4
"""A cold-started PCG stops at ``|b - A x| <= rtol |b|``; see docs/methods/layer-tomography.md for the choice."""

DEFAULT_WARM_RTOL = 1e-3
"""A warm-started PCG's ``rtol``: at 4.2 and 39 m the on-axis estimate is as far from the true
layers as a converged solve's (docs/methods/layer-tomography.md), in half the iterations of 3e-4."""


def build_tomography(
    prior,
    wfs,
    beacon_directions_rad,
    beacon_height_m: float,
    noise_rms_rad: float,
    target_directions_rad=((0.0, 0.0),),
    rtol: float = DEFAULT_RTOL,
    warm_rtol: float = DEFAULT_WARM_RTOL,
    match_frequency_per_m: float | None = None,
    preconditioned: bool = True,
    samples_per_subaperture: int = 2,
    dtype=np.float32,
    noise_covariance_rad2: np.ndarray | None = None,
) -> LayerTomography:
    """:class:`.solver.LayerTomography` (PCG to ``rtol`` from a cold start, to ``warm_rtol`` from
    the previous exposure's solution) on grids covering every beacon and target (directions
    (n, 2) [rad]) on the prior's layers; the prior matched at ``match_frequency_per_m`` [1/m]
    (default the WFS's Nyquist frequency ``1 / (2 d)``); ``samples_per_subaperture`` pupil samples
    across a sub-aperture (2: layers at half the sub-aperture pitch, cone-scaled; 1: Fried geometry at the
    sub-aperture pitch, 40-60 % more DM-fitted residual than the dense path on the study's systems);
    the solve in ``dtype`` (float32: half the memory traffic of float64, the same estimate to 1e-4);
    the slopes weighed by ``noise_covariance_rad2`` (n_valid, 2, 2) [rad^2] when given (a noisy
    geometric WFS's NEA), else by ``noise_rms_rad``."""
    d = wfs.subaperture_m
    grids = LayerGrids.covering(
        prior.heights_m,
        beacon_height_m,
        d / samples_per_subaperture,
        wfs.n_subapertures * d / 2,
        beacon_directions_rad,
        target_directions_rad,
    )
    operator = MeasurementOperator.build(grids, wfs.valid, d, beacon_directions_rad)
    match = 1 / (2 * d) if match_frequency_per_m is None else match_frequency_per_m
    biharmonic = BiharmonicPrior(prior, grids, match, dtype)
    if noise_covariance_rad2 is None:
        noise = SlopeNoise.uniform(noise_rms_rad)
    else:
        noise = SubapertureNoise(np.asarray(noise_covariance_rad2, dtype=float))
    preconditioner = (
        FourierPreconditioner.build(operator, biharmonic, noise.mean_inverse_rad2, dtype) if preconditioned else None
    )
    return LayerTomography(operator, biharmonic, noise, preconditioner, rtol=rtol, warm_rtol=warm_rtol, dtype=dtype)
