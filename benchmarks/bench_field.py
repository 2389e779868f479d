"""Benchmark: ms per 2.5 ms step of a field case (7 targets) against one target.

Single thread. Interleaved runs (median of REPEATS) of, per 2.5 ms step:

* ``single``: the whole time loop of the default AO case (one target);
* ``field_simulation``: the field case's time loop as the study runs it: LGS
  chain and DM shared, all 7 targets propagated (their truth), only the star imaged;
* ``field_replay``: one replay of the 6 off-axis targets' science path from the
  recorded DM commands (what the post-processing recomputes instead of reading
  stored frames; once per pass over the frames);
* ``field_all_imaged``: the time loop imaging all 7 targets (the alternative that
  would store 7 frame cubes).

Printed last: ``ms_per_step_field <simulation + passes x replay>`` with the passes
of the post-processing, and its ratio to ``single``.

Run: .venv/bin/python benchmarks/bench_field.py [config.yaml]
"""

import dataclasses

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from bench_step import products  # noqa: E402

from luckyao.steps.screens import read_screens, write_screens  # noqa: E402
from luckyao.steps.simulation import Replay, TimeLoop  # noqa: E402
from luckyao.studyspec.case import Case  # noqa: E402
from luckyao.studyspec.products import turbulence_spec  # noqa: E402
from luckyao.studyspec.resolved import imaged_targets  # noqa: E402
from luckyao.studyspec.study import load_study  # noqa: E402

N_STEPS = 600
SINGLE, FIELD = "ltao_r0_13.5cm", "ltao_field"
REPEATS = 5
REPLAY_PASSES = 1  # run_lucky reads a target selected and recentred by the star once (one pass)


def loop_seconds(case: Case, screens, reconstructors, commands, calibration, imaged=None):
    """Seconds of the case's time loop (``TimeLoop.run``; the LGS chain's set-up not counted) and
    its telemetry."""
    loop = TimeLoop(
        case,
        screens,
        1,
        reconstructors=reconstructors,
        calibration=calibration,
        commands=commands,
        imaged_targets=imaged,
    )
    start = time.perf_counter()
    telemetry = loop.run(lambda start, block: None)
    return time.perf_counter() - start, telemetry


def replay_seconds(case: Case, screens, targets, dm_commands) -> float:
    start = time.perf_counter()
    for _ in Replay(case, screens, targets, dm_commands)():
        pass
    return time.perf_counter() - start


def per_step_ms(timed, case: Case) -> float:
    """ms per step of ``timed(case)`` (seconds) over the steps between a 4-frame run and the
    whole run, so that set-up drops out."""
    short = timed(dataclasses.replace(case, n_frames=4))
    return 1e3 * (timed(case) - short) / (case.clock.n_steps - 4 * case.steps_per_frame)


def main(config_path="config/config.yaml"):
    study, cases = load_study(config_path)
    duration_s = N_STEPS * cases[SINGLE]["time_step_s"]
    configs = {name: dict(cases[name], duration_s=duration_s) for name in (SINGLE, FIELD)}
    spec = dict(turbulence_spec(study, configs[SINGLE]), duration_s=duration_s + 0.1)
    with tempfile.TemporaryDirectory() as tmp:
        write_screens(spec, Path(tmp) / "s.npy", Path(tmp) / "s.nc", {})
        screens = read_screens(Path(tmp) / "s.npy", Path(tmp) / "s.nc")
        np.asarray(screens.flat).sum()  # page the memory-mapped screens in
        built = {name: products(study, config) for name, config in configs.items()}
        single, field = Case.from_config(configs[SINGLE]), Case.from_config(configs[FIELD])
        imaged = imaged_targets(configs[FIELD])
        off_axis = [t for t in range(len(field.targets)) if t not in imaged]
        _, telemetry = loop_seconds(field, screens, *built[FIELD], imaged)
        commands = telemetry.dm_commands_m.values
        timings = {
            "single": lambda c: loop_seconds(c, screens, *built[SINGLE])[0],
            "field_simulation": lambda c: loop_seconds(c, screens, *built[FIELD], imaged)[0],
            "field_replay": lambda c: replay_seconds(c, screens, off_axis, commands),
            "field_all_imaged": lambda c: loop_seconds(c, screens, *built[FIELD])[0],
        }
        runs = {name: [] for name in timings}
        for _ in range(REPEATS):  # interleaved, so that the machine's drift hits every variant alike
            for name, timed in timings.items():
                runs[name].append(per_step_ms(timed, single if name == "single" else field))
        medians = {name: float(np.median(ms)) for name, ms in runs.items()}
        for name, ms in runs.items():
            print(f"ms_per_step_{name} {medians[name]:.3f} (runs: {', '.join(f'{m:.2f}' for m in ms)})")
        total = medians["field_simulation"] + REPLAY_PASSES * medians["field_replay"]
        print(f"{len(field.targets)} targets, {len(off_axis)} replayed, {REPLAY_PASSES} replay passes")
        print(f"ms_per_step_field {total:.3f} ({total / medians['single']:.2f} x one target)")


if __name__ == "__main__":
    main(*sys.argv[1:])
