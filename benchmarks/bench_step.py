"""Benchmark: ms per simulated 2.5 ms step, by stage, and the whole time loop per case.

Single thread, screens for a short stretch of time (the per-step cost does not
depend on the duration). First the stages of the default AO case
(``ltao_r0_13.5cm``: LTAO, 4 Rayleigh LGS, 8x8 WFS, 9x9 DM, tomography, the
lgs_rms and pseudo-closed-loop criteria), timed one by one; then the whole
time loop (``simulation.TimeLoop``, frames discarded) of the no-AO case with LGS
and of LTAO with 8x8, 16x16 and 32x32 WFS, run 5 times interleaved, each printed
as ``ms_per_step_<case> <median>``; last, ``ms_per_step <median>``: the whole loop
of the default AO case.

Run: .venv/bin/python benchmarks/bench_step.py [config.yaml]

Telescope size (``--diameters 2.5 4.2 8.2``): for each diameter, the default AO case at that
size (its WFS, DM, obscuration and camera derived, studyspec/scaling.py), each measured in fresh
processes so their peak memory is their own: the reconstructor and the command matrix (build
time, peak RSS), then the whole time loop (ms per step, median of ``--repeats`` runs, with
its peak RSS: the products loaded, the screens of the steps, a block of frames), and the
files a case of the default duration writes (the study's estimates, jobs/resources.py).
Printed as a table and one JSON line per diameter (``size {...}``); then each quantity's fitted
power law a D^b with its value at 39 m, and the study's own file-size estimates at 39 m.
"""

import argparse
import dataclasses
import json

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from luckyao.ao.correction import OpenLoopCorrection  # noqa: E402
from luckyao.jobs.resources import commands_bytes, frames_bytes, reconstructor_bytes, screens_bytes  # noqa: E402
from luckyao.optics.imaging import Imager  # noqa: E402
from luckyao.optics.propagation import Propagator  # noqa: E402
from luckyao.optics.pupil import TiltRemover  # noqa: E402
from luckyao.steps.calibration import build_calibration  # noqa: E402
from luckyao.steps.reconstructor import build_commands, build_reconstructors  # noqa: E402
from luckyao.steps.screens import read_screens, write_screens  # noqa: E402
from luckyao.steps.simulation import TimeLoop, lgs_chain  # noqa: E402
from luckyao.studyspec.case import Case  # noqa: E402
from luckyao.studyspec.products import calibration_spec, commands_spec, reconstructor_spec, turbulence_spec  # noqa: E402
from luckyao.studyspec.schema import deep_merge  # noqa: E402
from luckyao.studyspec.study import load_study, validate_study  # noqa: E402
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
    clock = case.clock
    correction = OpenLoopCorrection(
        *commands, surface, clock.exposure_steps, case.ao.delay_steps, clock.steps_per_frame
    )
    e, spf = clock.exposure_steps, clock.steps_per_frame
    estimator.rms_nm(sensor.exposure_slopes(np.arange(e), case.layer_scales(np.arange(e))))
    names = [
        "LGS propagation",
        "WFS",
        "reconstruction",
        "DM commands + residual",
        "science propagation",
        "DM surface",
        "science image",
        "truth rms",
        "frame",
    ]
    spent = dict.fromkeys(names, 0.0)
    intensity = np.zeros((len(case.targets), imager.fft_size, imager.fft_size), dtype=np.float32)
    for frame in range(N_STEPS // spf):
        steps = clock.steps(frame)
        layer_scales = case.layer_scales(steps)
        slopes = []
        for i in clock.exposure_offsets():
            t0 = time.perf_counter()
            sensor.sample(steps[i : i + e], layer_scales[i : i + e])
            t1 = time.perf_counter()
            slopes.append(sensor.slopes())
            spent["LGS propagation"] += t1 - t0
            spent["WFS"] += time.perf_counter() - t1
        t0 = time.perf_counter()
        slopes = np.stack(slopes)
        estimator.rms_nm(slopes)
        t1 = time.perf_counter()
        starts = clock.exposure_starts(steps)
        for start, exposure in zip(starts, slopes):
            correction.measure(int(start), exposure)
        estimator.rms_nm(np.stack([correction.residual_slopes(int(s), x) for s, x in zip(starts, slopes)]))
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
    """ms per step of the time loop (``TimeLoop.run``, the LGS chain measured in it; the chain's
    set-up before the clock starts): the time of the case's N_STEPS steps less that of its
    first 4 frames, over the steps between (so set-up, e.g. FFT plans, drops out); a first
    short run compiles what the case needs."""
    seconds = []
    for frames in (4, 4, case.n_frames):
        loop = TimeLoop(
            dataclasses.replace(case, n_frames=frames),
            screens,
            1,
            reconstructors=reconstructors,
            calibration=calibration,
            commands=commands,
        )
        start = time.perf_counter()
        loop.run(lambda start, block: None)
        seconds.append(time.perf_counter() - start)
    return 1e3 * (seconds[2] - seconds[1]) / (case.clock.n_steps - 4 * case.steps_per_frame)


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


def peak_rss_gb() -> float:
    """This process's peak resident memory [GB] (Linux: ru_maxrss in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def sized_study(config_path: str, diameter_m: float) -> tuple[dict, dict]:
    """The study and the default AO case at ``diameter_m`` (size-dependent keys derived)."""
    study, _ = load_study(config_path)
    sweep = dict(study["lucky"]["detector_sweep"], cases=[])  # the study's sweep cases are not here
    sized = dict(
        study,
        cases={"sized": {"telescope": {"diameter_m": diameter_m}, "ao": {"mode": "ltao"}}},
        figures={},
        sweeps={},
        lucky=dict(study["lucky"], detector_sweep=sweep),
    )
    return study, validate_study(sized)["sized"]


def measure_products(config_path: str, diameter_m: float, folder: str) -> dict:
    """Build the reconstructor, then the command matrix (each timed, with the peak RSS after it),
    and save them with the case's WFS calibration (few draws) to ``folder`` for the loop."""
    study, config = sized_study(config_path, diameter_m)
    start = time.perf_counter()
    reconstructors = build_reconstructors(reconstructor_spec(config))["reconstructor"].values
    built = time.perf_counter()
    out = {"reconstructor_s": built - start, "reconstructor_peak_gb": peak_rss_gb()}
    commands = build_commands(commands_spec(config))
    out.update(commands_s=time.perf_counter() - built, products_peak_gb=peak_rss_gb())
    spec = calibration_spec(study, deep_merge(config, {"wfs": {"calibration_draws": CALIBRATION_DRAWS}}))
    calibration = build_calibration(spec)
    np.save(Path(folder) / "reconstructors.npy", reconstructors)
    np.save(Path(folder) / "command_matrix.npy", commands["command_matrix"].values)
    np.save(Path(folder) / "dm_slopes.npy", commands["dm_slopes"].values)
    calibration.to_netcdf(Path(folder) / "calibration.nc")
    return out


def measure_loop(config_path: str, diameter_m: float, folder: str, repeats: int) -> dict:
    """ms per step of the whole time loop (median of ``repeats``) and the peak RSS."""
    import xarray as xr

    study, config = sized_study(config_path, diameter_m)
    config = dict(config, duration_s=N_STEPS * config["time_step_s"])
    spec = dict(turbulence_spec(study, config), duration_s=config["duration_s"] + 0.1)
    write_screens(spec, Path(folder) / "s.npy", Path(folder) / "s.nc", {})
    screens = read_screens(Path(folder) / "s.npy", Path(folder) / "s.nc")
    np.asarray(screens.flat).sum()  # page the memory-mapped screens in
    products_ = (
        np.load(Path(folder) / "reconstructors.npy"),
        (np.load(Path(folder) / "command_matrix.npy"), np.load(Path(folder) / "dm_slopes.npy")),
        xr.load_dataset(Path(folder) / "calibration.nc"),
    )
    case = Case.from_config(config)
    runs = [whole_loop_ms(case, screens, *products_) for _ in range(repeats)]
    return {"ms_per_step": float(np.median(runs)), "ms_per_step_runs": runs, "loop_peak_gb": peak_rss_gb()}


def case_files_gb(config_path: str, diameter_m: float) -> dict:
    """The files of the case at the study's default duration (the study's estimates) [GB]."""
    study, config = sized_study(config_path, diameter_m)
    return {
        "frames_gb": frames_bytes(config) / 1e9,
        "screens_gb": screens_bytes(turbulence_spec(study, config)) / 1e9,
        "reconstructor_gb": reconstructor_bytes(reconstructor_spec(config)) / 1e9,
        "commands_gb": commands_bytes(commands_spec(config)) / 1e9,
        "n_subapertures": config["wfs"]["n_subapertures"],
        "n_actuators": config["ao"]["n_actuators"],
        "camera_pixels": config["camera"]["n_pixels"],
    }


def child(stage: str, *args) -> dict:
    """Run one stage in a fresh process (its own peak memory); its last stdout line is JSON."""
    done = subprocess.run(
        [sys.executable, __file__, "--stage", stage, *map(str, args)], check=True, capture_output=True, text=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main_sizes(config_path: str, diameters, repeats: int) -> None:
    rows = {}
    for diameter_m in diameters:
        with tempfile.TemporaryDirectory() as folder:
            row = {"diameter_m": diameter_m, **case_files_gb(config_path, diameter_m)}
            row.update(child("products", config_path, diameter_m, folder))
            row.update(child("loop", config_path, diameter_m, folder, repeats))
        rows[diameter_m] = row
        print("size " + json.dumps(row), flush=True)
    print(
        "| D [m] | WFS | DM | camera px | ms/step (LTAO, 1 core) | loop peak RSS [GB] | reconstructor [s] | "
        "command matrix [s] | their peak RSS [GB] | frames [GB] | screens [GB] |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for d, r in rows.items():
        print(
            f"| {d:g} | {r['n_subapertures']} | {r['n_actuators']} | {r['camera_pixels']} | {r['ms_per_step']:.2f} | "
            f"{r['loop_peak_gb']:.2f} | {r['reconstructor_s']:.1f} | {r['commands_s']:.1f} | "
            f"{r['products_peak_gb']:.2f} | {r['frames_gb']:.2f} | {r['screens_gb']:.2f} |"
        )
    if len(rows) > 1:
        print_power_laws(list(rows.values()), PROJECTED_DIAMETER_M)
        print(
            f"the study's size estimates at {PROJECTED_DIAMETER_M:g} m: "
            + json.dumps(case_files_gb(config_path, PROJECTED_DIAMETER_M))
        )


SCALED = {
    "ms_per_step": "ms/step",
    "loop_peak_gb": "loop peak RSS [GB]",
    "reconstructor_s": "reconstructor [s]",
    "commands_s": "command matrix [s]",
    "products_peak_gb": "their peak RSS [GB]",
    "frames_gb": "frames [GB]",
    "screens_gb": "screens [GB]",
}
PROJECTED_DIAMETER_M = 39.0
"""The ELT's diameter: the size the power laws are projected to."""


def power_law(diameters_m, values) -> tuple[float, float]:
    """Least-squares fit of log value = log a + b log D: (a, b)."""
    b, log_a = np.polyfit(np.log(diameters_m), np.log(values), 1)
    return float(np.exp(log_a)), float(b)


def print_power_laws(rows: list[dict], projected_m: float) -> None:
    """Each measured quantity's fitted power law a D^b and its value at ``projected_m``."""
    diameters = [r["diameter_m"] for r in rows]
    print(f"| quantity | exponent b (a D^b) | at {projected_m:g} m |")
    print("|---|---|---|")
    for key, label in SCALED.items():
        a, b = power_law(diameters, [r[key] for r in rows])
        print(f"| {label} | {b:.2f} | {a * projected_m**b:.3g} |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="config/config.yaml")
    parser.add_argument("--diameters", type=float, nargs="+", help="telescope diameters [m]: the size benchmark")
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--stage", nargs="+", help=argparse.SUPPRESS)  # a child process of the size benchmark
    args = parser.parse_args()
    if args.stage:
        stage, config_path, diameter, *rest = args.stage
        if stage == "products":
            result = measure_products(config_path, float(diameter), rest[0])
        else:
            result = measure_loop(config_path, float(diameter), rest[0], int(rest[1]))
        print(json.dumps(result))
    elif args.diameters:
        main_sizes(args.config, args.diameters, args.repeats)
    else:
        main(args.config)
