"""Pupil-conjugate continuous-facesheet deformable mirror: actuators, influence
functions and the least-squares fit of an optical path onto the mirror.

Geometry: ``n_actuators`` x ``n_actuators`` actuators on a square lattice of
pitch ``d = D / (n_actuators - 1)`` spanning the pupil diameter ``D``, centred
on the axis (Fried geometry: with ``n_actuators - 1`` WFS sub-apertures across
``D`` the actuators sit on the sub-aperture corners).

Influence function (continuous facesheet, Gaussian): pushing one actuator by a
command ``c`` [m of optical path] changes the optical path by
``c h(r)``, ``h(r) = exp(ln(coupling) (r / d)^2)``, so ``h = coupling`` at the
neighbouring actuators (the Gaussian mechanical-coupling model of e.g. OOPAO,
Heritier et al.: ``DeformableMirror(mechCoupling=...)``, cheritier/OOPAO on
GitHub). The mirror is treated as transmissive: the command is the optical path
the DM adds, no factor 2 for reflection.

Fitting error of such a mirror on Kolmogorov turbulence,
``sigma^2 = kappa (d / r0)^(5/3)`` [rad^2], with ``kappa`` ~ 0.23-0.30 for
continuous facesheets (Hudgin 1977, JOSA 67, 393; Rigaut, Veran & Lai 1998,
Proc. SPIE 3353, 1038). For this influence function the infinite-lattice
least-squares value is 0.237; on the study's annular pupil the actuators at
the edge lower it to 0.16, 0.19, 0.21 for 5x5, 9x9, 17x17 (checked in
``tests/test_dm.py``).

Arrays: commands ``(n_valid,)`` in the order of :attr:`DeformableMirror.actuator_xy_m`
(row-major over the lattice ``[y, x]``); points ``(n_points, 2)`` as ``(x, y)`` [m].
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg

from ..optics.pupil import PupilGrid, Telescope

INFLUENCES = ("gaussian",)


@dataclass(frozen=True)
class DeformableMirror:
    """Continuous-facesheet DM conjugate to the pupil of ``telescope``.

    ``coupling`` is the influence function's value at the neighbouring actuator
    (0 < coupling < 1); ``influence`` names its shape (only ``"gaussian"``).

    Valid actuators: an actuator is kept when the open ``2d x 2d`` square
    centred on it overlaps the annular pupil, i.e. when it is a corner of at
    least one ``d x d`` lattice cell that contains pupil (in Fried geometry,
    the actuators that the slopes of an illuminated sub-aperture depend on).
    A kept actuator has pupil within ``sqrt(2) d`` (``h >= coupling^2``
    there); an excluded one reaches the pupil only beyond one pitch in ``x``
    or ``y``, would be weakly constrained by any fit, and is dropped. The
    test is analytic (nearest and farthest points of the square from the
    axis), so it does not depend on a pupil sampling.
    """

    telescope: Telescope
    n_actuators: int
    coupling: float = 0.3
    influence: str = "gaussian"

    def __post_init__(self):
        if self.influence not in INFLUENCES:
            raise ValueError(f"unknown influence function {self.influence!r}; known: {INFLUENCES}")
        if not 0.0 < self.coupling < 1.0:
            raise ValueError("coupling must be in (0, 1)")
        if self.n_actuators < 2:
            raise ValueError("n_actuators must be >= 2")

    @property
    def pitch_m(self) -> float:
        """Actuator pitch ``d = D / (n_actuators - 1)`` [m]."""
        return self.telescope.diameter_m / (self.n_actuators - 1)

    @cached_property
    def valid(self) -> np.ndarray:
        """Valid actuators, bool (n_actuators, n_actuators) indexed ``[y, x]``."""
        d = self.pitch_m
        coords = (np.arange(self.n_actuators) - (self.n_actuators - 1) / 2) * d
        y, x = np.meshgrid(np.abs(coords), np.abs(coords), indexing="ij")
        nearest = np.hypot(np.maximum(x - d, 0.0), np.maximum(y - d, 0.0))
        farthest = np.hypot(x + d, y + d)
        return (nearest < self.telescope.diameter_m / 2) & (farthest > self.telescope.obscuration_m / 2)

    @cached_property
    def actuator_xy_m(self) -> np.ndarray:
        """Positions ``(x, y)`` (n_valid, 2) [m] of the valid actuators, row-major."""
        index = np.argwhere(self.valid)  # (iy, ix)
        return ((index - (self.n_actuators - 1) / 2) * self.pitch_m)[:, ::-1].copy()

    @property
    def n_valid(self) -> int:
        return self.actuator_xy_m.shape[0]

    def influence_matrix(self, x_m, y_m) -> np.ndarray:
        """``H`` (n_points, n_valid) float64: optical path [m] at the points
        ``(x_m, y_m)`` (any shape, flattened) per unit command [m]."""
        iy, ix = np.nonzero(self.valid)  # the order of actuator_xy_m
        fx = self._factor(np.ravel(x_m))
        fy = self._factor(np.ravel(y_m))
        return fx[:, ix] * fy[:, iy]

    def _factor(self, coords_m: np.ndarray) -> np.ndarray:
        """``exp(ln(coupling) ((u - a) / d)^2)`` (n_coords, n_actuators) for lattice
        coordinates ``a``: one axis of the Gaussian influence function."""
        lattice = (np.arange(self.n_actuators) - (self.n_actuators - 1) / 2) * self.pitch_m
        u = np.asarray(coords_m, dtype=float)[:, None] - lattice[None, :]
        return np.exp(np.log(self.coupling) / self.pitch_m**2 * u**2)

    def grid_surface(self, grid: PupilGrid, mask: np.ndarray) -> "GridSurface":
        """The surface on a pupil grid's ``mask`` samples, computed separably."""
        return GridSurface(self._factor(grid.coords_m), self.valid, np.flatnonzero(mask))

    def fit_matrix(self, points_xy_m: np.ndarray) -> np.ndarray:
        """``F`` (n_valid, n_points) float64: optical path [m] at the points ->
        commands [m], least squares, with no piston, tip or tilt on the mirror.

        With ``H`` the influence matrix at the points and ``B = [1, x, y]``, the
        commands are restricted to the null space ``N`` of ``B^T H`` (the
        commands whose surface has zero least-squares piston/tip/tilt over the
        points), and ``F = N (H N)^+``: ``H F phi`` is the orthogonal projection
        of ``phi`` on the piston/tip/tilt-free surfaces the DM can make, so it
        ignores any piston/tip/tilt of ``phi`` and reproduces exactly any such
        surface. No regularisation is needed: with the valid-actuator rule
        above ``H`` is well conditioned (condition number 55, 93, 179 for
        5x5, 9x9, 17x17 on the study pupil sampled at D/256).
        """
        points = np.asarray(points_xy_m, dtype=float)
        h = self.influence_matrix(points[:, 0], points[:, 1])
        basis = np.stack([np.ones(len(points)), points[:, 0], points[:, 1]], axis=1)
        free = scipy.linalg.null_space(basis.T @ h)  # (n_valid, n_valid - 3)
        return free @ np.linalg.pinv(h @ free)


@dataclass(frozen=True, eq=False)
class GridSurface:
    """The DM surface at the samples of a square pupil grid, ``H c`` computed separably.

    A Gaussian influence function is a product of x and y factors, so on the grid
    ``S = E_y C E_x^T`` with ``C`` the commands on the actuator lattice and
    ``E`` (n_grid, n_actuators) the one-axis factors: ``n (n + m) m`` operations
    instead of ``n^2 m^2`` (m actuators across), and no large matrix to stream.
    ``samples`` are the flat indices of the grid samples returned, in order.
    """

    factor: np.ndarray
    valid: np.ndarray
    samples: np.ndarray

    def __call__(self, commands: np.ndarray) -> np.ndarray:
        """Surface (n_samples,) float64 [m] of ``commands`` (n_valid,) [m]."""
        lattice = np.zeros(self.valid.shape)
        lattice[self.valid] = commands
        return (self.factor @ lattice @ self.factor.T).ravel()[self.samples]
