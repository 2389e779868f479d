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
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from bench_step import DEFAULT_CASE, products, whole_loop_ms  # noqa: E402

from luckyao.steps.screens import read_screens, write_screens  # noqa: E402
from luckyao.steps.simulation import laser_criteria_of  # noqa: E402
from luckyao.studyspec.case import Case  # noqa: E402
from luckyao.studyspec.products import turbulence_spec  # noqa: E402
from luckyao.studyspec.schema import deep_merge  # noqa: E402
from luckyao.studyspec.study import load_study  # noqa: E402

N_STEPS = 400
REPEATS = 3


def main(config_path="config/config.yaml"):
    study, cases = load_study(config_path)
    duration_s = N_STEPS * cases[DEFAULT_CASE]["time_step_s"]
    base = dict(cases[DEFAULT_CASE], duration_s=duration_s)
    configs = {}
    for mode in ("ltao", "glao"):
        for laser in (False, True):
            configs[f"{mode}{'_laser' if laser else ''}"] = deep_merge(
                base, {"ao": {"mode": mode, "laser_criteria": laser}}
            )
    spec = dict(turbulence_spec(study, base), duration_s=duration_s + 0.1)
    with tempfile.TemporaryDirectory() as tmp:
        write_screens(spec, Path(tmp) / "s.npy", Path(tmp) / "s.nc", {})
        screens = read_screens(Path(tmp) / "s.npy", Path(tmp) / "s.nc")
        np.asarray(screens.flat).sum()  # page the memory-mapped screens in
        built = {mode: products(study, configs[mode]) for mode in ("ltao", "glao")}
        start = time.perf_counter()
        laser_criteria_of(Case.from_config(configs["ltao_laser"]), built["ltao"][0])
        print(f"laser_criteria_setup_s {time.perf_counter() - start:.2f}")
        runs = {name: [] for name in configs}
        for _ in range(REPEATS):  # interleaved, so that the machine's drift hits every case alike
            for name, config in configs.items():
                runs[name].append(whole_loop_ms(Case.from_config(config), screens, *built[name.split("_")[0]]))
                print(f"{name}: {runs[name][-1]:.3f} ms per step", flush=True)
        for name, ms in runs.items():
            print(f"ms_per_step_{name} {np.median(ms):.3f} (runs: {', '.join(f'{m:.3f}' for m in ms)})")
        for mode in ("ltao", "glao"):
            print(f"laser_ms_per_step_{mode} {np.median(runs[f'{mode}_laser']) - np.median(runs[mode]):.3f}")


if __name__ == "__main__":
    main(*sys.argv[1:])
