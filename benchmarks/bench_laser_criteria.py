"""Benchmark: what the laser-only criteria (``ao.laser_criteria``) add per simulated step.

The whole time loop (``simulation.TimeLoop``, frames discarded, the LGS chain measured in
it: ``bench_step.whole_loop_ms``) of the default AO case (``ltao_r0_13.5cm``) and of its
GLAO twin, without and with the criteria, run ``REPEATS`` times interleaved, single thread;
printed as ``ms_per_step_<case>[_laser] <median>``, then each case's increment. The increment is
per lucky frame (three more reconstructions per exposure, the DM change and the slope rms),
so per step it is a quarter of a frame's; the per-layer reconstructors' set-up is outside
the timing (``TimeLoop`` builds them), and timed once here.

Run: .venv/bin/python benchmarks/bench_laser_criteria.py [config.yaml]
"""

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import sys  # noqa: E402
import time  # noqa: E402

from ao_option import compare  # noqa: E402

from luckyao.steps.simulation import laser_criteria_of  # noqa: E402
from luckyao.studyspec.case import Case  # noqa: E402


def time_set_up(configs, built):
    """The per-layer reconstructors' set-up (outside the loop's timing: ``TimeLoop`` builds them)."""
    start = time.perf_counter()
    laser_criteria_of(Case.from_config(configs["ltao_laser"]), built["ltao"][0])
    print(f"laser_criteria_setup_s {time.perf_counter() - start:.2f}")


def main(config_path="config/config.yaml"):
    compare(config_path, "laser_criteria", "laser", time_set_up)


if __name__ == "__main__":
    main(*sys.argv[1:])
