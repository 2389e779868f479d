"""The layer tomography in the time loop: an open-loop correction whose commands come from each
exposure's layer estimate (warm-started) fitted onto the DM, in place of the dense command matrix.

:class:`LayerCorrection` is what :func:`luckyao.steps.simulation.simulate` asks of its correction
(:class:`luckyao.ao.correction.OpenLoopCorrection`: ``measure``, ``surface_at``, ``residual_slopes``,
``dm``); :func:`layer_estimate_for` builds the estimate and its DM projection of a case.
"""

import numpy as np

from ..ao.correction import DelayedDm, OpenLoopCorrection
from ..ao.dm import GridSurface
from .assembly import build_tomography
from .projection import DmProjection
from .solver import LayerTomography


def layer_estimate_for(case, **options) -> tuple[LayerTomography, DmProjection]:
    """The layer tomography of a :class:`luckyao.studyspec.case.Case` (its prior, WFS, beacons and
    slope noise; grids covering its targets) and the projection of its AO mode onto its DM;
    ``options`` go to :func:`.assembly.build_tomography`."""
    targets = [(t.theta_x_rad, t.theta_y_rad) for t in case.targets] + [case.ao.correction_direction_rad]
    tomography = build_tomography(
        case.tomography.prior,
        case.shack_hartmann(),
        case.lgs.directions_rad,
        case.lgs.height_m,
        case.tomography.noise_rms_rad,
        target_directions_rad=targets,
        **options,
    )
    projection = DmProjection.build(
        tomography.operator.grids,
        case.ao.deformable_mirror(case.telescope),
        case.ao.mode,
        case.ao.correction_direction_rad,
        case.ao.glao_max_height_m,
    )
    return tomography, projection


class LayerCorrection(OpenLoopCorrection):
    """:class:`luckyao.ao.correction.OpenLoopCorrection` with commands ``F(x_hat(s))``: the layer
    estimate of each exposure's slopes (warm-started from the previous exposure's) projected onto
    the DM; ``dm_slopes`` and the remaining arguments as there."""

    def __init__(
        self,
        tomography: LayerTomography,
        projection: DmProjection,
        dm_slopes: np.ndarray,
        surface: GridSurface,
        exposure_steps: int,
        delay_steps: int,
        lookahead_steps: int,
    ):
        self.dm = DelayedDm(surface, exposure_steps, delay_steps, lookahead_steps)
        if projection.n_actuators != self.dm.n_actuators or dm_slopes.shape[1] != self.dm.n_actuators:
            raise ValueError("the layer tomography's DM projection does not match this DM: rebuild it")
        if dm_slopes.shape[0] != tomography.operator.n_slopes:
            raise ValueError("the DM slopes do not match the layer tomography's WFS: rebuild them")
        self.tomography, self.projection = tomography, projection
        self.dm_slopes = np.asarray(dm_slopes, dtype=np.float32)

    def measure(self, start_step: int, slopes: np.ndarray) -> np.ndarray:
        """The commands (n_act,) float32 [m] of the exposure starting at ``start_step``, handed to the DM."""
        commands = self.projection.commands(self.tomography.estimate(slopes)).astype(np.float32)
        self.dm.apply(start_step, commands)
        return commands
