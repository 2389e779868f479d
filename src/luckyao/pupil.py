"""Telescope pupil: sampling grid, annular aperture and tip-tilt removal.

Conventions used throughout luckyao: arrays are indexed ``[y, x]``; grid
coordinates are centred, ``x_m[i] = (i - (n - 1) / 2) * dx_m``; so a grid of
even size has no sample on the optical axis.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class PupilGrid:
    """Square grid of ``n_pix`` x ``n_pix`` samples spaced ``dx_m`` metres."""

    n_pix: int
    dx_m: float

    @property
    def coords_m(self) -> np.ndarray:
        """Sample positions along one axis [m], shape (n_pix,)."""
        return (np.arange(self.n_pix) - (self.n_pix - 1) / 2) * self.dx_m

    @property
    def xy_m(self) -> tuple[np.ndarray, np.ndarray]:
        """Sample positions ``(x, y)`` [m], each of shape (n_pix, n_pix)."""
        y, x = np.meshgrid(self.coords_m, self.coords_m, indexing="ij")
        return x, y


@dataclass(frozen=True)
class Telescope:
    """Annular telescope aperture: ``diameter_m`` with a central obscuration."""

    diameter_m: float
    obscuration_m: float

    def grid_for(self, dx_m: float) -> PupilGrid:
        """The smallest even grid of spacing ``dx_m`` that holds the pupil."""
        n = int(np.ceil(self.diameter_m / dx_m - 1e-9))
        return PupilGrid(n_pix=n + n % 2, dx_m=dx_m)

    def mask(self, grid: PupilGrid) -> np.ndarray:
        """Boolean transmission (sample centres inside the annulus), shape (n, n)."""
        x, y = grid.xy_m
        r = np.hypot(x, y)
        return (r <= self.diameter_m / 2) & (r >= self.obscuration_m / 2)


@dataclass(frozen=True, eq=False)
class TiltRemover:
    """Least-squares removal of piston, tip and tilt over the pupil samples.

    For a phase ``phi`` on the ``n_valid`` pupil samples (any leading axes),
    ``residual(phi) = phi - B (B^T B)^-1 B^T phi`` with ``B = [1, x, y]``.
    """

    x_m: np.ndarray
    y_m: np.ndarray

    @cached_property
    def _projector(self) -> tuple[np.ndarray, np.ndarray]:
        basis = np.stack([np.ones_like(self.x_m), self.x_m, self.y_m], axis=1)
        pseudo_inverse = np.linalg.pinv(basis)
        return basis.astype(np.float32), pseudo_inverse.astype(np.float32)

    def coefficients(self, phase: np.ndarray) -> np.ndarray:
        """Piston [phase unit], tip and tilt [phase unit per m], shape (..., 3)."""
        return phase @ self._projector[1].T

    def residual(self, phase: np.ndarray) -> np.ndarray:
        """Phase with its best-fit piston, tip and tilt removed, same shape."""
        basis, _ = self._projector
        return phase - self.coefficients(phase) @ basis.T

    def rms(self, phase: np.ndarray) -> np.ndarray:
        """Tilt-removed rms over the pupil samples, shape (...)."""
        return np.sqrt(np.mean(self.residual(phase) ** 2, axis=-1))

    @classmethod
    def for_mask(cls, grid: PupilGrid, mask: np.ndarray) -> "TiltRemover":
        x, y = grid.xy_m
        return cls(x_m=x[mask], y_m=y[mask])
