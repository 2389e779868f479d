"""Minimum-variance (MAP) LGS tomography in slope space.

The turbulence is a set of layers ("virtual DMs") at ``heights_m``, each a
von Karman phase of ``r0_layer = r0 * fraction^(-3/5)``. With slopes
``s = P (G x + n)`` (``G`` the cone-projected mean-gradient model of every
beacon's sub-apertures, ``P`` removing each beacon's mean tip-tilt) the MAP /
minimum-mean-square-error estimate of any linear function ``y = A x`` of the
layers (e.g. the phase along a line of sight) is

    y_hat = A C_xx G^T P (P G C_xx G^T P + sigma^2 I)^-1 s

(Fusco et al. 2001, JOSA A 18, 2527; Neichel et al. 2009, JOSA A 26, 219;
the "slope-space" form of e.g. Vidal et al. 2010). ``C_xx`` is block
diagonal over layers, so every covariance is a sum over layers of the
von Karman phase covariance evaluated between cone-projected points -- no
layer grid is ever inverted and nothing of size (layer points)^2 is formed.

Slope model: the mean gradient over a square sub-aperture of side ``d`` is
the difference of edge means, ``s_x = (1/d) <phi(x + d/2, y') - phi(x - d/2, y')>``,
with ``n_edge`` mid-point samples per edge. Units: optical path [m],
slopes = angle of arrival [rad], covariances in m^2, m rad, rad^2.

Slope vectors are flattened from ``(n_beacons, 2, n_valid)`` (axis 1 = x, y).
"""

from dataclasses import dataclass

import numpy as np

from ..geometry import footprint_scale
from .prior import StructureTable, TurbulencePrior


@dataclass(frozen=True, eq=False)
class SlopeGeometry:
    """What the tomography needs of the WFS and the asterism.

    ``subaperture_xy_m`` (n_valid, 2) centres on a square lattice of pitch
    ``subaperture_m``; ``directions_rad`` (n_beacons, 2); one ``beacon_height_m``
    (``inf`` for natural stars).
    """

    subaperture_xy_m: np.ndarray
    subaperture_m: float
    directions_rad: np.ndarray
    beacon_height_m: float

    @classmethod
    def from_wfs(cls, wfs, lgs_config, directions_rad=None) -> "SlopeGeometry":
        """From a :class:`luckyao.wfs.shack_hartmann.ShackHartmann` and :class:`luckyao.wfs.beacons.LgsConfig`."""
        directions = lgs_config.directions_rad if directions_rad is None else directions_rad
        return cls(
            np.asarray(wfs.subaperture_xy_m, dtype=float),
            wfs.subaperture_m,
            np.atleast_2d(np.asarray(directions, dtype=float)),
            lgs_config.height_m,
        )

    @property
    def n_beacons(self) -> int:
        return self.directions_rad.shape[0]

    @property
    def n_valid(self) -> int:
        return self.subaperture_xy_m.shape[0]

    @property
    def n_slopes(self) -> int:
        return 2 * self.n_beacons * self.n_valid


def _edge_points(n_edge: int):
    """Sample offsets (2, 2 n_edge, 2) [units of d] and weights (2 n_edge,) [1/d].

    For x-slopes, mid-points of the right (+) and left (-) edges; y likewise.
    """
    e = (np.arange(n_edge) + 0.5) / n_edge - 0.5
    half = np.full(n_edge, 0.5)
    x_points = np.concatenate([np.stack([half, e], -1), np.stack([-half, e], -1)])
    y_points = x_points[:, ::-1]
    weights = np.concatenate([np.ones(n_edge), -np.ones(n_edge)]) / n_edge
    return np.stack([x_points, y_points]), weights


def _remove_beacon_means(matrix: np.ndarray, geometry: SlopeGeometry, axis: int) -> None:
    """In place: subtract, along ``axis`` (a slope axis of length n_slopes), each
    beacon's mean x and y slope (the projector P)."""
    shape = list(matrix.shape)
    new_shape = shape[:axis] + [geometry.n_beacons * 2, geometry.n_valid] + shape[axis + 1 :]
    view = matrix.reshape(new_shape)
    view -= view.mean(axis=axis + 1, keepdims=True)


def slope_covariance(
    prior: TurbulencePrior,
    geometry: SlopeGeometry,
    noise_rms_rad: float,
    n_edge: int = 2,
    noise_covariance_rad2: np.ndarray | None = None,
) -> np.ndarray:
    """``S = P G C_xx G^T P + sigma^2 I`` (n_slopes, n_slopes) float64 [rad^2], or with
    ``noise_covariance_rad2`` (n_valid, 2, 2) [rad^2] (each sub-aperture's x, y noise, every
    beacon's the same: ``studyspec.case.slope_noise_covariance_rad2``) that in place of ``sigma^2 I``.

    For beacons b, b' and layer l the covariance of two sub-aperture slopes
    depends only on the lattice offset of the sub-apertures, so it is
    evaluated once per offset, ``-1/2 sum w w' D_l(|(Delta + o - o')(1 - h/H) + (theta_b - theta_b') h|)``
    (weights sum to zero, so ``B`` -> ``-D/2``), then gathered. ``sigma`` =
    ``noise_rms_rad`` per slope (measurement noise and regularisation).
    """
    table = StructureTable(prior.outer_scale_m, prior.wavelength_m)
    d = geometry.subaperture_m
    lattice = np.rint(geometry.subaperture_xy_m / d * 2).astype(int)  # 2x: half-integer centres
    lattice = (lattice - lattice.min(axis=0)) // 2
    span = lattice.max(axis=0) + 1
    offsets = np.stack(
        np.meshgrid(np.arange(-span[0] + 1, span[0]), np.arange(-span[1] + 1, span[1]), indexing="ij"), -1
    )
    offsets = offsets.reshape(-1, 2).astype(float)  # (n_off, 2) (x, y) in units of d
    points, weights = _edge_points(n_edge)
    pair_offset = points[:, None, :, None, :] - points[None, :, None, :, :]  # (2,2,p,p,2)
    pair_weight = weights[:, None] * weights[None, :] / d**2  # (p, p)
    directions = geometry.directions_rad
    n_b = geometry.n_beacons
    table_cov = np.zeros((n_b, n_b, 2, 2, offsets.shape[0]))
    for height, fraction in zip(prior.heights_m, prior.cn2_fractions):
        if fraction == 0:
            continue
        scale = float(footprint_scale(height, geometry.beacon_height_m))
        shift = (directions[:, None, :] - directions[None, :, :]) * height  # (b, b', 2)
        strength = fraction ** (-3 / 5) * prior.r0_m
        for a in range(2):
            for c in range(2):
                sep = (offsets[:, None, None, :] + pair_offset[a, c][None]) * d * scale
                sep = sep[None, None] + shift[:, :, None, None, None, :]
                dist = np.sqrt((sep**2).sum(-1))  # (b, b', n_off, p, p)
                value = table(dist) * strength ** (-5 / 3)
                table_cov[:, :, a, c] += -0.5 * np.einsum("...pq,pq->...", value, pair_weight)
    # gather: offset index of (i - j)
    delta = lattice[:, None, :] - lattice[None, :, :] + (span - 1)
    index = delta[..., 0] * (2 * span[1] - 1) + delta[..., 1]  # (n_v, n_v)
    n_v = geometry.n_valid
    cov = table_cov[..., index]  # (b, b', a, c, i, j)
    cov = cov.transpose(0, 2, 4, 1, 3, 5).reshape(2 * n_b * n_v, 2 * n_b * n_v)
    cov = np.ascontiguousarray(cov)
    _remove_beacon_means(cov, geometry, 0)
    _remove_beacon_means(cov, geometry, 1)
    if noise_covariance_rad2 is None:
        cov[np.diag_indices_from(cov)] += noise_rms_rad**2
    else:
        blocks = cov.reshape(n_b, 2, n_v, n_b, 2, n_v)
        v = np.arange(n_v)
        for b in range(n_b):
            for a in range(2):
                for c in range(2):
                    blocks[b, a, v, b, c, v] += noise_covariance_rad2[:, a, c]
    return cov


def cross_covariance(
    prior: TurbulencePrior,
    geometry: SlopeGeometry,
    points_xy_m: np.ndarray,
    direction_rad=(0.0, 0.0),
    source_height_m: float = np.inf,
    layer_indices=None,
    n_edge: int = 2,
) -> np.ndarray:
    """``A C_xx G^T P`` (n_points, n_slopes) [m rad]: covariance of the optical path
    along a line of sight with the tilt-removed slopes.

    The line of sight is ``direction_rad`` from the pupil points ``points_xy_m``
    (n_points, 2) [m] to a source at ``source_height_m`` (inf: the science
    target); only layers ``layer_indices`` (default all) are summed -- e.g.
    ``[0]`` for the ground-layer (GLAO) projection. With ``source_height_m`` =
    0 and ``direction_rad`` = 0 the "pupil" points are coordinates on the layer
    itself (a virtual-DM estimate, one layer index).
    """
    table = StructureTable(prior.outer_scale_m, prior.wavelength_m)
    d = geometry.subaperture_m
    points_xy_m = np.asarray(points_xy_m, dtype=float)
    direction = np.asarray(direction_rad, dtype=float)
    edge, weights = _edge_points(n_edge)
    n_b, n_v = geometry.n_beacons, geometry.n_valid
    out = np.zeros((points_xy_m.shape[0], n_b, 2, n_v))
    layers = range(len(prior.heights_m)) if layer_indices is None else layer_indices
    for layer in layers:
        height = prior.heights_m[layer]
        fraction = prior.cn2_fractions[layer]
        if fraction == 0:
            continue
        strength = (fraction ** (-3 / 5) * prior.r0_m) ** (-5 / 3)
        target_scale = 1.0 if source_height_m == 0 else float(footprint_scale(height, source_height_m))
        target = points_xy_m * target_scale + direction * height  # (t, 2)
        scale = float(footprint_scale(height, geometry.beacon_height_m))
        for b in range(n_b):
            centres = geometry.subaperture_xy_m * scale + geometry.directions_rad[b] * height
            for a in range(2):
                samples = centres[:, None, :] + edge[a][None] * d * scale  # (v, p, 2)
                sums = table.weighted_sums(target, samples, weights)
                out[:, b, a] += (-0.5 * strength / d) * sums
    out = out.reshape(points_xy_m.shape[0], -1)
    _remove_beacon_means(out, geometry, 1)
    return out
