"""MAP reconstructors: tilt-removed LGS slopes -> optical path along a line of sight.

``R = A C_xx G^T P (P G C_xx G^T P + sigma^2 I)^-1`` from the covariances of
:mod:`.slopes` (Fusco et al. 2001, JOSA A 18, 2527), by one Cholesky
factorisation of the slope covariance shared by every target.
"""

import numpy as np
import scipy.linalg

from ..optics.pupil import PupilGrid, Telescope, TiltRemover
from .prior import TurbulencePrior
from .slopes import SlopeGeometry, cross_covariance, slope_covariance


def factorize(slope_cov: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor ``L`` of ``S`` (plain array, cacheable); overwrites nothing."""
    return scipy.linalg.cholesky(slope_cov, lower=True)


def apply_inverse(cholesky_lower: np.ndarray, cross_cov: np.ndarray) -> np.ndarray:
    """``R = C S^-1`` (n_points, n_slopes) from ``C`` (n_points, n_slopes) and ``L``."""
    return scipy.linalg.cho_solve((cholesky_lower, True), cross_cov.T).T


def reconstruction_points(telescope: Telescope, subaperture_m: float, points_per_subaperture: int) -> np.ndarray:
    """The reconstructors' points (n_points, 2) [m]: the pupil at the sub-aperture pitch over
    ``points_per_subaperture`` (:func:`pupil_points`)."""
    return pupil_points(telescope, subaperture_m / points_per_subaperture)[2]


def pupil_points(telescope: Telescope, pitch_m: float) -> tuple[PupilGrid, np.ndarray, np.ndarray]:
    """Grid of ``pitch_m`` over the pupil: ``(grid, mask (n, n), xy (n_valid, 2) [m])``."""
    grid = telescope.grid_for(pitch_m)
    mask = telescope.mask(grid)
    x, y = grid.xy_m
    return grid, mask, np.stack([x[mask], y[mask]], axis=-1)


def remove_tilt_rows(reconstructor: np.ndarray, points_xy_m: np.ndarray) -> np.ndarray:
    """Reconstructor whose output has piston, tip and tilt removed over the points."""
    remover = TiltRemover(x_m=points_xy_m[:, 0], y_m=points_xy_m[:, 1])
    return remover.residual(reconstructor.T.astype(np.float32)).T.copy()


def target_reconstructor(
    prior: TurbulencePrior,
    geometry: SlopeGeometry,
    noise_rms_rad: float,
    points_xy_m: np.ndarray,
    direction_rad=(0.0, 0.0),
    layer_indices=None,
    cholesky_lower: np.ndarray | None = None,
    remove_tilt: bool = True,
    n_edge: int = 2,
) -> np.ndarray:
    """``R`` (n_points, n_slopes) float32 [m / rad]: tilt-removed slopes -> optical
    path [m] along ``direction_rad`` at ``points_xy_m``, tilt-removed by default.

    ``R = P_target C_xx G^T (G C_xx G^T + C_nn)^-1``; pass the cached
    ``cholesky_lower`` of :func:`slope_covariance` (same noise) to skip it.
    """
    if cholesky_lower is None:
        cholesky_lower = factorize(slope_covariance(prior, geometry, noise_rms_rad, n_edge))
    cross = cross_covariance(prior, geometry, points_xy_m, direction_rad, layer_indices=layer_indices, n_edge=n_edge)
    rec = apply_inverse(cholesky_lower, cross).astype(np.float32)
    return remove_tilt_rows(rec, points_xy_m) if remove_tilt else rec
