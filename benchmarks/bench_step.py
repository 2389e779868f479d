"""Benchmark: ms per simulated 2.5 ms step, by stage, for the default on-axis case.

Single thread. Uses the base system of config/config.yaml (no AO; 4 Rayleigh LGS
with 8x8 open-loop Shack-Hartmann WFS, tomography and the lgs_rms criterion)
with screens for a short stretch of time (the per-step cost does not depend on
the duration). Prints ``ms_per_step_camera <number>`` (propagation + science
image + truth: the no-LGS pipeline) and, last, ``ms_per_step <number>``: the
whole pipeline of the default case.

Run: .venv/bin/python benchmarks/bench_step.py [config.yaml]
"""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_name] = "1"

import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from luckyao.config import load_study, reconstructor_spec, turbulence_spec  # noqa: E402
from luckyao.imaging import Imager  # noqa: E402
from luckyao.propagation import Propagator  # noqa: E402
from luckyao.reconstructor import build_reconstructors  # noqa: E402
from luckyao.sensing import LgsSensing  # noqa: E402
from luckyao.pupil import TiltRemover  # noqa: E402
from luckyao.simulate import System  # noqa: E402
from luckyao.turbulence import read_screens, write_screens  # noqa: E402
from luckyao.units import REFERENCE_WAVELENGTH_M  # noqa: E402

N_STEPS = 800


def main(config_path="config/config.yaml"):
    study, _ = load_study(config_path)
    case = dict(study["base"], duration_s=1.0)
    spec = dict(turbulence_spec(study, case), duration_s=N_STEPS * case["time_step_s"] + 0.1)
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        write_screens(spec, Path(tmp) / "s.npy", Path(tmp) / "s.nc", {})
        print(f"screens for {spec['duration_s']:.1f} s: {time.perf_counter() - start:.1f} s")
        screens = read_screens(Path(tmp) / "s.npy", Path(tmp) / "s.nc")
        system = System.from_config(case)
        imager = Imager(system.telescope, system.camera)
        propagator = Propagator(list(system.layers), screens, list(system.targets), imager.grid,
                                mask=imager.mask)
        tilt = TiltRemover.for_mask(imager.grid, imager.mask)
        to_camera = np.float32(REFERENCE_WAVELENGTH_M / system.camera.wavelength_m)
        np.asarray(screens.flat).sum()  # page the memory-mapped screens in
        for step in range(8):  # warm up: JIT, FFT plans
            imager.intensity(propagator.sample_valid([step], system.layer_scales([step]))[0] * to_camera)
        start = time.perf_counter()
        reconstructors = build_reconstructors(reconstructor_spec(case))["reconstructor"].values
        print(f"reconstructor ({case['wfs']['n_subapertures']}x{case['wfs']['n_subapertures']}): "
              f"{time.perf_counter() - start:.1f} s")
        sensing = LgsSensing(case, list(system.layers), screens, reconstructors, seed=1)
        exposure = sensing.exposure_steps
        sensing.rms_nm(sensing.exposure_slopes(np.arange(exposure), system.layer_scales(np.arange(exposure))))
        camera = ["propagation", "science image", "truth rms", "frame"]
        stages = dict.fromkeys(camera + ["LGS propagation", "WFS", "reconstruction"], 0.0)
        intensity = np.zeros((len(system.targets), imager.fft_size, imager.fft_size), dtype=np.float32)
        spf = system.steps_per_frame
        for frame in range(N_STEPS // spf):
            steps = frame * spf + np.arange(spf)
            layer_scales = system.layer_scales(steps)
            t0 = time.perf_counter()
            phases = propagator.sample_valid(steps, layer_scales)
            t1 = time.perf_counter()
            for phase in phases:
                imager.accumulate(phase * to_camera, intensity)
            t2 = time.perf_counter()
            for phase in phases:
                tilt.rms(phase)
            t3 = time.perf_counter()
            imager.to_pixels(intensity / spf)
            intensity.fill(0.0)
            t4 = time.perf_counter()
            slopes = []
            for i in range(0, spf, exposure):
                t5 = time.perf_counter()
                sensing.sample(steps[i:i + exposure], layer_scales[i:i + exposure])
                t6 = time.perf_counter()
                slopes.append(sensing.slopes())
                stages["LGS propagation"] += t6 - t5
                stages["WFS"] += time.perf_counter() - t6
            t7 = time.perf_counter()
            sensing.rms_nm(np.stack(slopes))  # the frame's exposures
            stages["reconstruction"] += time.perf_counter() - t7
            for name, dt in zip(camera, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                stages[name] += dt
    print(f"pupil {imager.grid.n_pix}^2 samples ({imager.n_valid} in the pupil), FFT {imager.fft_size}^2, "
          f"{len(system.layers)} layers, {N_STEPS} steps, single thread")
    for name, total in stages.items():
        print(f"{name:>16s}: {1e3 * total / N_STEPS:.3f} ms per step")
    print(f"ms_per_step_camera {1e3 * sum(stages[name] for name in camera) / N_STEPS:.3f}")
    print(f"ms_per_step {1e3 * sum(stages.values()) / N_STEPS:.3f}")


if __name__ == "__main__":
    main(*sys.argv[1:])
