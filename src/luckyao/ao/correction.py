"""The open-loop correction of the time loop: LGS slopes -> DM commands -> DM surface, with a delay.

The WFS are open loop: they never see the DM, so every exposure can be sensed
before the science steps it corrects. The commands ``c_e = M s_e`` of the
exposure over steps ``[s, s + E)`` (``M`` from :func:`.control.command_matrix`)
are applied to the science path from step ``s + delay_steps`` for ``E`` steps,
until the next exposure's command takes over (``delay_steps = E``: a 5 ms
exposure's command holds during the next exposure). Before the first command
the DM is flat. The DM is conjugate to the pupil, so every line of sight sees
the same surface ``H c`` (the influence functions at the science pupil samples,
:class:`.dm.GridSurface`), subtracted from the turbulence.

Pseudo-closed loop: the residual slopes of exposure ``e`` are ``s_e - D c_e'``,
``D`` the DM's slopes as every WFS sees them (:func:`.control.dm_slopes_matrix`)
and ``c_e'`` the mean command applied during that exposure; reconstructed along a
target they estimate the corrected residual without photons from it.
"""

import numpy as np

from ..units import REFERENCE_WAVELENGTH_M
from .dm import GridSurface


class DelayedDm:
    """The DM of the time loop: each exposure's commands and the surface they make,
    applied ``delay_steps`` after the exposure starts, until the next exposure's.

    ``surface``: commands [m] -> the DM surface [m] at the science pupil samples
    (n_samples,), in the order the propagator packs them. ``lookahead_steps``: how
    far commands may arrive ahead of the science steps (a lucky frame's steps, when
    its exposures are all sensed first). Fed by :class:`OpenLoopCorrection` in the
    time loop, or directly with recorded commands when the science path is replayed.
    """

    def __init__(self, surface: GridSurface, exposure_steps: int, delay_steps: int, lookahead_steps: int):
        if delay_steps < exposure_steps:
            raise ValueError(
                f"a command cannot be applied before its exposure ends: delay_steps "
                f"{delay_steps} < exposure_steps {exposure_steps}"
            )
        self.surface = surface
        self.exposure_steps, self.delay_steps, self.lookahead_steps = exposure_steps, delay_steps, lookahead_steps
        self.n_actuators = int(surface.valid.sum())
        self._commands = {}  # exposure start step -> commands (n_act,) float32 [m]
        self._surfaces = {}  # exposure start step -> DM surface (n_samples,) float32 [rad at 500 nm]
        self._flat_commands = np.zeros(self.n_actuators, dtype=np.float32)
        self._flat_surface = np.zeros(surface.samples.size, dtype=np.float32)

    def apply(self, start_step: int, commands: np.ndarray) -> None:
        """The commands (n_act,) [m] of the exposure starting at ``start_step``; commands no
        longer needed are dropped."""
        commands = np.asarray(commands, dtype=np.float32)
        self._commands[start_step] = commands
        # in rad at the reference wavelength, that of the stored phases
        self._surfaces[start_step] = (self.surface(commands) * (2 * np.pi / REFERENCE_WAVELENGTH_M)).astype(np.float32)
        oldest = self.oldest_needed(start_step)
        for key in [k for k in self._commands if k < oldest]:
            del self._commands[key], self._surfaces[key]

    def oldest_needed(self, start_step: int) -> int:
        """The oldest exposure start step whose command may still be applied once the exposure
        starting at ``start_step`` is known (older ones can be dropped)."""
        return start_step - self.delay_steps - self.exposure_steps - self.lookahead_steps

    def source_step(self, step: int) -> int:
        """Start step of the exposure whose command is applied at ``step`` (< 0: none yet)."""
        return (step - self.delay_steps) // self.exposure_steps * self.exposure_steps

    def commands_at(self, step: int) -> np.ndarray:
        """Commands (n_act,) [m] applied at ``step``."""
        source = self.source_step(step)
        return self._commands[source] if source >= 0 else self._flat_commands

    def surface_at(self, step: int) -> np.ndarray:
        """DM surface (n_samples,) [rad at 500 nm] at the science pupil samples at ``step``."""
        source = self.source_step(step)
        return self._surfaces[source] if source >= 0 else self._flat_surface

    def surface_of(self, start_step: int) -> np.ndarray:
        """DM surface (n_samples,) [rad at 500 nm] of the command of the exposure starting at ``start_step``."""
        return self._surfaces[start_step]


class OpenLoopCorrection:
    """LGS slopes -> each exposure's commands -> the :class:`DelayedDm`.

    ``command_matrix`` (n_act, n_slopes) [m / rad]; ``dm_slopes`` (n_slopes, n_act)
    [rad / m]; the other arguments are the :class:`DelayedDm`'s.
    """

    def __init__(
        self,
        command_matrix: np.ndarray,
        dm_slopes: np.ndarray,
        surface: GridSurface,
        exposure_steps: int,
        delay_steps: int,
        lookahead_steps: int,
    ):
        self.dm = DelayedDm(surface, exposure_steps, delay_steps, lookahead_steps)
        if command_matrix.shape[0] != self.dm.n_actuators or dm_slopes.shape != command_matrix.shape[::-1]:
            raise ValueError("the command matrix does not match this DM or WFS: rebuild it")
        self.command_matrix = np.asarray(command_matrix, dtype=np.float32)
        self.dm_slopes = np.asarray(dm_slopes, dtype=np.float32)

    def measure(self, start_step: int, slopes: np.ndarray) -> np.ndarray:
        """The commands (n_act,) float32 [m] of the exposure starting at ``start_step`` from
        its tilt-removed slopes (n_beacons, 2, n_valid) [rad], handed to the DM."""
        commands = self.command_matrix @ np.asarray(slopes, dtype=np.float32).ravel()
        self.dm.apply(start_step, commands)
        return commands

    def surface_at(self, step: int) -> np.ndarray:
        """DM surface (n_samples,) [rad at 500 nm] at the science pupil samples at ``step``."""
        return self.dm.surface_at(step)

    def applied_commands(self, start_step: int) -> np.ndarray:
        """The mean command (n_act,) [m] applied during the exposure starting at ``start_step``."""
        return np.mean([self.dm.commands_at(start_step + i) for i in range(self.dm.exposure_steps)], axis=0)

    def residual_slopes(self, start_step: int, slopes: np.ndarray) -> np.ndarray:
        """Pseudo-closed-loop slopes of the exposure starting at ``start_step``: its
        open-loop slopes less the DM's, for the mean command applied during it."""
        return slopes - (self.dm_slopes @ self.applied_commands(start_step)).reshape(slopes.shape)

    def residual_rms_nm(self, start_steps, slopes: np.ndarray, estimator) -> np.ndarray:
        """Each target's pseudo-closed-loop rms [nm] (n_targets, exposure) of the exposures starting
        at ``start_steps``, their slopes (exposure, n_beacons, 2, n_valid) [rad]: ``estimator``'s
        (:class:`luckyao.tomography.criterion.LgsRmsEstimator`) of their :meth:`residual_slopes`."""
        return estimator.rms_nm(np.stack([self.residual_slopes(int(s), e) for s, e in zip(start_steps, slopes)]))
