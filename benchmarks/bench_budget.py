"""Benchmark: what the residual budget (``ao.residual_budget``) adds per simulated step.

The whole time loop (``simulation.TimeLoop``, frames discarded, the LGS chain measured in
it: ``bench_step.whole_loop_ms``) of the default AO case (``ltao_r0_13.5cm``) and of its
GLAO twin, without and with the budget, run ``REPEATS`` times interleaved, single thread;
printed as ``ms_per_step_<case>[_budget] <median>``, then each case's budget increment. The
increment is the noiseless twin of the LGS sensor and the budget's own products (the DM
fits of the science and beacon phases, six part surfaces and their tilt-removed rms per
step); a workflow simulation replays its recorded slopes, so there the twin sensor is all
the LGS sensing it runs.

Run: .venv/bin/python benchmarks/bench_budget.py [config.yaml]
"""

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import sys  # noqa: E402

from ao_option import compare  # noqa: E402


def main(config_path="config/config.yaml"):
    compare(config_path, "residual_budget", "budget")


if __name__ == "__main__":
    main(*sys.argv[1:])
