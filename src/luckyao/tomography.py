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

import math

import numba
import numpy as np
import scipy.linalg
import scipy.special

from .pupil import PupilGrid, Telescope, TiltRemover
from .units import REFERENCE_WAVELENGTH_M


# --- turbulence prior ---------------------------------------------------------
@dataclass(frozen=True)
class TurbulencePrior:
    """Layered von Karman prior: ``r0_m`` at ``wavelength_m``, outer scale, layers."""

    r0_m: float
    outer_scale_m: float
    heights_m: tuple[float, ...]
    cn2_fractions: tuple[float, ...]
    wavelength_m: float = REFERENCE_WAVELENGTH_M

    def __post_init__(self):
        if len(self.heights_m) != len(self.cn2_fractions):
            raise ValueError("heights_m and cn2_fractions differ in length")


def von_karman_covariance_rad2(r_m, r0_m: float, outer_scale_m: float):
    """Phase covariance ``B(r)`` [rad^2 at r0's wavelength] of von Karman turbulence.

    ``B(r) = (L0/r0)^(5/3) 2^(-5/6) Gamma(11/6) / pi^(8/3) (24/5 Gamma(6/5))^(5/6)
    (2 pi r / L0)^(5/6) K_(5/6)(2 pi r / L0)`` and its r -> 0 limit
    (e.g. Conan 2000, thesis; Assemat et al. 2006, Opt. Express 14, 988).
    """
    r = np.asarray(r_m, dtype=float)
    gamma = scipy.special.gamma
    coefficient = ((outer_scale_m / r0_m) ** (5 / 3) * 2 ** (-5 / 6) * gamma(11 / 6)
                   / np.pi ** (8 / 3) * (24 / 5 * gamma(6 / 5)) ** (5 / 6))
    u = 2 * np.pi * r / outer_scale_m
    at_zero = coefficient * 2 ** (-1 / 6) * gamma(5 / 6)  # lim u^(5/6) K_(5/6)(u)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = coefficient * u ** (5 / 6) * scipy.special.kv(5 / 6, u)
    return np.where(u > 0, value, at_zero)


def von_karman_structure_function_rad2(r_m, r0_m: float, outer_scale_m: float):
    """``D(r) = 2 (B(0) - B(r))`` [rad^2]; -> 6.88 (r/r0)^(5/3) for r << L0."""
    b0 = von_karman_covariance_rad2(0.0, r0_m, outer_scale_m)
    return 2 * (b0 - von_karman_covariance_rad2(r_m, r0_m, outer_scale_m))


@dataclass(frozen=True, eq=False)
class _StructureTable:
    """Fast ``D(r)`` [m^2 of optical path] for r0 = 1 m at the prior wavelength.

    Tabulates ``D(r) / r^(5/3)`` (smooth, finite at 0) on a log grid
    (relative interpolation error < 1e-6); scale by ``r0^(-5/3)``.
    """

    outer_scale_m: float
    wavelength_m: float

    def __post_init__(self):
        log_r = np.linspace(np.log(1e-5), np.log(1e4), 4000)
        r = np.exp(log_r)
        ratio = von_karman_structure_function_rad2(r, 1.0, self.outer_scale_m) / r ** (5 / 3)
        object.__setattr__(self, "_log_r", log_r)
        object.__setattr__(self, "_ratio", ratio * (self.wavelength_m / (2 * np.pi)) ** 2)

    def __call__(self, r_m: np.ndarray) -> np.ndarray:
        r = np.maximum(r_m, 1e-12)
        return np.interp(np.log(r), self._log_r, self._ratio) * r ** (5 / 3)

    def weighted_sums(self, targets: np.ndarray, samples: np.ndarray,
                      weights: np.ndarray) -> np.ndarray:
        """``sum_p w_p D(|t - s_vp|)`` (n_t, n_v) for targets (n_t, 2), samples (n_v, p, 2)."""
        out = np.empty((targets.shape[0], samples.shape[0]))
        _weighted_structure_sums(np.ascontiguousarray(targets), np.ascontiguousarray(samples),
                                 np.ascontiguousarray(weights, dtype=float), self._log_r[0],
                                 self._log_r[1] - self._log_r[0], self._ratio, out)
        return out


@numba.njit(nogil=True)
def _weighted_structure_sums(targets, samples, weights, log_r_first, log_r_step, ratio,
                             out):  # pragma: no cover (jit)
    """Fused loop for :meth:`_StructureTable.weighted_sums` (no temporaries)."""
    n_table = ratio.size
    for t in range(targets.shape[0]):
        tx = targets[t, 0]
        ty = targets[t, 1]
        for v in range(samples.shape[0]):
            acc = 0.0
            for p in range(samples.shape[1]):
                dx = tx - samples[v, p, 0]
                dy = ty - samples[v, p, 1]
                r2 = dx * dx + dy * dy
                if r2 > 0.0:
                    log_r2 = math.log(r2)
                    position = (0.5 * log_r2 - log_r_first) / log_r_step
                    if position < 0.0:
                        position = 0.0
                    i = int(position)
                    if i > n_table - 2:
                        i = n_table - 2
                    frac = position - i
                    value = ratio[i] + (ratio[i + 1] - ratio[i]) * frac
                    acc += weights[p] * value * math.exp(log_r2 * (5.0 / 6.0))
            out[t, v] = acc


# --- geometry -----------------------------------------------------------------
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
        """From a :class:`luckyao.wfs.ShackHartmann` and :class:`luckyao.lgs.LgsConfig`."""
        directions = lgs_config.directions_rad if directions_rad is None else directions_rad
        return cls(np.asarray(wfs.subaperture_xy_m, dtype=float), wfs.subaperture_m,
                   np.atleast_2d(np.asarray(directions, dtype=float)), lgs_config.height_m)

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
    new_shape = shape[:axis] + [geometry.n_beacons * 2, geometry.n_valid] + shape[axis + 1:]
    view = matrix.reshape(new_shape)
    view -= view.mean(axis=axis + 1, keepdims=True)


def slope_covariance(prior: TurbulencePrior, geometry: SlopeGeometry, noise_rms_rad: float,
                     n_edge: int = 2) -> np.ndarray:
    """``S = P G C_xx G^T P + sigma^2 I`` (n_slopes, n_slopes) float64 [rad^2].

    For beacons b, b' and layer l the covariance of two sub-aperture slopes
    depends only on the lattice offset of the sub-apertures, so it is
    evaluated once per offset, ``-1/2 sum w w' D_l(|(Delta + o - o')(1 - h/H) + (theta_b - theta_b') h|)``
    (weights sum to zero, so ``B`` -> ``-D/2``), then gathered. ``sigma`` =
    ``noise_rms_rad`` per slope (measurement noise and regularisation).
    """
    table = _StructureTable(prior.outer_scale_m, prior.wavelength_m)
    d = geometry.subaperture_m
    lattice = np.rint(geometry.subaperture_xy_m / d * 2).astype(int)  # 2x: half-integer centres
    lattice = (lattice - lattice.min(axis=0)) // 2
    span = lattice.max(axis=0) + 1
    offsets = np.stack(np.meshgrid(np.arange(-span[0] + 1, span[0]),
                                   np.arange(-span[1] + 1, span[1]), indexing="ij"), -1)
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
        scale = 1.0 - height / geometry.beacon_height_m
        shift = (directions[:, None, :] - directions[None, :, :]) * height  # (b, b', 2)
        strength = fraction ** (-3 / 5) * prior.r0_m
        for a in range(2):
            for c in range(2):
                sep = ((offsets[:, None, None, :] + pair_offset[a, c][None]) * d * scale)
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
    cov[np.diag_indices_from(cov)] += noise_rms_rad**2
    return cov


def cross_covariance(prior: TurbulencePrior, geometry: SlopeGeometry, points_xy_m: np.ndarray,
                     direction_rad=(0.0, 0.0), source_height_m: float = np.inf,
                     layer_indices=None, n_edge: int = 2) -> np.ndarray:
    """``A C_xx G^T P`` (n_points, n_slopes) [m rad]: covariance of the optical path
    along a line of sight with the tilt-removed slopes.

    The line of sight is ``direction_rad`` from the pupil points ``points_xy_m``
    (n_points, 2) [m] to a source at ``source_height_m`` (inf: the science
    target); only layers ``layer_indices`` (default all) are summed -- e.g.
    ``[0]`` for the ground-layer (GLAO) projection. With ``source_height_m`` =
    0 and ``direction_rad`` = 0 the "pupil" points are coordinates on the layer
    itself (a virtual-DM estimate, one layer index).
    """
    table = _StructureTable(prior.outer_scale_m, prior.wavelength_m)
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
        target_scale = 1.0 if source_height_m == 0 else 1.0 - height / source_height_m
        target = points_xy_m * target_scale + direction * height  # (t, 2)
        scale = 1.0 - height / geometry.beacon_height_m
        for b in range(n_b):
            centres = geometry.subaperture_xy_m * scale + geometry.directions_rad[b] * height
            for a in range(2):
                samples = centres[:, None, :] + edge[a][None] * d * scale  # (v, p, 2)
                sums = table.weighted_sums(target, samples, weights)
                out[:, b, a] += (-0.5 * strength / d) * sums
    out = out.reshape(points_xy_m.shape[0], -1)
    _remove_beacon_means(out, geometry, 1)
    return out


# --- reconstructors -------------------------------------------------------------
def factorize(slope_cov: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor ``L`` of ``S`` (plain array, cacheable); overwrites nothing."""
    return scipy.linalg.cholesky(slope_cov, lower=True)


def apply_inverse(cholesky_lower: np.ndarray, cross_cov: np.ndarray) -> np.ndarray:
    """``R = C S^-1`` (n_points, n_slopes) from ``C`` (n_points, n_slopes) and ``L``."""
    return scipy.linalg.cho_solve((cholesky_lower, True), cross_cov.T).T


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


def target_reconstructor(prior: TurbulencePrior, geometry: SlopeGeometry, noise_rms_rad: float,
                         points_xy_m: np.ndarray, direction_rad=(0.0, 0.0), layer_indices=None,
                         cholesky_lower: np.ndarray | None = None, remove_tilt: bool = True,
                         n_edge: int = 2) -> np.ndarray:
    """``R`` (n_points, n_slopes) float32 [m / rad]: tilt-removed slopes -> optical
    path [m] along ``direction_rad`` at ``points_xy_m``, tilt-removed by default.

    ``R = P_target C_xx G^T (G C_xx G^T + C_nn)^-1``; pass the cached
    ``cholesky_lower`` of :func:`slope_covariance` (same noise) to skip it.
    """
    if cholesky_lower is None:
        cholesky_lower = factorize(slope_covariance(prior, geometry, noise_rms_rad, n_edge))
    cross = cross_covariance(prior, geometry, points_xy_m, direction_rad,
                             layer_indices=layer_indices, n_edge=n_edge)
    rec = apply_inverse(cholesky_lower, cross).astype(np.float32)
    return remove_tilt_rows(rec, points_xy_m) if remove_tilt else rec


def layer_reconstructor(prior: TurbulencePrior, geometry: SlopeGeometry, layer_index: int,
                        points_xy_m: np.ndarray, cholesky_lower: np.ndarray,
                        n_edge: int = 2) -> np.ndarray:
    """Virtual-DM estimate (n_points, n_slopes) [m / rad] of layer ``layer_index``
    at layer coordinates ``points_xy_m`` [m]."""
    cross = cross_covariance(prior, geometry, points_xy_m, (0.0, 0.0), source_height_m=0.0,
                             layer_indices=[layer_index], n_edge=n_edge)
    return apply_inverse(cholesky_lower, cross)


def project_layers(layer_values: list, layer_grids: list, heights_m, points_xy_m: np.ndarray,
                   direction_rad=(0.0, 0.0), source_height_m: float = np.inf) -> np.ndarray:
    """Sum of layer maps along a line of sight (bilinear interpolation).

    ``layer_values[l]`` (n, n) [m] on ``layer_grids[l]`` (:class:`PupilGrid`,
    centred on the axis) at ``heights_m[l]``; returns (n_points,) [m] at the
    pupil ``points_xy_m`` for a source in ``direction_rad`` at ``source_height_m``.
    Points outside a layer grid take its edge value.
    """
    from scipy.ndimage import map_coordinates

    total = np.zeros(points_xy_m.shape[0])
    for values, grid, height in zip(layer_values, layer_grids, heights_m):
        scale = 1.0 - height / source_height_m
        xy = points_xy_m * scale + np.asarray(direction_rad) * height
        index = xy / grid.dx_m + (grid.n_pix - 1) / 2  # fractional (x, y) indices
        total += map_coordinates(values, [index[:, 1], index[:, 0]], order=1, mode="nearest")
    return total


# --- selection criterion -----------------------------------------------------------
def lgs_rms_nm(reconstructor: np.ndarray, slopes_rad: np.ndarray) -> np.ndarray:
    """Tilt-removed rms [nm] of the reconstructed optical path along the target.

    ``reconstructor`` from :func:`target_reconstructor` (tilt removed);
    ``slopes_rad`` (..., n_beacons, 2, n_valid), one per WFS exposure.
    """
    flat = np.asarray(slopes_rad, dtype=np.float32)
    flat = flat.reshape(*flat.shape[:-3], -1)
    opd = flat @ reconstructor.T
    return np.sqrt(np.mean(opd**2, axis=-1)) * 1e9


def lucky_frame_rms_nm(exposure_rms_nm: np.ndarray) -> np.ndarray:
    """Combine WFS exposures into one lucky frame: ``sqrt(mean(rms^2))`` over the last axis.

    A 10 ms lucky frame spans 2 WFS exposures of 5 ms (each 2 steps of
    2.5 ms): pass their ``lgs_rms_nm`` as (..., 2).
    """
    return np.sqrt(np.mean(np.square(exposure_rms_nm), axis=-1))
