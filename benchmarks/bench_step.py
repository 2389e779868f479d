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
from luckyao.jobs.resources import (  # noqa: E402
    commands_bytes,
    frames_bytes,
    machine_memory_bytes,
    reconstructor_bytes,
    reconstructor_memory_bytes,
    screens_bytes,
)
from luckyao.layer_tomography.correction import LayerCorrection, LayerEstimator  # noqa: E402
from luckyao.optics.imaging import Imager  # noqa: E402
from luckyao.optics.propagation import Propagator  # noqa: E402
from luckyao.optics.pupil import TiltRemover  # noqa: E402
from luckyao.steps.calibration import build_calibration  # noqa: E402
from luckyao.steps.lgs_slopes import lgs_sensor  # noqa: E402
from luckyao.steps.reconstructor import build_commands, build_reconstructors  # noqa: E402
from luckyao.steps.screens import read_screens, write_screens  # noqa: E402
from luckyao.steps.simulation import TimeLoop, lgs_chain  # noqa: E402
from luckyao.studyspec.case import Case  # noqa: E402
from luckyao.studyspec.products import calibration_spec, commands_spec, reconstructor_spec, turbulence_spec  # noqa: E402
from luckyao.studyspec.schema import deep_merge  # noqa: E402
from luckyao.studyspec.study import load_study, read_study, validate_study  # noqa: E402
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


STAGES = (
    "LGS propagation",
    "WFS",
    "tomography",
    "DM commands + residual",
    "science propagation",
    "DM surface",
    "science image",
    "truth rms",
    "frame",
)
"""The stages of a step, timed one by one (:func:`stages`)."""


def stages(case: Case, screens, reconstructors, commands, calibration, n_steps: int = N_STEPS) -> tuple[dict, list]:
    """Seconds spent per stage (:data:`STAGES`) over ``n_steps`` steps of the case's AO chain (after
    a first frame, the FFT plans and the compilation), and the PCG iterations of each exposure
    (empty for the dense reconstructors). ``tomography``: the open-loop estimate and each target's
    ``lgs_rms`` (dense: the reconstructors' products; ``tomography.method: iterative``: the
    warm-started layer estimate and its lines of sight); ``DM commands + residual``: the commands
    and the pseudo-closed-loop ``lgs_residual_rms``."""
    imager = Imager(case.telescope, case.camera)
    propagator = Propagator(list(case.layers), screens, list(case.targets), imager.grid, mask=imager.mask)
    tilt = TiltRemover.for_mask(imager.grid, imager.mask)
    to_camera = np.float32(REFERENCE_WAVELENGTH_M / case.camera.wavelength_m)
    for step in range(8):  # warm up: JIT, FFT plans
        imager.intensity(propagator.sample_valid([step], case.layer_scales([step]))[0] * to_camera)
    surface = case.ao.deformable_mirror(case.telescope).grid_surface(imager.grid, imager.mask)
    clock = case.clock
    e, spf = clock.exposure_steps, clock.steps_per_frame
    timing = (e, case.ao.delay_steps, spf)
    if case.tomography.iterative:
        sensor, estimator = lgs_sensor(case, screens, 1, calibration), LayerEstimator.for_case(case)
        correction = LayerCorrection(estimator.projection, surface, *timing)
    else:
        sensor, estimator = lgs_chain(case, screens, reconstructors, 1, calibration)
        correction = OpenLoopCorrection(*commands, surface, *timing)
    spent = dict.fromkeys(STAGES, 0.0)
    intensity = np.zeros((len(case.targets), imager.fft_size, imager.fft_size), dtype=np.float32)
    n_frames = n_steps // spf
    for frame in range(n_frames + 1):  # the first frame warms up (compilation, a cold solve): not timed
        steps = clock.steps(frame)
        layer_scales = case.layer_scales(steps)
        lap = dict.fromkeys(STAGES, 0.0)
        slopes = []
        for i in clock.exposure_offsets():
            t0 = time.perf_counter()
            sensor.sample(steps[i : i + e], layer_scales[i : i + e])
            t1 = time.perf_counter()
            slopes.append(sensor.slopes())
            lap["LGS propagation"] += t1 - t0
            lap["WFS"] += time.perf_counter() - t1
        t0 = time.perf_counter()
        slopes = np.stack(slopes)
        estimates = estimator.estimate(slopes)
        estimator.rms_nm(estimates)
        t1 = time.perf_counter()
        starts = clock.exposure_starts(steps)
        for start, estimate in zip(starts, estimates):
            correction.measure(int(start), estimate)
        correction.residual_rms_nm(starts, estimates, estimator)
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
        for name, dt in zip(STAGES[2:], (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5, t7 - t6)):
            lap[name] += dt
        if frame > 0:
            for name, dt in lap.items():
                spent[name] += dt
    iterations = list(estimator.tomography.iterations[e:]) if case.tomography.iterative else []
    return spent, iterations


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
        spent, _ = stages(default, screens, *built[DEFAULT_CASE])
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


ELT_OVERLAY, ELT_CASE = str(Path(__file__).resolve().parents[1] / "config" / "elt.yaml"), "ltao_sodium_D39m"
"""The system of ``--system elt``: the 39 m overlay's LTAO case, scaled to each diameter."""
ELT_DIAMETER_M = 39.0


def sized_study(
    config_path: str, diameter_m: float, system: str = "default", method: str = "dense"
) -> tuple[dict, dict]:
    """The study and its AO case at ``diameter_m`` (size-dependent keys derived): ``system``
    ``default``, the default AO case (4 Rayleigh LGS at 22 km) with the tomography ``method``;
    ``elt``, config/elt.yaml's LTAO case (6 sodium LGS, side launch, 12" WFS field, 2" camera,
    iterative tomography), its obscuration at the same ratio and its launch the same distance
    beyond the aperture's edge."""
    overlays = [ELT_OVERLAY] if system == "elt" else []
    study, cases = load_study(config_path, *overlays)
    sweep = dict(study["lucky"]["detector_sweep"], cases=[])  # the study's sweep cases are not here
    if system == "elt":
        written = read_study(config_path, ELT_OVERLAY)["cases"][ELT_CASE]
        scale = diameter_m / ELT_DIAMETER_M
        lgs = cases[ELT_CASE]["lgs"]
        edge_m = lgs["launch_x_m"] - ELT_DIAMETER_M / 2
        case = deep_merge(
            written,
            {
                "telescope": {
                    "diameter_m": diameter_m,
                    "obscuration_m": round(scale * written["telescope"]["obscuration_m"], 3),
                },
                "lgs": {"launch_x_m": diameter_m / 2 + edge_m},
            },
        )
    else:
        case = {"telescope": {"diameter_m": diameter_m}, "ao": {"mode": "ltao"}, "tomography": {"method": method}}
    sized = dict(
        study,
        cases={"sized": case},
        figures={},
        sweeps={},
        lucky=dict(study["lucky"], detector_sweep=sweep),
    )
    return study, validate_study(sized)["sized"]


def measure_products(
    config_path: str, diameter_m: float, folder: str, system: str, method: str, draws: int = CALIBRATION_DRAWS
) -> dict:
    """Build the reconstructor, then the command matrix (each timed, with the peak RSS after it;
    none with the iterative tomography), and save them with the case's WFS calibration (``draws``
    draws, timed) to ``folder`` for the loop."""
    study, config = sized_study(config_path, diameter_m, system, method)
    out = {"reconstructor_s": None, "reconstructor_peak_gb": None, "commands_s": None}
    if reconstructor_spec(config) is not None:
        start = time.perf_counter()
        reconstructors = build_reconstructors(reconstructor_spec(config))["reconstructor"].values
        built = time.perf_counter()
        out = {"reconstructor_s": built - start, "reconstructor_peak_gb": peak_rss_gb()}
        commands = build_commands(commands_spec(config))
        out["commands_s"] = time.perf_counter() - built
        np.save(Path(folder) / "reconstructors.npy", reconstructors)
        np.save(Path(folder) / "command_matrix.npy", commands["command_matrix"].values)
        np.save(Path(folder) / "dm_slopes.npy", commands["dm_slopes"].values)
    spec = calibration_spec(study, deep_merge(config, {"wfs": {"calibration_draws": int(draws)}}))
    out.update(calibration_s=None, calibration_draws=0)
    if spec is not None:  # none for a geometric WFS (wfs.model)
        start = time.perf_counter()
        calibration = build_calibration(spec)
        out.update(calibration_s=time.perf_counter() - start, calibration_draws=int(draws))
        calibration.to_netcdf(Path(folder) / "calibration.nc")
    out["products_peak_gb"] = peak_rss_gb()
    return out


def measure_loop(
    config_path: str, diameter_m: float, folder: str, repeats: int, system: str, method: str, n_steps: int
) -> dict:
    """Each stage's ms per step over ``n_steps`` (:func:`stages`), the PCG iterations per exposure
    (iterative), then the whole time loop's ms per step (median of ``repeats``; none if 0), and the
    peak RSS."""
    import xarray as xr

    study, config = sized_study(config_path, diameter_m, system, method)
    steps_per_frame = Case.from_config(config).steps_per_frame
    # the stages' frames and a warm-up frame; the whole loop's 4 frames more than its warm-up
    config = dict(config, duration_s=(n_steps + 8 * steps_per_frame) * config["time_step_s"])
    spec = dict(turbulence_spec(study, config), duration_s=config["duration_s"] + 0.1)
    start = time.perf_counter()
    write_screens(spec, Path(folder) / "s.npy", Path(folder) / "s.nc", {})
    out = {"screens_s": time.perf_counter() - start}
    screens = read_screens(Path(folder) / "s.npy", Path(folder) / "s.nc")
    np.asarray(screens.flat).sum()  # page the memory-mapped screens in
    dense = (Path(folder) / "reconstructors.npy").exists()
    products_ = (
        np.load(Path(folder) / "reconstructors.npy") if dense else None,
        (np.load(Path(folder) / "command_matrix.npy"), np.load(Path(folder) / "dm_slopes.npy")) if dense else None,
        xr.load_dataset(Path(folder) / "calibration.nc") if (Path(folder) / "calibration.nc").exists() else None,
    )
    case = Case.from_config(config)
    wall, cpu = time.perf_counter(), time.process_time()
    spent, iterations = stages(case, screens, *products_, n_steps=n_steps)
    # this process's share of a core while timed (below 1 on a loaded machine: the stages' wall
    # times then overstate one core's)
    out["stages_cpu_share"] = (time.process_time() - cpu) / (time.perf_counter() - wall)
    out["stage_ms"] = {name: 1e3 * seconds / n_steps for name, seconds in spent.items()}
    out["stages_ms_per_step"] = sum(out["stage_ms"].values())
    out["pcg_iterations_per_exposure"] = float(np.mean(iterations)) if iterations else None
    out["stages_peak_gb"] = peak_rss_gb()
    runs = [whole_loop_ms(case, screens, *products_) for _ in range(repeats)]
    out.update(ms_per_step=float(np.median(runs)) if runs else None, ms_per_step_runs=runs, loop_peak_gb=peak_rss_gb())
    return out


def case_files_gb(config_path: str, diameter_m: float, system: str = "default", method: str = "dense") -> dict:
    """The files of the case at the study's duration (the study's estimates) [GB]: no reconstructor
    or command matrix with the iterative tomography."""
    study, config = sized_study(config_path, diameter_m, system, method)
    dense = reconstructor_spec(config) is not None
    return {
        "frames_gb": frames_bytes(config) / 1e9,
        "frames_s": config["duration_s"],
        "screens_gb": screens_bytes(turbulence_spec(study, config)) / 1e9,
        "reconstructor_gb": reconstructor_bytes(reconstructor_spec(config)) / 1e9 if dense else None,
        "commands_gb": commands_bytes(commands_spec(config)) / 1e9 if dense else None,
        "n_subapertures": config["wfs"]["n_subapertures"],
        "n_actuators": config["ao"]["n_actuators"],
        "camera_pixels": config["camera"]["n_pixels"],
        "method": config["tomography"].get("method", "dense"),
    }


def child(stage: str, *args) -> dict:
    """Run one stage in a fresh process (its own peak memory); its last stdout line is JSON."""
    done = subprocess.run(
        [sys.executable, __file__, "--stage", stage, *map(str, args)], check=True, capture_output=True, text=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main_sizes(
    config_path: str, diameters, repeats: int, system: str, method: str, n_steps: int, draws: int = CALIBRATION_DRAWS
) -> None:
    rows = {}
    for diameter_m in diameters:
        study, config = sized_study(config_path, diameter_m, system, method)
        spec = reconstructor_spec(config)
        if spec is not None and reconstructor_memory_bytes(spec) > machine_memory_bytes():
            sys.exit(
                f"bench_step: the dense reconstructor at {diameter_m:g} m needs about "
                f"{reconstructor_memory_bytes(spec) / 1e9:.0f} GB, more than this machine's "
                f"{machine_memory_bytes() / 1e9:.0f} GB: --method iterative (or --system elt)"
            )
        with tempfile.TemporaryDirectory() as folder:
            row = {"diameter_m": diameter_m, **case_files_gb(config_path, diameter_m, system, method)}
            row.update(child("products", config_path, diameter_m, folder, system, method, draws))
            row.update(child("loop", config_path, diameter_m, folder, repeats, system, method, n_steps))
        rows[diameter_m] = row
        print("size " + json.dumps(row), flush=True)
    print(f"system {system}, {n_steps} steps per stage timing, single thread")
    print("share of a core while timed: " + ", ".join(f"{d:g} m {r['stages_cpu_share']:.2f}" for d, r in rows.items()))
    print(
        "| D [m] | WFS | DM | camera px | tomography | "
        + " | ".join(STAGES)
        + " | stages [ms/step] | whole loop [ms/step] | PCG iterations per exposure | loop peak RSS [GB] |"
    )
    print("|---" * (9 + len(STAGES)) + "|")
    for d, r in rows.items():
        print(
            f"| {d:g} | {r['n_subapertures']} | {r['n_actuators']} | {r['camera_pixels']} | {r['method']} | "
            + " | ".join(f"{r['stage_ms'][name]:.2f}" for name in STAGES)
            + f" | {r['stages_ms_per_step']:.2f} | {_value(r['ms_per_step'], '.2f')} | "
            f"{_value(r['pcg_iterations_per_exposure'], '.1f')} | {r['loop_peak_gb']:.2f} |"
        )
    print(
        "| D [m] | screens made [s] | WFS calibration [s] (draws) | reconstructor [s] | command matrix [s] | "
        "products' peak RSS [GB] | frames [GB] | screens [GB] |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for d, r in rows.items():
        print(
            f"| {d:g} | {r['screens_s']:.1f} | {_value(r['calibration_s'], '.1f')} ({r['calibration_draws']}) | "
            f"{_value(r['reconstructor_s'], '.1f')} | "
            f"{_value(r['commands_s'], '.1f')} | {r['products_peak_gb']:.2f} | {r['frames_gb']:.2f} "
            f"({r['frames_s']:g} s) | {r['screens_gb']:.2f} |"
        )
    if len(rows) > 1 and PROJECTED_DIAMETER_M not in rows:
        print_power_laws(list(rows.values()), PROJECTED_DIAMETER_M)


def _value(value, spec: str) -> str:
    """``value`` formatted, or a dash for None (not measured: no dense product, no whole loop)."""
    return "-" if value is None else format(value, spec)


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
    print(f"| quantity | exponent b (a D^b) | at {projected_m:g} m |")
    print("|---|---|---|")
    for key, label in SCALED.items():
        measured = [r for r in rows if r.get(key) is not None]
        if len(measured) < 2:
            continue
        a, b = power_law([r["diameter_m"] for r in measured], [r[key] for r in measured])
        print(f"| {label} | {b:.2f} | {a * projected_m**b:.3g} |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config", nargs="?", default="config/config.yaml")
    parser.add_argument("--diameters", type=float, nargs="+", help="telescope diameters [m]: the size benchmark")
    parser.add_argument("--repeats", type=int, default=REPEATS, help="whole-loop runs per size (0: none)")
    parser.add_argument(
        "--system",
        choices=["default", "elt"],
        default="default",
        help="the size benchmark's case: the default AO case, or config/elt.yaml's LTAO case scaled",
    )
    parser.add_argument(
        "--method", choices=["dense", "iterative"], default="dense", help="the default system's tomography"
    )
    parser.add_argument("--steps", type=int, default=N_STEPS, help="steps of the size benchmark's stage timing")
    parser.add_argument(
        "--calibration-draws", type=int, default=CALIBRATION_DRAWS, help="the size benchmark's WFS calibration draws"
    )
    parser.add_argument("--stage", nargs="+", help=argparse.SUPPRESS)  # a child process of the size benchmark
    args = parser.parse_args()
    if args.stage:
        stage, config_path, diameter, folder, *rest = args.stage
        if stage == "products":
            result = measure_products(config_path, float(diameter), folder, *rest)
        else:
            repeats, system, method, n_steps = rest
            result = measure_loop(config_path, float(diameter), folder, int(repeats), system, method, int(n_steps))
        print(json.dumps(result))
    elif args.diameters:
        main_sizes(
            args.config, args.diameters, args.repeats, args.system, args.method, args.steps, args.calibration_draws
        )
    else:
        main(args.config)
