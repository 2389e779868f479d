"""From the reconstructed layers to what the loop needs: the optical path along any line of sight
(the ``lgs_rms`` criterion, the field) and the DM commands.

* Line of sight: the layers interpolated bilinearly where the rays from pupil points towards a
  source cross them (:func:`luckyao.geometry.cone_coordinates`), summed: a sparse matrix
  (:func:`line_of_sight_matrix`).
* DM: the optical path along the correction direction at the fit points
  (:func:`luckyao.ao.control.fit_points`) fitted onto the DM by least squares with no piston, tip or
  tilt on the mirror -- the fit ``F`` of :meth:`luckyao.ao.dm.DeformableMirror.fit_matrix`, here as the
  sparse saddle-point system ``[[H^T H, H^T B], [B^T H, 0]] [c; l] = [H^T phi; 0]`` (``H`` the influence
  functions at the points, truncated below :data:`INFLUENCE_CUTOFF`; ``B = [1, x, y]``), factorised once.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ..ao.control import fit_points, ground_layers
from ..ao.dm import DeformableMirror
from ..geometry import cone_coordinates
from ..optics.pupil import TiltRemover
from .grids import LayerGrids
from .operators import bilinear_matrix

INFLUENCE_CUTOFF = 1e-6
"""Influence-function values below this (of the actuator's own) are dropped from the sparse fit."""

POINTS_PER_CHUNK = 2048
"""Fit points whose influence functions are evaluated (densely) at once, before truncation."""


def line_of_sight_matrix(
    grids: LayerGrids, points_xy_m: np.ndarray, direction_rad=(0.0, 0.0), source_height_m=np.inf, layers=None
) -> scipy.sparse.csr_matrix:
    """``(n_points, n_layers n n)``: layers -> optical path [m] at pupil points ``(n_points, 2)`` [m]
    along ``direction_rad`` to a source at ``source_height_m``, summed over ``layers`` (default all)."""
    points = np.asarray(points_xy_m, dtype=float)
    chosen = set(range(grids.n_layers) if layers is None else layers)
    blocks = []
    for layer, height in enumerate(grids.heights_m):
        if layer in chosen:
            x, y = cone_coordinates(points[:, 0], points[:, 1], height, source_height_m, direction_rad)
            blocks.append(bilinear_matrix(*grids.sample_index(layer, x, y), grids.n))
        else:
            blocks.append(scipy.sparse.csr_matrix((len(points), grids.n * grids.n)))
    return scipy.sparse.hstack(blocks, format="csr")


def sparse_influence(dm: DeformableMirror, points_xy_m: np.ndarray) -> scipy.sparse.csr_matrix:
    """The DM's influence matrix ``(n_points, n_valid)`` at the points, values below
    :data:`INFLUENCE_CUTOFF` dropped."""
    chunks = []
    for start in range(0, len(points_xy_m), POINTS_PER_CHUNK):
        chunk = points_xy_m[start : start + POINTS_PER_CHUNK]
        dense = dm.influence_matrix(chunk[:, 0], chunk[:, 1])
        dense[dense < INFLUENCE_CUTOFF] = 0.0
        chunks.append(scipy.sparse.csr_matrix(dense))
    return scipy.sparse.vstack(chunks, format="csr")


@dataclass(frozen=True, eq=False)
class LineOfSight:
    """Layers -> tilt-removed optical path [m] at ``points`` along one line of sight."""

    trace: scipy.sparse.csr_matrix
    tilt: TiltRemover

    @classmethod
    def build(cls, grids: LayerGrids, points_xy_m: np.ndarray, direction_rad=(0.0, 0.0), layers=None):
        points = np.asarray(points_xy_m, dtype=float)
        return cls(line_of_sight_matrix(grids, points, direction_rad, layers=layers), TiltRemover(*points.T))

    def path_m(self, layers: np.ndarray, less_m: np.ndarray | None = None) -> np.ndarray:
        """The tilt-removed path [m] at the points, less ``less_m`` (n_points,) [m] (e.g. the DM's shape)."""
        path = self.trace @ layers.reshape(-1)
        return self.tilt.residual(path if less_m is None else path - less_m)

    def rms_nm(self, layers: np.ndarray, less_m: np.ndarray | None = None) -> float:
        """Tilt-removed rms [nm] along the line of sight (the ``lgs_rms`` of one exposure), less ``less_m``."""
        return float(np.sqrt(np.mean(self.path_m(layers, less_m) ** 2)) * 1e9)


@dataclass(frozen=True, eq=False)
class DmProjection:
    """Layers -> DM commands [m]: the estimate along the correction direction fitted onto the DM."""

    trace: scipy.sparse.csr_matrix
    influence_t: scipy.sparse.csr_matrix
    factor: scipy.sparse.linalg.SuperLU
    n_actuators: int

    @classmethod
    def build(
        cls,
        grids: LayerGrids,
        dm: DeformableMirror,
        mode: str,
        direction_rad=(0.0, 0.0),
        ground_max_height_m: float | None = None,
        fit_pitch_m: float | None = None,
        heights_m=None,
    ) -> "DmProjection":
        """LTAO: every layer along ``direction_rad``; GLAO: the ground layers
        (:func:`luckyao.ao.control.ground_layers` of the grids' heights) on axis."""
        points = fit_points(dm, fit_pitch_m)
        if mode == "ltao":
            trace = line_of_sight_matrix(grids, points, direction_rad)
        elif mode == "glao":
            layers = ground_layers(_Heights(grids.heights_m), ground_max_height_m)
            trace = line_of_sight_matrix(grids, points, layers=layers)
        else:
            raise ValueError(f"unknown correction mode {mode!r}; known: ('ltao', 'glao')")
        h = sparse_influence(dm, points)
        basis = scipy.sparse.csr_matrix(np.stack([np.ones(len(points)), points[:, 0], points[:, 1]], axis=1))
        constraint = (basis.T @ h).tocsr()  # (3, n_act)
        system = scipy.sparse.bmat([[h.T @ h, constraint.T], [constraint, None]], format="csc")
        return cls(trace, h.T.tocsr(), scipy.sparse.linalg.splu(system), dm.n_valid)

    def commands(self, layers: np.ndarray) -> np.ndarray:
        """DM commands ``(n_act,)`` [m] of layers ``(n_layers, n, n)`` [m]."""
        path = self.trace @ layers.reshape(-1)
        rhs = np.concatenate([self.influence_t @ path, np.zeros(3)])
        return self.factor.solve(rhs)[: self.n_actuators]


@dataclass(frozen=True)
class _Heights:
    """What :func:`luckyao.ao.control.ground_layers` reads of a prior: the layer heights."""

    heights_m: tuple[float, ...]
