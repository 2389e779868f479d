"""The measurement operator ``H``: layer grids -> every beacon's tilt-removed sub-aperture slopes.

For beacon ``b`` the pupil phase on the samples ``(o n_sub + 1)^2`` of pitch ``Delta = d/o``
(``o = 2``, the default: the sub-aperture corners, edge mid-points and centres; ``o = 1``: the
corners, Fried geometry) is the sum over layers of the layers interpolated bilinearly where the
beacon's rays cross them (:mod:`.grids`: a constant stencil per layer, :class:`BeaconRayTracing`).
Each sub-aperture's slope is the mean gradient of that bilinear surface over the sub-aperture,
exactly the difference of its edge means over ``d``, each edge mean the trapezoid of its ``o + 1``
samples (:class:`SubapertureGradient`; the dense slope-space model of
:mod:`luckyao.tomography.slopes` takes the same difference of edge means, at ``n_edge``
mid-points). Each beacon's mean x and y slope is removed (LGS do not measure tip-tilt):
``s = P G R x``. Units: layers in metres of optical path, slopes in radians.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse

from . import kernels
from .grids import LayerGrids

EDGE_WEIGHTS = {1: (0.5, 0.5), 2: (0.25, 0.5, 0.25)}
"""Trapezoid weights of an edge's ``o + 1`` samples at ``o`` pupil samples per sub-aperture: exact for a
bilinear surface (``o = 1``: the corners, Fried geometry; ``o = 2``: corners and mid-point)."""


def bilinear_matrix(column, row, n: int) -> scipy.sparse.csr_matrix:
    """``(n_points, n * n)`` bilinear interpolation of an ``n x n`` grid (row-major ``[y, x]``) at
    fractional ``(column, row)`` indices; every point must lie inside the grid."""
    column, row = np.ravel(column).astype(float), np.ravel(row).astype(float)
    if column.size and (min(column.min(), row.min()) < 0 or max(column.max(), row.max()) > n - 1):
        raise ValueError("a ray leaves the layer grid: build the grids covering every line of sight")
    c0 = np.minimum(np.floor(column).astype(np.int64), n - 2)
    r0 = np.minimum(np.floor(row).astype(np.int64), n - 2)
    fc, fr = column - c0, row - r0
    points = np.arange(column.size)
    rows, cols, values = [], [], []
    for dr, wr in ((0, 1 - fr), (1, fr)):
        for dc, wc in ((0, 1 - fc), (1, fc)):
            rows.append(points)
            cols.append((r0 + dr) * n + c0 + dc)
            values.append(wr * wc)
    matrix = scipy.sparse.coo_matrix(
        (np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=(column.size, n * n)
    )
    return matrix.tocsr()


@dataclass(frozen=True, eq=False)
class BeaconRayTracing:
    """Layers ``(n_layers, n, n)`` -> one beacon's pupil phase ``(m, m)``, ``m = o n_sub + 1``:
    on each layer a bilinear stencil of constant weights at offset ``offsets[l]`` (column, row)
    [layer samples] from the pupil sample's index."""

    grids: LayerGrids
    m: int
    offsets: np.ndarray  # (n_layers, 2) fractional (column, row) of pupil sample (0, 0)

    @classmethod
    def for_beacon(cls, grids: LayerGrids, m: int, direction_rad) -> "BeaconRayTracing":
        """Pupil sample ``a`` (per axis) of ``m`` sits at ``(a - (m - 1)/2) Delta``; its ray to the
        beacon crosses layer ``l`` at layer sample ``a - (m - 1)/2 + c + theta h_l / Delta_l``."""
        shift = np.outer(grids.heights_m, np.asarray(direction_rad, dtype=float)) / grids.pitches_m[:, None]
        offsets = shift + grids.centre - (m - 1) / 2
        if offsets.min() < 0 or offsets.max() + m > grids.n - 1:
            raise ValueError("a beacon's footprint leaves the layer grid: build the grids for its direction")
        return cls(grids, m, offsets)

    @cached_property
    def _stencils(self) -> tuple[np.ndarray, np.ndarray]:
        """Per layer: the integer offset (column, row) (n_layers, 2) and the weights of the taps
        (d_row, d_column) = (0, 0), (0, 1), (1, 0), (1, 1) (n_layers, 4)."""
        integer = np.floor(self.offsets)
        fc, fr = (self.offsets - integer).T
        weights = np.stack([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc], axis=1)
        return integer.astype(np.int64), weights

    def forward(self, layers: np.ndarray) -> np.ndarray:
        """Pupil phase ``(m, m)`` [m] of layers ``(n_layers, n, n)`` [m] (:func:`.kernels.trace`)."""
        corners, weights = self._stencils
        phase = np.empty((self.m, self.m), dtype=layers.dtype)
        kernels.trace(np.ascontiguousarray(layers), corners, weights.astype(layers.dtype), phase)
        return phase

    def adjoint_add(self, phase: np.ndarray, layers: np.ndarray) -> None:
        """``layers += R^T phase`` for a pupil phase ``(m, m)`` (layers C-contiguous)."""
        corners, weights = self._stencils
        phase = np.ascontiguousarray(phase, layers.dtype)
        kernels.trace_adjoint_add(phase, corners, weights.astype(layers.dtype), layers)

    def matrix(self) -> scipy.sparse.csr_matrix:
        """``R`` as a sparse matrix ``(m * m, n_layers * n * n)`` (:func:`bilinear_matrix` per layer)."""
        a = np.arange(self.m, dtype=float)
        rows, columns = np.meshgrid(a, a, indexing="ij")
        blocks = [bilinear_matrix(columns + c, rows + r, self.grids.n) for c, r in self.offsets]
        return scipy.sparse.hstack(blocks, format="csr")


@dataclass(frozen=True, eq=False)
class SubapertureGradient:
    """Pupil phase ``(o n + 1, o n + 1)`` [m] -> mean x and y gradients ``(2, n_valid)`` [rad] of
    the valid sub-apertures (``valid`` (n, n) ``[y, x]``, the WFS's; row-major order, as its
    slopes), side ``subaperture_m``, ``oversampling`` (``o``) pupil samples per side."""

    valid: np.ndarray
    subaperture_m: float
    oversampling: int = 1

    def __post_init__(self):
        if self.oversampling not in EDGE_WEIGHTS:
            raise ValueError(f"pupil samples per sub-aperture must be one of {sorted(EDGE_WEIGHTS)}")

    @property
    def n_valid(self) -> int:
        return int(self.valid.sum())

    @property
    def m(self) -> int:
        """Pupil samples across, ``o n + 1``."""
        return self.oversampling * self.valid.shape[0] + 1

    @cached_property
    def _corners(self) -> tuple[np.ndarray, np.ndarray]:
        """First pupil sample (row, column) of each valid sub-aperture, row-major (n_valid,) each."""
        rows, columns = np.nonzero(self.valid)
        return self.oversampling * rows, self.oversampling * columns

    def forward(self, phase: np.ndarray) -> np.ndarray:
        """Slopes ``(2, n_valid)`` [rad] of a pupil phase ``(m, m)`` [m] (:func:`.kernels.edge_differences`)."""
        slopes = np.empty((2, self.n_valid), dtype=phase.dtype)
        weights = np.asarray(EDGE_WEIGHTS[self.oversampling], dtype=phase.dtype)
        side = phase.dtype.type(self.subaperture_m)
        kernels.edge_differences(np.ascontiguousarray(phase), *self._corners, weights, side, slopes)
        return slopes

    def adjoint(self, slopes: np.ndarray) -> np.ndarray:
        """``G^T`` of slopes ``(2, n_valid)``: a pupil phase ``(m, m)`` (:func:`.kernels.edge_differences_adjoint`)."""
        phase = np.empty((self.m, self.m), dtype=slopes.dtype)
        weights = np.asarray(EDGE_WEIGHTS[self.oversampling], dtype=slopes.dtype)
        side = slopes.dtype.type(self.subaperture_m)
        kernels.edge_differences_adjoint(np.ascontiguousarray(slopes), *self._corners, weights, side, phase)
        return phase


def remove_beacon_tilt(slopes: np.ndarray) -> np.ndarray:
    """``P s``: each beacon's mean x and y slope removed from ``(..., 2, n_valid)`` (self-adjoint)."""
    return slopes - slopes.mean(axis=-1, keepdims=True)


@dataclass(frozen=True, eq=False)
class MeasurementOperator:
    """``H = P G R``: layers ``(n_layers, n, n)`` [m] -> tilt-removed slopes
    ``(n_beacons, 2, n_valid)`` [rad] of every beacon (:class:`BeaconRayTracing` per beacon)."""

    grids: LayerGrids
    gradient: SubapertureGradient
    beacons: tuple[BeaconRayTracing, ...]

    @classmethod
    def build(cls, grids: LayerGrids, valid: np.ndarray, subaperture_m: float, directions_rad) -> "MeasurementOperator":
        """For a WFS of ``valid`` sub-apertures (n, n) of side ``subaperture_m`` [m] per beacon
        ``directions_rad`` (n_beacons, 2); ``grids.pupil_pitch_m`` is ``subaperture_m / o``."""
        oversampling = int(round(subaperture_m / grids.pupil_pitch_m))
        if not np.isclose(grids.pupil_pitch_m * oversampling, subaperture_m):
            raise ValueError(f"the layer grids' pupil pitch {grids.pupil_pitch_m} m does not divide the sub-aperture")
        gradient = SubapertureGradient(np.asarray(valid, dtype=bool), subaperture_m, oversampling)
        beacons = tuple(BeaconRayTracing.for_beacon(grids, gradient.m, d) for d in np.atleast_2d(directions_rad))
        return cls(grids, gradient, beacons)

    @property
    def n_slopes(self) -> int:
        return 2 * len(self.beacons) * self.gradient.n_valid

    def forward(self, layers: np.ndarray) -> np.ndarray:
        return remove_beacon_tilt(np.stack([self.gradient.forward(b.forward(layers)) for b in self.beacons]))

    def adjoint(self, slopes: np.ndarray) -> np.ndarray:
        """``H^T s`` for slopes ``(n_beacons, 2, n_valid)``: layers ``(n_layers, n, n)``."""
        slopes = remove_beacon_tilt(slopes)
        layers = np.zeros(self.grids.shape, dtype=slopes.dtype)
        for beacon, s in zip(self.beacons, slopes):
            beacon.adjoint_add(self.gradient.adjoint(s), layers)
        return layers

    def matrix(self) -> scipy.sparse.csr_matrix:
        """``H`` as a sparse matrix ``(n_slopes, n_layers n n)`` (small systems: tests, direct solves)."""
        m = self.gradient.m
        gradient = np.stack([self.gradient.forward(e.reshape(m, m)) for e in np.eye(m * m)], axis=-1)
        gradient = gradient - gradient.mean(axis=1, keepdims=True)  # P G (2, n_valid, m m)
        g = scipy.sparse.csr_matrix(gradient.reshape(-1, m * m))
        return scipy.sparse.vstack([g @ b.matrix() for b in self.beacons], format="csr")
