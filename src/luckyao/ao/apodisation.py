"""Adaptive apodisation: per WFS exposure, block the pupil regions whose residual phase along
the target is largest (the paper's conclusion: detect the regions with a large residual and
block them for that frame).

Regions are the squares of the WFS sub-aperture grid (side ``p = D / n_across``), clipped to
the pupil: the LGS estimate resolves the wavefront only at that pitch (slopes are sub-aperture
means, the DM has the same pitch), so finer regions would rank structure the instrument cannot
see; the oracle uses the same regions, so the two variants differ only by their knowledge of
the residual.

Ranking: each region's mean square of the residual phase with piston, tip and tilt removed over
the whole pupil (the lucky frames are recentred; LGS do not measure tilt), its per-sample share
of the pupil's residual variance; the ``round(f n_regions)`` regions with the largest are
blocked (``f`` the configured fraction, ``n_regions`` those holding pupil samples). Every kept
sample's region has a mean square no larger than any blocked region's, so the kept samples'
mean square is at most the whole pupil's, and the tilt-removed variance of the kept pupil
(least squares, at most that of any plane removed) is at most the whole pupil's tilt-removed
variance.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SubapertureRegions:
    """The ``n_across`` x ``n_across`` squares of side ``diameter_m / n_across`` over the pupil
    (centred on the optical axis), numbered ``iy * n_across + ix``."""

    diameter_m: float
    n_across: int

    @property
    def n_regions(self) -> int:
        return self.n_across * self.n_across

    def labels(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Region number (int64, shape of ``x_m``) of each point [m]; points on the rim go to
        the outermost squares."""
        pitch_m = self.diameter_m / self.n_across

        def index(c):
            return np.clip(np.floor((np.asarray(c, dtype=float) + self.diameter_m / 2) / pitch_m),
                           0, self.n_across - 1).astype(np.int64)

        return index(y_m) * self.n_across + index(x_m)

    def mean_square(self, labels: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Mean square (n_regions,) float64 of ``values`` over the points of each region
        (``labels`` from :meth:`labels`); 0 for a region without points."""
        counts = np.bincount(labels, minlength=self.n_regions)
        power = np.bincount(labels, weights=np.square(np.asarray(values, dtype=np.float64)),
                            minlength=self.n_regions)
        return np.divide(power, counts, out=np.zeros(self.n_regions), where=counts > 0)


class Apodiser:
    """The open pupil samples for a ranking of the regions: ``x_m``, ``y_m`` (n_samples,) the
    pupil samples [m]; ``blocked_fraction`` in [0, 1) the fraction of the regions holding
    samples that are blocked."""

    def __init__(self, regions: SubapertureRegions, x_m: np.ndarray, y_m: np.ndarray, blocked_fraction: float):
        if not 0.0 <= blocked_fraction < 1.0:
            raise ValueError(f"blocked_fraction must be in [0, 1), got {blocked_fraction}")
        self.regions = regions
        self.labels = regions.labels(x_m, y_m)
        self.present = np.flatnonzero(np.bincount(self.labels, minlength=regions.n_regions))
        self.n_blocked = int(round(blocked_fraction * len(self.present)))

    def blocked_regions(self, region_mean_square: np.ndarray) -> np.ndarray:
        """The ``n_blocked`` regions (of those holding samples) with the largest mean square
        (n_regions,); ties go to the lower region number."""
        ranked = self.present[np.argsort(-region_mean_square[self.present], kind="stable")]
        return ranked[:self.n_blocked]

    def open_samples(self, region_mean_square: np.ndarray) -> np.ndarray:
        """Transmission (n_samples,) float32, 1 open and 0 blocked, for a ranking (n_regions,)."""
        blocked = np.zeros(self.regions.n_regions, dtype=bool)
        blocked[self.blocked_regions(region_mean_square)] = True
        return (~blocked[self.labels]).astype(np.float32)

    def from_residual(self, residual: np.ndarray) -> np.ndarray:
        """Transmission (n_samples,) blocking the regions with the largest mean square of
        ``residual`` (n_samples,), the tilt-removed residual phase at the pupil samples (oracle)."""
        return self.open_samples(self.regions.mean_square(self.labels, residual))
