"""The slope-noise covariance of the layer-space tomography: diagonal, ``N = diag(sigma_i^2)``."""

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
