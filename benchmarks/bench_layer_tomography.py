"""Benchmark: the layer-space tomography (luckyao.layer_tomography), one thread.

Per system: set-up time (grids, operators, prior, FDPCG, DM and line-of-sight projections), the
per-exposure solve (right-hand side + warm-started PCG to the default tolerances) and projection
(DM commands + the on-axis lgs_rms) times, PCG iterations per exposure, the projected on-axis path's
rms difference from a tightly converged solve (rtol 1e-6), and the peak memory (each system in a
fresh subprocess, so its peak RSS is its own).

Systems: 4.2 and 8.2 m as the default study (4 Rayleigh LGS at 22 km on a 40" circle, the 9-layer
prior, 0.525 m sub-apertures, Fried DM); 16 and 39 m with six sodium LGS at 90 km on a ring of
34" radius (the ring of the ELT's LTAO instrument; docs/methods/layer-tomography.md). Slopes are
synthetic: the measurement operator applied to von Karman layers on the prior's profile, frozen flow
at 10 m/s (a fraction of a sample per 5 ms exposure), plus white noise of the prior's rms.

Run: .venv/bin/python benchmarks/bench_layer_tomography.py [--diameters 4.2 8.2 16 39] [--exposures 20]
[--warm-rtol 1e-3] ("ms_per_iteration": the solve over the warm iterations, right-hand side included)
"""

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from luckyao.ao.dm import DeformableMirror  # noqa: E402
from luckyao.layer_tomography.assembly import DEFAULT_WARM_RTOL, build_tomography  # noqa: E402
from luckyao.layer_tomography.prior import von_karman_psd_m2  # noqa: E402
from luckyao.layer_tomography.projection import DmProjection, LineOfSight  # noqa: E402
from luckyao.layer_tomography.solver import pcg  # noqa: E402
from luckyao.optics.pupil import Telescope  # noqa: E402
from luckyao.studyspec.case import tomography_from  # noqa: E402
from luckyao.studyspec.study import load_study  # noqa: E402
from luckyao.tomography.reconstructor import reconstruction_points  # noqa: E402
from luckyao.wfs.beacons import LgsConfig  # noqa: E402
from luckyao.wfs.shack_hartmann import ShackHartmann  # noqa: E402

BASE = load_study(Path(__file__).resolve().parents[1] / "config" / "config.yaml")[1]["ltao_r0_13.5cm"]
TOMOGRAPHY = tomography_from(BASE["tomography"])
PITCH_M = 0.525
OBSCURATION_RATIO = 2 / 7
SODIUM = dict(height_m=90e3, wavelength_m=589e-9, profile="gaussian", profile_width_m=10e3)
WIND_M_S, EXPOSURE_S = 10.0, 5e-3


def lgs_for(diameter_m: float) -> LgsConfig:
    if diameter_m <= 8.2:
        return LgsConfig.rayleigh()
    return LgsConfig(n_beacons=6, asterism_diameter_arcsec=68.0, **SODIUM)


def true_layers(tomo, rng) -> np.ndarray:
    """Von Karman layers (n_layers, n, n) [m] of the prior's profile on the layer grids (FFT screens)."""
    grids, prior = tomo.operator.grids, tomo.prior.prior
    k = np.fft.fftfreq(grids.n)
    k2 = k[:, None] ** 2 + k[None, :] ** 2
    layers = np.empty(grids.shape)
    for layer, (pitch, fraction) in enumerate(zip(grids.pitches_m, prior.cn2_fractions)):
        psd = von_karman_psd_m2(np.sqrt(k2) / pitch, prior.r0_m, prior.outer_scale_m, prior.wavelength_m) * fraction
        noise = rng.normal(size=k2.shape) + 1j * rng.normal(size=k2.shape)
        layers[layer] = np.fft.ifft2(noise * np.sqrt(psd) / pitch).real * grids.n
    return layers


def shifted(layers, tomo, seconds: float) -> np.ndarray:
    """The layers moved by the wind along +x for ``seconds`` (Fourier shift)."""
    k = np.fft.fftfreq(tomo.operator.grids.n)
    out = np.empty_like(layers)
    for layer, pitch in enumerate(tomo.operator.grids.pitches_m):
        ramp = np.exp(-2j * np.pi * k[None, :] * WIND_M_S * seconds / pitch)
        out[layer] = np.fft.ifft2(np.fft.fft2(layers[layer]) * ramp).real
    return out


def run(diameter_m: float, n_exposures: int, warm_rtol: float) -> dict:
    start = time.perf_counter()
    telescope = Telescope(diameter_m, round(OBSCURATION_RATIO * diameter_m, 3))
    n_sub = int(round(diameter_m / PITCH_M))
    lgs = lgs_for(diameter_m)
    wfs = ShackHartmann(telescope, n_sub, lgs.wavelength_m)
    tomo = build_tomography(
        TOMOGRAPHY.prior, wfs, lgs.directions_rad, lgs.height_m, TOMOGRAPHY.noise_rms_rad, warm_rtol=warm_rtol
    )
    dm = DeformableMirror(telescope, n_sub + 1)
    projection = DmProjection.build(tomo.operator.grids, dm, "ltao")
    points = reconstruction_points(telescope, wfs.subaperture_m, TOMOGRAPHY.points_per_subaperture)
    on_axis = LineOfSight.build(tomo.operator.grids, points)
    setup_s = time.perf_counter() - start
    rng = np.random.default_rng(1)
    truth = true_layers(tomo, rng)
    solve_s, project_s = [], []
    for e in range(n_exposures):
        slopes = tomo.operator.forward(shifted(truth, tomo, e * EXPOSURE_S))
        slopes += TOMOGRAPHY.noise_rms_rad * rng.normal(size=slopes.shape)
        t0 = time.perf_counter()
        layers = tomo.estimate(slopes)
        t1 = time.perf_counter()
        projection.commands(layers)
        on_axis.rms_nm(layers)
        project_s.append(time.perf_counter() - t1)
        solve_s.append(t1 - t0)
    b = tomo.right_hand_side(slopes)
    converged = pcg(tomo.normal, b, layers, tomo.preconditioner.apply, 1e-6, 2000).solution
    reference = on_axis.path_m(converged)
    accuracy = float(np.sqrt(np.mean((on_axis.path_m(layers) - reference) ** 2) / np.mean(reference**2)))
    warm = slice(min(3, n_exposures - 1), None)  # after the cold start
    return {
        "diameter_m": diameter_m,
        "beacons": f"{lgs.n_beacons} x {lgs.height_m / 1e3:g} km",
        "subapertures": f"{n_sub}x{n_sub} ({wfs.n_valid} valid)",
        "slopes": tomo.operator.n_slopes,
        "unknowns": tomo.operator.grids.size,
        "grid": f"{tomo.prior.prior.heights_m.__len__()} x {tomo.operator.grids.n}^2",
        "actuators": dm.n_valid,
        "setup_s": round(setup_s, 2),
        "solve_ms": round(1e3 * float(np.median(solve_s[warm])), 1),
        "project_ms": round(1e3 * float(np.median(project_s[warm])), 1),
        "iterations_cold": tomo.iterations[0],
        "iterations_warm": round(float(np.mean(tomo.iterations[warm])), 1),
        "ms_per_iteration": round(1e3 * float(np.median(solve_s[warm])) / float(np.mean(tomo.iterations[warm])), 2),
        "on_axis_vs_converged": round(accuracy, 4),
        "peak_rss_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--diameters", type=float, nargs="+", default=[4.2, 8.2, 16.0, 39.0])
    parser.add_argument("--exposures", type=int, default=20)
    parser.add_argument("--warm-rtol", type=float, default=DEFAULT_WARM_RTOL, help="the warm-started PCG's rtol")
    parser.add_argument("--one", type=float, help=argparse.SUPPRESS)  # the child process
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(run(args.one, args.exposures, args.warm_rtol)))
        return
    for diameter in args.diameters:
        out = subprocess.run(
            [sys.executable, __file__, "--one", str(diameter), "--exposures", str(args.exposures)]
            + ["--warm-rtol", str(args.warm_rtol)],
            capture_output=True,
            text=True,
            check=True,
        )
        print(out.stdout.strip().splitlines()[-1], flush=True)


if __name__ == "__main__":
    main()
