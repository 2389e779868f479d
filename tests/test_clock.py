"""The frame clock (``luckyao.clock``): frames, their time steps and their WFS exposures tile the run."""

import numpy as np

from luckyao.clock import FrameClock, frame_count, steps_per_frame


def test_frames_and_exposures_tile_the_steps():
    clock = FrameClock(steps_per_frame=4, exposure_steps=2, n_frames=5)
    steps = [clock.steps(f) for f in range(clock.n_frames)]
    np.testing.assert_array_equal(np.concatenate(steps), np.arange(clock.n_steps))
    assert clock.n_exposures == 10 and clock.exposures_per_frame == 2
    for frame, s in enumerate(steps):
        starts = clock.exposure_starts(s)
        assert [int(s[i]) for i in clock.exposure_offsets()] == list(starts)
        assert [clock.exposure(int(t)) for t in starts] == list(range(clock.n_exposures))[clock.frame_exposures(frame)]
        assert {clock.exposure(int(t)) for t in s} == set(range(clock.n_exposures)[clock.frame_exposures(frame)])


def test_the_clock_of_a_config():
    case = {"duration_s": 1.0, "time_step_s": 0.0025, "camera": {"frame_time_s": 0.01}, "wfs": {"exposure_steps": 2}}
    assert (frame_count(case), steps_per_frame(case)) == (100, 4)
    assert FrameClock.from_config(case) == FrameClock(4, 2, 100)
