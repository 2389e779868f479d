"""Benchmark: ms per simulated 2.5 ms step, by stage, and the whole time loop per case.

Single thread, screens for a short stretch of time (the per-step cost does not
depend on the duration). First the stages of the default AO case
(``ltao_r0_13.5cm``: LTAO, 4 Rayleigh LGS, 8x8 WFS, 9x9 DM, tomography, the
lgs_rms and pseudo-closed-loop criteria), timed one by one; then the whole
time loop (``simulation.simulate``, frames discarded) of the no-AO case with LGS
and of LTAO with 8x8, 16x16 and 32x32 WFS, run 5 times interleaved, each printed
as ``ms_per_step_<case> <median>``; last, ``ms_per_step <median>``: the whole loop
of the default AO case.

Run: .venv/bin/python benchmarks/bench_step.py [config.yaml]
"""

import dataclasses
import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_name] = "1"

import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from luckyao.ao.correction import OpenLoopCorrection  # noqa: E402
from luckyao.optics.imaging import Imager  # noqa: E402
from luckyao.optics.propagation import Propagator  # noqa: E402
from luckyao.optics.pupil import TiltRemover  # noqa: E402
from luckyao.study.case import Case  # noqa: E402
from luckyao.study.calibration import build_calibration  # noqa: E402
from luckyao.study.config import (calibration_spec, commands_spec, deep_merge, load_study,  # noqa: E402
                                  reconstructor_spec, turbulence_spec)
from luckyao.study.reconstructor import build_commands, build_reconstructors  # noqa: E402
from luckyao.study.simulation import lgs_chain, simulate  # noqa: E402
from luckyao.study.turbulence import read_screens, write_screens  # noqa: E402
from luckyao.units import REFERENCE_WAVELENGTH_M  # noqa: E402

N_STEPS = 800
DEFAULT_CASE = "ltao_r0_13.5cm"
WHOLE_LOOP_CASES = ("noao_r0_13.5cm", "ltao_wfs16", "ltao_wfs32", DEFAULT_CASE)
REPEATS = 5


CALIBRATION_DRAWS = 8
"""Turbulence draws of the benchmarks' WFS calibration: its gains' precision costs nothing per step."""


def products(study: dict, config: dict):
    """The case's reconstructors, (with AO) its command matrix and DM slopes, and (with
    ``wfs.calibration``) its WFS calibration, from few draws."""
    reconstructors = build_reconstructors(reconstructor_spec(config))["reconstructor"].values
    spec = calibration_spec(study, deep_merge(config, {"wfs": {"calibration_draws": CALIBRATION_DRAWS}}))
    calibration = None if spec is None else build_calibration(spec)
    spec = commands_spec(config)
    if spec is None:
        return reconstructors, None, calibration
    commands = build_commands(spec)
    return reconstructors, (commands["command_matrix"].values, commands["dm_slopes"].values), calibration


def stages(case: Case, screens, reconstructors, commands, calibration) -> dict:
    """Seconds spent per stage over N_STEPS steps of the default AO chain."""
    imager = Imager(case.telescope, case.camera)
    propagator = Propagator(list(case.layers), screens, list(case.targets), imager.grid, mask=imager.mask)
    tilt = TiltRemover.for_mask(imager.grid, imager.mask)
    to_camera = np.float32(REFERENCE_WAVELENGTH_M / case.camera.wavelength_m)
    for step in range(8):  # warm up: JIT, FFT plans
        imager.intensity(propagator.sample_valid([step], case.layer_scales([step]))[0] * to_camera)
    sensor, estimator = lgs_chain(case, screens, reconstructors, 1, calibration)
    surface = case.ao.deformable_mirror(case.telescope).grid_surface(imager.grid, imager.mask)
    correction = OpenLoopCorrection(*commands, surface, sensor.exposure_steps, case.ao.delay_steps,
                                        case.steps_per_frame)
    e, spf = sensor.exposure_steps, case.steps_per_frame
    estimator.rms_nm(sensor.exposure_slopes(np.arange(e), case.layer_scales(np.arange(e))))
    names = ["LGS propagation", "WFS", "reconstruction", "DM commands + residual", "science propagation",
             "DM surface", "science image", "truth rms", "frame"]
    spent = dict.fromkeys(names, 0.0)
    intensity = np.zeros((len(case.targets), imager.fft_size, imager.fft_size), dtype=np.float32)
    for frame in range(N_STEPS // spf):
        steps = frame * spf + np.arange(spf)
        layer_scales = case.layer_scales(steps)
        slopes = []
        for i in range(0, spf, e):
            t0 = time.perf_counter()
            sensor.sample(steps[i:i + e], layer_scales[i:i + e])
            t1 = time.perf_counter()
            slopes.append(sensor.slopes())
            spent["LGS propagation"] += t1 - t0
            spent["WFS"] += time.perf_counter() - t1
        t0 = time.perf_counter()
        slopes = np.stack(slopes)
        estimator.rms_nm(slopes)
        t1 = time.perf_counter()
        for start, exposure in zip(steps[::e], slopes):
            correction.measure(int(start), exposure)
        estimator.rms_nm(np.stack([correction.residual_slopes(int(s), x) for s, x in zip(steps[::e], slopes)]))
        t2 = time.perf_counter()
        phases = propagator.sample_valid(steps, layer_scales)
        t3 = time.perf_counter()
        residuals = [phase - correction.surface_at(int(step)) for step, phase in zip(steps, phases)]
        t4 = time.perf_counter()
        for phase in residuals:
            imager.accumulate(phase * to_camera, intensity)
        t5 = time.perf_counter()
        for phase in residuals:
            tilt.rms(phase)
        t6 = time.perf_counter()
        imager.to_pixels(intensity / spf)
        intensity.fill(0.0)
        t7 = time.perf_counter()
        for name, dt in zip(names[2:], (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5, t7 - t6)):
            spent[name] += dt
    return spent


def whole_loop_ms(case: Case, screens, reconstructors, commands, calibration) -> float:
    """ms per step of ``simulate``: the time of the case's N_STEPS steps less that of
    its first 4 frames, over the steps between (so set-up, e.g. FFT plans, drops out);
    a first short run compiles what the case needs."""
    seconds = []
    for frames in (4, 4, case.n_frames):
        run = dataclasses.replace(case, n_frames=frames)
        sensor, estimator = lgs_chain(run, screens, reconstructors, 1, calibration)
        start = time.perf_counter()
        simulate(run, screens, lambda start, block: None, sensor, estimator, commands)
        seconds.append(time.perf_counter() - start)
    return 1e3 * (seconds[2] - seconds[1]) / ((case.n_frames - 4) * case.steps_per_frame)


def main(config_path="config/config.yaml"):
    study, cases = load_study(config_path)
    duration_s = N_STEPS * cases[DEFAULT_CASE]["time_step_s"]
    configs = {name: dict(cases[name], duration_s=duration_s) for name in WHOLE_LOOP_CASES}
    spec = dict(turbulence_spec(study, configs[DEFAULT_CASE]), duration_s=duration_s + 0.1)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        write_screens(spec, Path(tmp) / "s.npy", Path(tmp) / "s.nc", {})
        print(f"screens for {spec['duration_s']:.1f} s: {time.perf_counter() - start:.1f} s")
        screens = read_screens(Path(tmp) / "s.npy", Path(tmp) / "s.nc")
        np.asarray(screens.flat).sum()  # page the memory-mapped screens in
        built = {}
        for name, config in configs.items():
            start = time.perf_counter()
            built[name] = products(study, config)
            print(f"{name}: reconstructor, command matrix and WFS calibration in {time.perf_counter() - start:.1f} s")
        default = Case.from_config(configs[DEFAULT_CASE])
        spent = stages(default, screens, *built[DEFAULT_CASE])
        print(f"{DEFAULT_CASE}: {len(default.layers)} layers, {N_STEPS} steps, single thread")
        for name, total in spent.items():
            print(f"{name:>24s}: {1e3 * total / N_STEPS:.3f} ms per step")
        print(f"ms_per_step_stages_sum {1e3 * sum(spent.values()) / N_STEPS:.3f}")
        runs = {name: [] for name in WHOLE_LOOP_CASES}
        for _ in range(REPEATS):  # interleaved, so that the machine's drift hits every case alike
            for name in WHOLE_LOOP_CASES:
                runs[name].append(whole_loop_ms(Case.from_config(configs[name]), screens, *built[name]))
        for name, ms in runs.items():
            print(f"ms_per_step_{name} {np.median(ms):.3f} (runs: {', '.join(f'{m:.2f}' for m in ms)})")
        print(f"ms_per_step {np.median(runs[DEFAULT_CASE]):.3f}")


if __name__ == "__main__":
    main(*sys.argv[1:])
