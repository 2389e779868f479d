"""The slope-noise covariance of the layer-space tomography: diagonal, ``N = diag(sigma_i^2)``, or
each sub-aperture's 2 x 2 block (a geometric WFS's NEA)."""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class SlopeNoise:
    """Slope-noise variance [rad^2]: one value for every slope, or one per slope ``(n_beacons, 2, n_valid)``."""

    variance_rad2: float | np.ndarray

    def __post_init__(self):
        if np.any(np.asarray(self.variance_rad2) <= 0):
            raise ValueError("the slope-noise variance must be positive (it also regularises the tomography)")

    @classmethod
    def uniform(cls, rms_rad: float) -> "SlopeNoise":
        return cls(float(rms_rad) ** 2)

    def weigh(self, slopes: np.ndarray) -> np.ndarray:
        """``N^-1 s``."""
        return slopes / self.variance_rad2

    @property
    def mean_inverse_rad2(self) -> float:
        """Mean of ``1 / sigma_i^2`` (the preconditioner's uniform weight)."""
        return float(np.mean(1.0 / np.asarray(self.variance_rad2)))


@dataclass(frozen=True, eq=False)
class SubapertureNoise:
    """Slope-noise covariance of each sub-aperture's x and y slopes, ``(n_valid, 2, 2)`` [rad^2],
    every beacon's the same (a geometric WFS's NEA: ``studyspec.case.slope_noise_covariance_rad2``):
    ``N`` block diagonal."""

    covariance_rad2: np.ndarray

    def __post_init__(self):
        try:
            np.linalg.cholesky(self.covariance_rad2)
        except np.linalg.LinAlgError:
            raise ValueError("each sub-aperture's slope-noise covariance must be positive definite") from None
        object.__setattr__(self, "_inverse", np.linalg.inv(self.covariance_rad2))

    def weigh(self, slopes: np.ndarray) -> np.ndarray:
        """``N^-1 s`` of slopes ``(n_beacons, 2, n_valid)``, in their dtype."""
        return np.einsum("vab,...bv->...av", self._inverse.astype(slopes.dtype), slopes)

    @property
    def mean_inverse_rad2(self) -> float:
        """Mean of the diagonal of ``N^-1`` (the preconditioner's uniform weight)."""
        return float(np.mean(np.diagonal(self._inverse, axis1=1, axis2=2)))
