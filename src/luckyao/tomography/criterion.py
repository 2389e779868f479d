"""The LGS selection criterion: tilt-removed rms of the reconstructed wavefront along the target.

Per WFS exposure, each target's reconstructor (:mod:`.reconstructor`) maps the
slopes to the tilt-removed optical path along it; a 10 ms lucky frame spans
``steps_per_frame / exposure_steps`` exposures (2 of 5 ms by default) and its
``lgs_rms`` is ``sqrt(mean(rms^2))`` over them.
"""

import numpy as np


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


class LgsRmsEstimator:
    """Each target's tilt-removed reconstructed rms from one case's slopes."""

    def __init__(self, reconstructors: np.ndarray, n_slopes: int):
        self.reconstructors = np.asarray(reconstructors, dtype=np.float32)
        if self.reconstructors.shape[-1] != n_slopes:
            raise ValueError("the reconstructor does not match this WFS: rebuild it")
        # (target, slope, point), C-contiguous: OpenBLAS packs it for the product faster than the
        # (point, slope) array's transpose (a quarter of the time at 8.2 m), into the same panels
        # for the same kernel: the same sums
        self._transposed = np.ascontiguousarray(self.reconstructors.transpose(0, 2, 1))

    def estimate(self, slopes: np.ndarray) -> np.ndarray:
        """What :meth:`rms_nm` and the dense correction take of exposures' slopes: the slopes
        themselves (the iterative path's :class:`luckyao.layer_tomography.correction.LayerEstimator`
        gives its layer estimates)."""
        return slopes

    def rms_nm(self, slopes: np.ndarray) -> np.ndarray:
        """Each target's reconstructed tilt-removed rms [nm] (n_targets, ...) from
        slopes (..., n_beacons, 2, n_valid): a frame's exposures in one call read
        the reconstructors once."""
        return np.array([lgs_rms_nm(r.T, slopes) for r in self._transposed])  # r.T.T: r itself
