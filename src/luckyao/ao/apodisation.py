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
            return np.clip(
                np.floor((np.asarray(c, dtype=float) + self.diameter_m / 2) / pitch_m), 0, self.n_across - 1
            ).astype(np.int64)

        return index(y_m) * self.n_across + index(x_m)

    def mean_square(self, labels: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Mean square (n_regions,) float64 of ``values`` over the points of each region
        (``labels`` from :meth:`labels`); 0 for a region without points."""
        counts = np.bincount(labels, minlength=self.n_regions)
        power = np.bincount(labels, weights=np.square(np.asarray(values, dtype=np.float64)), minlength=self.n_regions)
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
        return ranked[: self.n_blocked]

    def open_samples(self, region_mean_square: np.ndarray) -> np.ndarray:
        """Transmission (n_samples,) float32, 1 open and 0 blocked, for a ranking (n_regions,)."""
        blocked = np.zeros(self.regions.n_regions, dtype=bool)
        blocked[self.blocked_regions(region_mean_square)] = True
        return (~blocked[self.labels]).astype(np.float32)

    def from_residual(self, residual: np.ndarray) -> np.ndarray:
        """Transmission (n_samples,) blocking the regions with the largest mean square of
        ``residual`` (n_samples,), the tilt-removed residual phase at the pupil samples (oracle)."""
        return self.open_samples(self.regions.mean_square(self.labels, residual))


DRIVERS = ("lgs", "oracle")
"""What ranks the regions: the LGS estimate (reconstructed phase along the target less the DM
shape, what an instrument can do) or the true residual (an oracle upper bound)."""


@dataclass(frozen=True)
class ApodisationSettings:
    """``ao.apodisation``: the ``driver`` (:data:`DRIVERS`) and the ``blocked_fraction`` of the regions."""

    driver: str
    blocked_fraction: float

    def __post_init__(self):
        if self.driver not in DRIVERS:
            raise ValueError(f"unknown apodisation driver {self.driver!r}; known: {DRIVERS}")


class DelayedApodisation:
    """Each WFS exposure's transmission of the science pupil samples, applied during the steps
    that exposure's DM command is (``dm``, a :class:`.correction.DelayedDm`); the full pupil
    before the first.

    Both drivers rank the same quantity, the residual along the target during the exposure
    less the DM shape its command makes, with piston, tip and tilt removed: from the LGS
    (:meth:`from_estimate`, at the reconstruction points) or from the truth (:meth:`observe`,
    the mean of the exposure's true phases at the science samples).
    """

    def __init__(self, apodiser: Apodiser, dm, tilt, point_labels=None, point_tilt=None):
        """``tilt``: the :class:`..optics.pupil.TiltRemover` of the science samples; for the LGS
        driver, ``point_labels`` and ``point_tilt`` of the reconstruction points."""
        self.apodiser, self.dm, self.tilt = apodiser, dm, tilt
        self.point_labels, self.point_tilt = point_labels, point_tilt
        self._transmissions = {}  # exposure start step -> transmission (n_samples,) float32
        self._full = np.ones(len(apodiser.labels), dtype=np.float32)
        self._phase_sum = None  # the true phases of the current exposure, summed [rad at 500 nm]

    def _set(self, start_step: int, region_mean_square: np.ndarray) -> None:
        self._transmissions[start_step] = self.apodiser.open_samples(region_mean_square)
        oldest = self.dm.oldest_needed(start_step)
        for key in [k for k in self._transmissions if k < oldest]:
            del self._transmissions[key]

    def from_estimate(self, start_step: int, estimate_m: np.ndarray, dm_at_points_m: np.ndarray) -> None:
        """LGS driver: the exposure's reconstructed optical path along the target and the DM
        shape of its command at the reconstruction points (n_points,) [m]."""
        residual = self.point_tilt.residual(np.asarray(estimate_m - dm_at_points_m, dtype=np.float32))
        self._set(start_step, self.apodiser.regions.mean_square(self.point_labels, residual))

    def observe(self, step: int, phase_500: np.ndarray) -> None:
        """Oracle driver: the target's true phase (n_samples,) [rad at 500 nm] at ``step``, steps
        in order; at an exposure's last step its transmission is set."""
        e = self.dm.exposure_steps
        self._phase_sum = phase_500.astype(np.float64) if step % e == 0 else self._phase_sum + phase_500
        if step % e == e - 1:
            start = step - e + 1
            residual = self.tilt.residual((self._phase_sum / e - self.dm.surface_of(start)).astype(np.float32))
            self._set(start, self.apodiser.regions.mean_square(self.apodiser.labels, residual))

    def at(self, step: int) -> np.ndarray:
        """Transmission (n_samples,) float32 of the science pupil at ``step``."""
        source = self.dm.source_step(step)
        return self._transmissions[source] if source >= 0 else self._full
