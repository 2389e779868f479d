"""What an opt-in AO key adds per simulated step: the whole time loop (``simulation.TimeLoop``,
frames discarded, the LGS chain measured in it: ``bench_step.whole_loop_ms``) of the default AO
case (``ltao_r0_13.5cm``) and of its GLAO twin, without and with ``ao.<key>``, run ``REPEATS``
times interleaved, single thread; printed as ``ms_per_step_<case>[_<label>] <median>``, then
``<label>_ms_per_step_<mode>``, each case's increment. Used by ``bench_budget.py`` and
``bench_laser_criteria.py`` (the caller pins one thread before numpy is imported)."""

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_step import DEFAULT_CASE, products, whole_loop_ms  # noqa: E402

from luckyao.steps.screens import read_screens, write_screens  # noqa: E402
from luckyao.studyspec.case import Case  # noqa: E402
from luckyao.studyspec.products import turbulence_spec  # noqa: E402
from luckyao.studyspec.schema import deep_merge  # noqa: E402
from luckyao.studyspec.study import load_study  # noqa: E402

N_STEPS = 400
REPEATS = 3
MODES = ("ltao", "glao")


def compare(config_path: str, key: str, label: str, set_up=None) -> None:
    """Time the loop without and with ``ao.<key>``; ``set_up(configs, built)``, if given, runs
    once before the timing (e.g. to time what ``TimeLoop`` builds for the key)."""
    study, cases = load_study(config_path)
    duration_s = N_STEPS * cases[DEFAULT_CASE]["time_step_s"]
    base = dict(cases[DEFAULT_CASE], duration_s=duration_s)
    configs = {
        f"{mode}{f'_{label}' if on else ''}": deep_merge(base, {"ao": {"mode": mode, key: on}})
        for mode in MODES
        for on in (False, True)
    }
    spec = dict(turbulence_spec(study, base), duration_s=duration_s + 0.1)
    with tempfile.TemporaryDirectory() as tmp:
        write_screens(spec, Path(tmp) / "s.npy", Path(tmp) / "s.nc", {})
        screens = read_screens(Path(tmp) / "s.npy", Path(tmp) / "s.nc")
        np.asarray(screens.flat).sum()  # page the memory-mapped screens in
        built = {mode: products(study, configs[mode]) for mode in MODES}
        if set_up is not None:
            set_up(configs, built)
        runs = {name: [] for name in configs}
        for _ in range(REPEATS):  # interleaved, so that the machine's drift hits every case alike
            for name, config in configs.items():
                start = time.perf_counter()
                runs[name].append(whole_loop_ms(Case.from_config(config), screens, *built[name.split("_")[0]]))
                print(f"{name}: {runs[name][-1]:.3f} ms per step ({time.perf_counter() - start:.0f} s)", flush=True)
        for name, ms in runs.items():
            print(f"ms_per_step_{name} {np.median(ms):.3f} (runs: {', '.join(f'{m:.3f}' for m in ms)})")
        for mode in MODES:
            print(f"{label}_ms_per_step_{mode} {np.median(runs[f'{mode}_{label}']) - np.median(runs[mode]):.3f}")
