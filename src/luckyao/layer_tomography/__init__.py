"""Matrix-free MAP tomography in layer space: sparse ray tracing, a bi-harmonic prior, FDPCG.

The layered alternative to the dense slope-space reconstructor of :mod:`luckyao.tomography`, for
systems whose slope covariance is too large to factorise (docs/methods/layer-tomography.md).
"""

from ..exports import lazy_exports

EXPORTS = {
    "grids": ("LayerGrids",),
    "operators": ("MeasurementOperator", "BeaconRayTracing", "SubapertureGradient", "bilinear_matrix"),
    "prior": ("BiharmonicPrior", "von_karman_psd_m2"),
    "noise": ("SlopeNoise",),
    "preconditioner": ("FourierPreconditioner",),
    "solver": ("LayerTomography", "pcg"),
    "projection": ("LineOfSight", "DmProjection", "line_of_sight_matrix", "sparse_influence"),
    "assembly": ("build_tomography",),
    "correction": ("LayerEstimator", "LayerCorrection"),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
