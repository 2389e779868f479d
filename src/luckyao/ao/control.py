"""Open-loop AO control: tilt-removed LGS slopes -> DM commands, and the slopes
the DM alone would produce (for the pseudo-closed-loop residual).

Command matrix (minimum-variance estimate, then DM fit; Fusco et al. 2001,
JOSA A 18, 2527, who show the optimal correction is the tomographic MMSE
estimate projected on the DM):

    M = F A C_xx G^T P (P G C_xx G^T P + sigma^2 I)^-1

with ``A C_xx G^T P`` the covariance of the optical path at pupil fitting
points with the slopes (:func:`luckyao.tomography.slopes.cross_covariance`) and ``F``
the DM fit of those points (:meth:`.dm.DeformableMirror.fit_matrix`),
which removes piston, tip and tilt (LGS do not measure tip-tilt; the DM must
add none). ``F`` is applied before the inverse, so the solve has only
``n_act`` right-hand sides.

* LTAO: every layer, along the target direction.
* GLAO: only the layers at or below ``ground_max_height_m`` (default: the
  lowest layer), along the telescope axis.

Units: slopes = angle of arrival [rad] (mean gradient of the optical path);
commands = optical path added by the DM [m]; it compensates the turbulence, so
the residual optical path is ``turbulence - H c`` and the pseudo-closed-loop
slopes are ``s - D c`` with ``D`` from :func:`dm_slopes_matrix`. Slope vectors
are flattened from ``(n_beacons, 2, n_valid)`` (axis 1 = x, y).
"""

import numpy as np

from ..tomography.prior import TurbulencePrior
from ..tomography.reconstructor import apply_inverse, factorize, pupil_points
from ..tomography.slopes import SlopeGeometry, cross_covariance, slope_covariance
from .dm import DeformableMirror

MODES = ("ltao", "glao")


def ground_layers(prior: TurbulencePrior, ground_max_height_m: float | None = None) -> list[int]:
    """Indices of the layers a GLAO DM takes: height <= ``ground_max_height_m``
    [m], by default the lowest layer only."""
    heights = np.asarray(prior.heights_m, dtype=float)
    if ground_max_height_m is None:
        return [int(np.argmin(heights))]
    layers = [int(i) for i in np.flatnonzero(heights <= ground_max_height_m)]
    if not layers:
        raise ValueError(f"no layer at or below {ground_max_height_m} m")
    return layers


def fit_points(dm: DeformableMirror, fit_pitch_m: float | None = None) -> np.ndarray:
    """Pupil points (n, 2) [m] at which an estimate is fitted onto the DM: pitch ``fit_pitch_m``
    [m], by default a quarter of the DM pitch (see :func:`command_matrix`)."""
    return pupil_points(dm.telescope, dm.pitch_m / 4 if fit_pitch_m is None else fit_pitch_m)[2]


def command_matrix(
    prior: TurbulencePrior,
    geometry: SlopeGeometry,
    noise_rms_rad: float,
    dm: DeformableMirror,
    mode: str,
    direction_rad=(0.0, 0.0),
    ground_max_height_m: float | None = None,
    fit_pitch_m: float | None = None,
    cholesky_lower: np.ndarray | None = None,
) -> np.ndarray:
    """``M`` (n_act, n_slopes) float32 [m / rad]: tilt-removed slopes -> DM commands.

    ``mode`` is ``"ltao"`` (all layers, along ``direction_rad`` (2,) [rad]) or
    ``"glao"`` (layers from :func:`ground_layers`, on axis; ``direction_rad``
    is not used). The estimate is formed at pupil points of pitch
    ``fit_pitch_m`` [m] (default a quarter of the DM pitch ``d``; for the
    8x8 WFS, 9x9 DM and the study's profile the corrected surface differs by
    1 % rms from that with points at ``d/8``, by 4 % with ``d/2``) and fitted
    onto the DM without piston, tip or tilt. ``noise_rms_rad`` is the slope noise (and regularisation) of
    :func:`luckyao.tomography.slopes.slope_covariance`; pass its cached
    ``cholesky_lower`` (same prior, geometry and noise) to skip the factorisation.
    """
    if mode == "ltao":
        layers, direction = None, direction_rad
    elif mode == "glao":
        layers, direction = ground_layers(prior, ground_max_height_m), (0.0, 0.0)
    else:
        raise ValueError(f"unknown correction mode {mode!r}; known: {MODES}")
    points = fit_points(dm, fit_pitch_m)
    if cholesky_lower is None:
        cholesky_lower = factorize(slope_covariance(prior, geometry, noise_rms_rad))
    cross = cross_covariance(prior, geometry, points, direction, layer_indices=layers)
    return apply_inverse(cholesky_lower, dm.fit_matrix(points) @ cross).astype(np.float32)


def dm_slopes_matrix(dm: DeformableMirror, subapertures, n_beacons: int, n_edge: int = 8) -> np.ndarray:
    """``D`` (n_slopes, n_act) float32 [rad / m]: tilt-removed slopes of every
    beacon's WFS for DM commands [m of optical path].

    ``subapertures`` is a :class:`luckyao.tomography.slopes.SlopeGeometry` or a
    :class:`luckyao.wfs.shack_hartmann.ShackHartmann` (its ``subaperture_xy_m`` and
    ``subaperture_m`` are used). The DM is conjugate to the pupil, so every
    beacon sees the same surface. The mean gradient over a square of side
    ``d`` is exactly the difference of its edge means divided by ``d``; each
    edge mean is an ``n_edge``-point Gauss-Legendre quadrature of the
    influence functions (smooth on the scale of the DM pitch). Each beacon's
    mean x and y slope is then removed, as for the measured slopes.
    """
    d = subapertures.subaperture_m
    centres = np.asarray(subapertures.subaperture_xy_m, dtype=float)
    nodes, weights = np.polynomial.legendre.leggauss(n_edge)
    along = nodes * d / 2  # (n_edge,) offsets along an edge [m]
    slopes = np.zeros((2, len(centres), dm.n_valid))
    for axis in range(2):
        for sign in (1.0, -1.0):
            offset = np.zeros((1, n_edge, 2))
            offset[..., axis] = sign * d / 2
            offset[..., 1 - axis] = along
            edge = centres[:, None, :] + offset  # (n_valid, n_edge, 2)
            h = dm.influence_matrix(edge[..., 0], edge[..., 1]).reshape(len(centres), n_edge, -1)
            slopes[axis] += sign * np.einsum("e,vea->va", weights / 2, h) / d
    slopes -= slopes.mean(axis=1, keepdims=True)
    tiled = np.broadcast_to(slopes, (n_beacons,) + slopes.shape)
    return tiled.reshape(-1, dm.n_valid).astype(np.float32)
