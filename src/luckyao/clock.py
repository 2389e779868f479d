"""The frame clock: a lucky frame -> its time steps -> its WFS exposures (the one home of
that arithmetic).

A case's time runs in steps of ``time_step_s`` from step 0. Camera frame ``f`` is the
``steps_per_frame`` steps from ``f * steps_per_frame``; WFS exposure ``e`` is the
``exposure_steps`` steps from ``e * exposure_steps``. A frame holds whole exposures
(``exposure_steps`` divides ``steps_per_frame``: the config's validation), so frame ``f``'s
exposures are ``f * steps_per_frame / exposure_steps`` on, and the exposure of step ``s`` is
``s // exposure_steps``.
"""

from dataclasses import dataclass

import numpy as np


def frame_count(case: dict) -> int:
    """Whole lucky frames in a resolved case's duration."""
    return int(np.floor(case["duration_s"] / case["camera"]["frame_time_s"] + 1e-9))


def steps_per_frame(case: dict) -> int:
    """Time steps of one camera frame of a resolved case."""
    return round(case["camera"]["frame_time_s"] / case["time_step_s"])


@dataclass(frozen=True)
class FrameClock:
    """Frames, steps and WFS exposures of a run of ``n_frames`` frames."""

    steps_per_frame: int
    exposure_steps: int
    n_frames: int

    @classmethod
    def from_config(cls, case: dict) -> "FrameClock":
        """The clock of a resolved case (its whole duration)."""
        return cls(steps_per_frame(case), case["wfs"]["exposure_steps"], frame_count(case))

    @property
    def n_steps(self) -> int:
        """Time steps of the run."""
        return self.n_frames * self.steps_per_frame

    @property
    def n_exposures(self) -> int:
        """WFS exposures of the run."""
        return self.n_steps // self.exposure_steps

    @property
    def exposures_per_frame(self) -> int:
        return self.steps_per_frame // self.exposure_steps

    def steps(self, frame: int) -> np.ndarray:
        """Frame ``frame``'s time steps (steps_per_frame,) int."""
        return frame * self.steps_per_frame + np.arange(self.steps_per_frame)

    def exposure_offsets(self) -> range:
        """Where a frame's exposures start among its steps: 0, exposure_steps, ..."""
        return range(0, self.steps_per_frame, self.exposure_steps)

    def exposure_starts(self, steps: np.ndarray) -> np.ndarray:
        """The first steps of the exposures of a frame's ``steps`` (:meth:`steps`)."""
        return steps[:: self.exposure_steps]

    def exposure(self, step):
        """The exposure holding time step ``step``."""
        return step // self.exposure_steps

    def frame_exposures(self, frame: int) -> slice:
        """Frame ``frame``'s exposures, as a slice of the run's."""
        return slice(self.exposure(frame * self.steps_per_frame), self.exposure((frame + 1) * self.steps_per_frame))
