"""The layer tomography in the time loop (``tomography.method: iterative``): each exposure's layer
estimate, made once (warm-started from the previous exposure's), gives every target's ``lgs_rms``
along its line of sight (:class:`LayerEstimator`, in place of the dense reconstructors of
:class:`luckyao.tomography.criterion.LgsRmsEstimator`) and, with AO, the DM commands
(:class:`LayerCorrection`, in place of the dense command matrix).

:func:`luckyao.steps.simulation.simulate` asks of an estimator ``estimate`` (an exposure's slopes to
what ``rms_nm`` and the correction take: here the layers) and ``rms_nm``; of a correction
``measure``, ``surface_at``, ``residual_rms_nm`` and ``dm``.
"""

import numpy as np
import scipy.sparse

from ..ao.correction import DelayedDm, OpenLoopCorrection
from ..ao.dm import GridSurface
from ..tomography.reconstructor import reconstruction_points
from .assembly import build_tomography
from .projection import DmProjection, LineOfSight, sparse_influence
from .solver import LayerTomography


class LayerEstimator:
    """Each exposure's layer estimate and its tilt-removed optical path along each target, at the
    dense reconstructors' pupil points (:func:`luckyao.tomography.reconstructor.reconstruction_points`);
    with AO, the estimate's projection onto the DM and the DM's influence at those points."""

    def __init__(
        self,
        tomography: LayerTomography,
        lines: list[LineOfSight],
        projection: DmProjection | None = None,
        dm_at_points: scipy.sparse.csr_matrix | None = None,
    ):
        self.tomography, self.lines = tomography, lines
        self.projection, self.dm_at_points = projection, dm_at_points

    @classmethod
    def for_case(cls, case, **options) -> "LayerEstimator":
        """The estimator of a :class:`luckyao.studyspec.case.Case` with LGS: its prior, WFS, beacons,
        slope noise (its NEA with a noisy geometric WFS) and ``tomography.iterative_rtol`` (a
        warm-started solve's tolerance), on grids covering its targets and correction direction;
        with AO, its DM and correction mode. ``options`` go to :func:`.assembly.build_tomography`."""
        targets = [(t.theta_x_rad, t.theta_y_rad) for t in case.targets]
        ao = case.ao if case.ao is not None and case.ao.enabled else None
        wfs = case.shack_hartmann()
        tomography = build_tomography(
            case.tomography.prior,
            wfs,
            case.lgs.directions_rad,
            case.lgs.height_m,
            case.tomography.noise_rms_rad,
            noise_covariance_rad2=case.slope_noise_covariance_rad2(wfs),
            target_directions_rad=targets + ([ao.correction_direction_rad] if ao else []),
            **{"warm_rtol": case.tomography.iterative_rtol, **options},
        )
        grids = tomography.operator.grids
        points = reconstruction_points(case.telescope, wfs.subaperture_m, case.tomography.points_per_subaperture)
        lines = [LineOfSight.build(grids, points, direction) for direction in targets]
        if ao is None:
            return cls(tomography, lines)
        dm = ao.deformable_mirror(case.telescope)
        projection = DmProjection.build(grids, dm, ao.mode, ao.correction_direction_rad, ao.glao_max_height_m)
        return cls(tomography, lines, projection, sparse_influence(dm, points))

    @property
    def n_slopes(self) -> int:
        return self.tomography.operator.n_slopes

    def estimate(self, slopes: np.ndarray) -> np.ndarray:
        """Layers ``(exposure, n_layers, n, n)`` [m] of slopes ``(exposure, n_beacons, 2, n_valid)``
        [rad], each exposure's warm-started from the one before."""
        return np.stack([self.tomography.estimate(exposure) for exposure in slopes])

    def rms_nm(self, layers: np.ndarray) -> np.ndarray:
        """Each target's tilt-removed rms [nm] ``(n_targets, exposure)`` of ``layers`` along it."""
        return np.array([[line.rms_nm(x) for x in layers] for line in self.lines])

    def residual_rms_nm(self, layers: np.ndarray, dm_commands_m: np.ndarray) -> np.ndarray:
        """Each target's tilt-removed rms [nm] ``(n_targets, exposure)`` of ``layers`` along it less
        the DM's shape of ``dm_commands_m`` ``(exposure, n_act)`` [m]: the pseudo-closed-loop residual."""
        shapes = (self.dm_at_points @ np.asarray(dm_commands_m, dtype=float).T).T  # (exposure, n_points) [m]
        return np.array([[line.rms_nm(x, shape) for x, shape in zip(layers, shapes)] for line in self.lines])


class LayerCorrection(OpenLoopCorrection):
    """:class:`luckyao.ao.correction.OpenLoopCorrection` whose commands are each exposure's layer
    estimate fitted onto the DM (``projection``), and whose pseudo-closed-loop residual is that
    estimate less the DM shape applied during the exposure (no DM slopes: :meth:`residual_rms_nm`);
    the remaining arguments are the :class:`luckyao.ao.correction.DelayedDm`'s."""

    def __init__(
        self,
        projection: DmProjection,
        surface: GridSurface,
        exposure_steps: int,
        delay_steps: int,
        lookahead_steps: int,
    ):
        self.dm = DelayedDm(surface, exposure_steps, delay_steps, lookahead_steps)
        if projection.n_actuators != self.dm.n_actuators:
            raise ValueError("the layer tomography's DM projection does not match this DM: rebuild it")
        self.projection = projection

    def measure(self, start_step: int, layers: np.ndarray) -> np.ndarray:
        """The commands (n_act,) float32 [m] of the exposure starting at ``start_step`` from its
        layer estimate ``(n_layers, n, n)`` [m], handed to the DM."""
        commands = self.projection.commands(layers).astype(np.float32)
        self.dm.apply(start_step, commands)
        return commands

    def residual_rms_nm(self, start_steps, layers: np.ndarray, estimator: LayerEstimator) -> np.ndarray:
        """Each target's pseudo-closed-loop rms [nm] ``(n_targets, exposure)`` of the exposures
        starting at ``start_steps``: their layer estimates less the DM shape applied during each."""
        applied = np.stack([self.applied_commands(int(step)) for step in start_steps])
        return estimator.residual_rms_nm(layers, applied)
