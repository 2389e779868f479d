"""Telescope pupil: sampling grid, annular aperture and tip-tilt removal.

Conventions used throughout luckyao: arrays are indexed ``[y, x]``; grid
coordinates are centred, ``x_m[i] = (i - (n - 1) / 2) * dx_m``; so a grid of
even size has no sample on the optical axis.
"""

from dataclasses import dataclass
from functools import cached_property

import numba
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
    def _basis(self) -> np.ndarray:
        """B = [1, x, y], float64 (n_valid, 3)."""
        return np.stack([np.ones_like(self.x_m), self.x_m, self.y_m], axis=1).astype(np.float64)

    @cached_property
    def _projector(self) -> tuple[np.ndarray, np.ndarray]:
        return self._basis.astype(np.float32), np.linalg.pinv(self._basis).astype(np.float32)

    def coefficients(self, phase: np.ndarray) -> np.ndarray:
        """Piston [phase unit], tip and tilt [phase unit per m], shape (..., 3)."""
        return phase @ self._projector[1].T

    def residual(self, phase: np.ndarray) -> np.ndarray:
        """Phase with its best-fit piston, tip and tilt removed, same shape."""
        basis, _ = self._projector
        return phase - self.coefficients(phase) @ basis.T

    @cached_property
    def _normal_inverse(self) -> np.ndarray:
        return np.linalg.inv(self._basis.T @ self._basis)

    def rms(self, phase: np.ndarray) -> np.ndarray:
        """Tilt-removed rms over the pupil samples, shape (...).

        The residual is orthogonal to the basis, so ``|phi - B c|^2 = |phi|^2 -
        b^T (B^T B)^-1 b`` with ``b = B^T phi``: one compiled pass over the
        samples, accumulated in float64.
        """
        phase = np.asarray(phase, dtype=np.float32)
        flat = np.ascontiguousarray(phase.reshape(-1, phase.shape[-1]))
        out = np.empty(flat.shape[0])
        _tilt_removed_rms(
            flat, np.asarray(self.x_m, np.float64), np.asarray(self.y_m, np.float64), self._normal_inverse, out
        )
        return out.reshape(phase.shape[:-1])

    @classmethod
    def for_mask(cls, grid: PupilGrid, mask: np.ndarray) -> "TiltRemover":
        x, y = grid.xy_m
        return cls(x_m=x[mask], y_m=y[mask])


@numba.njit(cache=True, nogil=True)
def _tilt_removed_rms(phase, x_m, y_m, normal_inverse, out):  # pragma: no cover (jit)
    """out[k] = sqrt((|phi_k|^2 - b^T (B^T B)^-1 b) / n), b = (sum phi, sum x phi, sum y phi)."""
    n = phase.shape[1]
    b = np.empty(3)
    for k in range(phase.shape[0]):
        s0 = sx = sy = power = 0.0
        for i in range(n):
            v = np.float64(phase[k, i])
            s0 += v
            sx += x_m[i] * v
            sy += y_m[i] * v
            power += v * v
        b[0], b[1], b[2] = s0, sx, sy
        fitted = 0.0
        for i in range(3):
            for j in range(3):
                fitted += b[i] * normal_inverse[i, j] * b[j]
        out[k] = np.sqrt(max(power - fitted, 0.0) / n)
