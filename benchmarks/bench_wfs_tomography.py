"""Benchmark: LGS WFS and tomography cost, single thread.

Reports ms per 2.5 ms simulation step for the WFS stage (4 LGS x 8x8, both
time-steps' images of a 5 ms exposure, elongation and uplink, centroiding;
cost of one exposure / 2) and for the reconstruction (slopes -> projected,
tilt-removed phase -> rms; one per exposure / 2), then the reconstructor
build times and peak memory for 8x8, 16x16 and 32x32 (each build in a fresh
subprocess so its peak RSS is its own).

Run: .venv/bin/python benchmarks/bench_wfs_tomography.py
"""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_name] = "1"

import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from luckyao.lgs import LgsConfig  # noqa: E402
from luckyao.pupil import Telescope  # noqa: E402
from luckyao import tomography as tomo  # noqa: E402
from luckyao import wfs as sh  # noqa: E402
from luckyao.units import ARCSEC_RAD  # noqa: E402

TELESCOPE = Telescope(4.2, 1.2)
PRIOR = tomo.TurbulencePrior(
    0.135, 20.0, (47, 140, 281, 562, 1125, 2250, 4500, 9000, 18000),
    (0.5224, 0.0260, 0.0444, 0.1160, 0.0989, 0.0295, 0.0598, 0.0430, 0.0600))
NOISE_RAD = 0.02 * ARCSEC_RAD


def best_ms(function, repeat=7, number=20):
    function()
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            function()
        best = min(best, (time.perf_counter() - start) / number)
    return best * 1e3


def build(n_sub: int) -> None:
    lgs = LgsConfig.rayleigh()
    wfs = sh.ShackHartmann(TELESCOPE, n_sub, lgs.wavelength_m)
    geometry = tomo.SlopeGeometry.from_wfs(wfs, lgs)
    points = tomo.pupil_points(TELESCOPE, wfs.subaperture_m / 2)[2]
    start = time.perf_counter()
    factor = tomo.factorize(tomo.slope_covariance(PRIOR, geometry, NOISE_RAD))
    middle = time.perf_counter()
    tomo.target_reconstructor(PRIOR, geometry, NOISE_RAD, points, cholesky_lower=factor)
    end = time.perf_counter()
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"build {n_sub}x{n_sub}: {geometry.n_slopes} slopes, {len(points)} target points: "
          f"S+Cholesky {middle - start:.1f} s, target R {end - middle:.1f} s, "
          f"total {end - start:.1f} s, peak RSS {peak_gb:.2f} GB")


def per_step() -> None:
    lgs = LgsConfig.rayleigh()
    wfs = sh.ShackHartmann(TELESCOPE, 8, lgs.wavelength_m)
    elongation = sh.lgs_elongation_otf(wfs, lgs)
    rng = np.random.default_rng(0)
    n = wfs.grid.n_pix
    downlink = rng.normal(0, 2, (2, lgs.n_beacons, n, n)).astype(np.float32)
    uplink = rng.normal(0, 1, (2, lgs.n_beacons) + wfs.launch_grid.xy_m[0].shape).astype(np.float32)
    geometry = tomo.SlopeGeometry.from_wfs(wfs, lgs)
    points = tomo.pupil_points(TELESCOPE, wfs.subaperture_m / 2)[2]
    rec = tomo.target_reconstructor(PRIOR, geometry, NOISE_RAD, points)
    slopes = sh.measure_slopes(wfs, downlink, 500e-9, elongation, uplink)

    t_wfs = best_ms(lambda: sh.measure_slopes(wfs, downlink, 500e-9, elongation, uplink))
    t_images = best_ms(lambda: sh.exposure_images(wfs, downlink, 500e-9, elongation, uplink))
    t_rec = best_ms(lambda: tomo.lgs_rms_nm(rec, slopes), number=200)
    print(f"WFS 4 LGS x 8x8 ({wfs.n_valid} valid, n_s={wfs.samples_per_subaperture}, "
          f"M={wfs.fft_size}): {t_wfs:.2f} ms per 5 ms exposure (images {t_images:.2f}) "
          f"= {t_wfs / 2:.2f} ms per 2.5 ms step")
    # sub-stages of exposure_images (private helpers; ms per 2.5 ms step)
    plan = sh._exposure_plan(wfs, lgs.n_beacons)
    down = plan.down
    ratio = 500e-9 / wfs.wavelength_m
    cos_p, sin_p = down.trig(downlink, ratio)
    kernel = sh._lane_kernels(down.n_fft, down.n_in, down.lanes)
    half = down.n_fft // 2
    out = np.empty(down.n_fft * down.n_chunks * half * down.lanes, np.complex64)
    spot = np.ones(lgs.n_beacons * down.n_fft * half, np.complex64)
    t_trig = best_ms(lambda: down.trig(downlink, ratio))
    t_up = best_ms(lambda: sh._exposure_uplink_otf(wfs, plan, uplink, ratio))
    t_fft = best_ms(lambda: kernel.spectra(cos_p, sin_p, down.amp.reshape(-1), 2, down.n_chunks,
                                           plan.no_elongation.reshape(-1), spot, out))
    images = sh.exposure_images(wfs, downlink, 500e-9, elongation, uplink)
    t_cog = best_ms(lambda: sh.remove_tip_tilt(sh.centroids_rad(wfs, images)), number=200)
    t_rest = t_wfs - t_trig - t_up - t_fft - t_cog
    print(f"  per step: phase gather + cos/sin {t_trig / 2:.3f}, uplink OTF {t_up / 2:.3f}, "
          f"downlink FFTs + |.|^2 + spectrum x OTF {t_fft / 2:.3f}, centroids {t_cog / 2:.3f}, "
          f"pixel integration + rest {t_rest / 2:.3f} ms")
    print(f"reconstruction + rms ({rec.shape[0]} points x {rec.shape[1]} slopes): "
          f"{t_rec:.3f} ms per exposure = {t_rec / 2:.3f} ms per step")
    print(f"WFS + reconstruction: {(t_wfs + t_rec) / 2:.2f} ms per step")


if __name__ == "__main__":
    if len(sys.argv) > 1:
        build(int(sys.argv[1]))
    else:
        per_step()
        for order in (8, 16, 32):
            subprocess.run([sys.executable, __file__, str(order)], check=True)
