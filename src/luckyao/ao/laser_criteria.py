"""Laser-only selection criteria of an AO case (``ao.laser_criteria``): per lucky frame, from
the LGS slopes and the DM commands alone, no photon of the target.

Every value is a tilt-removed rms [nm] at the reconstruction points (the tomography's pupil
points, :func:`luckyao.tomography.reconstructor.reconstruction_points`), combined over the
frame's WFS exposures as ``sqrt(mean(rms^2))`` (:func:`.criterion.lucky_frame_rms_nm`); smaller
is better. With ``R`` a target's tilt-removed reconstructor, ``H`` the DM's influence functions
at the points and ``F`` their least-squares DM fit (no piston/tip/tilt):

* ``lgs_high_order_rms``: ``(I - H F) R s``, the reconstructed phase along the target that the
  DM cannot fit: what a WFS finer than the DM sees of the fitting error. With the paper's
  8x8 WFS under a 9x9 (Fried) DM the reconstruction holds little beyond the DM's reach (the
  slopes sample the DM's scales only), so the value is small; it grows with a finer WFS.
* ``lgs_ground_rms`` and ``lgs_altitude_rms``: ``R_l s``, the reconstruction along the target
  restricted to the ground layers (those GLAO corrects, :func:`.control.ground_layers` with
  ``ao.glao_max_height_m``) and to the others: their sum is ``R s``.
* ``dm_change_rms``: ``H (c_e - c_(e-1))``, how far the DM moves between consecutive
  exposures (before the first, the flat DM): a proxy of the servo-lag part of the residual.
  The same for every target (the DM is conjugate to the pupil).
* ``lgs_slope_rms``: the rms of the beacons' tilt-removed slopes times the sub-aperture width,
  the optical-path difference across a sub-aperture: a seeing proxy, the same for every target.

The laser spots' widths and peaks (sub-aperture-scale turbulence) are not among them: an AO
case's time loop replays the slopes of its slopes product (:mod:`luckyao.steps.lgs_slopes`),
which never holds the spot images.
"""

import numpy as np

from ..optics.pupil import TiltRemover
from ..tomography.criterion import LgsRmsEstimator, lucky_frame_rms_nm

TARGET_CRITERIA = (
    ("lgs_high_order_rms", "LGS reconstruction along the target that the DM cannot fit (tilt-removed rms)"),
    ("lgs_ground_rms", "LGS reconstruction of the ground layers along the target (tilt-removed rms)"),
    ("lgs_altitude_rms", "LGS reconstruction of the altitude layers along the target (tilt-removed rms)"),
)
"""Criteria of each target (telemetry ``<name>_nm`` (target, frame)), in :meth:`LaserCriteria.frame`'s order."""

FRAME_CRITERIA = (
    ("dm_change_rms", "DM command change between consecutive WFS exposures at the pupil (tilt-removed rms)"),
    ("lgs_slope_rms", "LGS slope rms times the sub-aperture width (optical-path difference across one)"),
)
"""Criteria of the frame, every target's alike (telemetry ``<name>_nm`` (frame,))."""


def dm_residual_projector(influence: np.ndarray, fit: np.ndarray) -> np.ndarray:
    """``I - H F`` (n_points, n_points): a phase at the points less its DM fit; ``influence``
    ``H`` (n_points, n_act) and ``fit`` ``F`` (n_act, n_points)
    (:meth:`.dm.DeformableMirror.fit_matrix`), so piston, tip and tilt pass through."""
    return np.eye(influence.shape[0]) - influence @ fit


class LaserCriteria:
    """Each frame's laser-only criteria (the module's) of a case's targets.

    ``reconstructors`` (target, point, slope) [m / rad] tilt-removed, as the case's
    (:func:`luckyao.tomography.reconstructor.target_reconstructor`); ``layer_reconstructors``
    (2, target, point, slope) the same restricted to the ground and to the altitude layers;
    ``influence`` (n_points, n_act) and ``fit`` (n_act, n_points) the DM's at the points
    ``points_xy_m`` (n_points, 2) [m]; ``subaperture_m`` the WFS sub-aperture width [m].
    """

    def __init__(self, reconstructors, layer_reconstructors, influence, fit, points_xy_m, subaperture_m: float):
        reconstructors = np.asarray(reconstructors, dtype=np.float64)
        high = dm_residual_projector(influence, fit) @ reconstructors  # (target, point, slope)
        stacked = np.concatenate([high[None], np.asarray(layer_reconstructors, dtype=np.float64)])
        self.n_targets = reconstructors.shape[0]
        self._estimator = LgsRmsEstimator(stacked.reshape(-1, *reconstructors.shape[1:]), reconstructors.shape[-1])
        self._influence = np.asarray(influence, dtype=np.float32)
        self._tilt = TiltRemover(np.asarray(points_xy_m)[:, 0], np.asarray(points_xy_m)[:, 1])
        self._subaperture_m = subaperture_m
        self._previous = np.zeros(self._influence.shape[1], dtype=np.float32)  # the flat DM

    def frame(self, slopes: np.ndarray, commands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The frame's criteria [nm]: (len(TARGET_CRITERIA), target) and (len(FRAME_CRITERIA),),
        from its exposures' ``slopes`` (exposure, beacon, axis, subaperture) [rad] and
        ``commands`` (exposure, actuator) [m], the frames fed in time order."""
        per_target = lucky_frame_rms_nm(self._estimator.rms_nm(slopes)).reshape(-1, self.n_targets)
        commands = np.asarray(commands, dtype=np.float32)
        changes = np.diff(np.concatenate([self._previous[None], commands]), axis=0)
        self._previous = commands[-1].copy()
        change_nm = self._tilt.rms(changes @ self._influence.T) * 1e9
        flat = np.asarray(slopes, dtype=np.float64).reshape(len(slopes), -1)
        slope_nm = np.sqrt(np.mean(flat**2, axis=-1)) * self._subaperture_m * 1e9
        return per_target, np.array([lucky_frame_rms_nm(change_nm), lucky_frame_rms_nm(slope_nm)])
