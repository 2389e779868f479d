"""Benchmark: LGS WFS and tomography cost, single thread.

Reports ms per 2.5 ms simulation step for the WFS stage (4 LGS x 8x8, both
time-steps' images of a 5 ms exposure, elongation and uplink, centroiding;
cost of one exposure / 2), with its stages in ms per exposure (the compiled
kernels of luckyao.wfs.kernels), and for the reconstruction (slopes -> projected,
tilt-removed phase -> rms; one per exposure / 2), then the reconstructor
build times and peak memory for 8x8, 16x16 and 32x32 (each build in a fresh
subprocess so its peak RSS is its own).

Run: .venv/bin/python benchmarks/bench_wfs_tomography.py
"""

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from luckyao.studyspec.case import telescope_from, tomography_from  # noqa: E402
from luckyao.studyspec.study import load_study  # noqa: E402
from luckyao.tomography.criterion import lgs_rms_nm  # noqa: E402
from luckyao.tomography.reconstructor import factorize, pupil_points, target_reconstructor  # noqa: E402
from luckyao.tomography.slopes import SlopeGeometry, slope_covariance  # noqa: E402
from luckyao.wfs import kernels as wk  # noqa: E402
from luckyao.wfs import shack_hartmann as sh  # noqa: E402
from luckyao.wfs.beacons import LgsConfig  # noqa: E402
from luckyao.wfs.centroiders import centroids_rad  # noqa: E402
from luckyao.wfs.sensor import measure_slopes  # noqa: E402

BASE = load_study(Path(__file__).resolve().parents[1] / "config" / "config.yaml")[1][
    "noao_r0_13.5cm"
]  # the base, resolved
TELESCOPE = telescope_from(BASE["telescope"])
PRIOR = tomography_from(BASE["tomography"]).prior  # the study's default system
NOISE_RAD = tomography_from(BASE["tomography"]).noise_rms_rad


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
    geometry = SlopeGeometry.from_wfs(wfs, lgs)
    points = pupil_points(TELESCOPE, wfs.subaperture_m / 2)[2]
    start = time.perf_counter()
    factor = factorize(slope_covariance(PRIOR, geometry, NOISE_RAD))
    middle = time.perf_counter()
    target_reconstructor(PRIOR, geometry, NOISE_RAD, points, cholesky_lower=factor)
    end = time.perf_counter()
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(
        f"build {n_sub}x{n_sub}: {geometry.n_slopes} slopes, {len(points)} target points: "
        f"S+Cholesky {middle - start:.1f} s, target R {end - middle:.1f} s, "
        f"total {end - start:.1f} s, peak RSS {peak_gb:.2f} GB"
    )


def per_step() -> None:
    lgs = LgsConfig.rayleigh()
    wfs = sh.ShackHartmann(TELESCOPE, 8, lgs.wavelength_m)
    elongation = sh.lgs_elongation_otf(wfs, lgs)
    rng = np.random.default_rng(0)
    n = wfs.grid.n_pix
    downlink = rng.normal(0, 2, (2, lgs.n_beacons, n, n)).astype(np.float32)
    uplink = rng.normal(0, 1, (2, lgs.n_beacons) + wfs.launch_grid.xy_m[0].shape).astype(np.float32)
    geometry = SlopeGeometry.from_wfs(wfs, lgs)
    points = pupil_points(TELESCOPE, wfs.subaperture_m / 2)[2]
    rec = target_reconstructor(PRIOR, geometry, NOISE_RAD, points)
    slopes = measure_slopes(wfs, downlink, 500e-9, elongation, uplink)

    t_wfs = best_ms(lambda: measure_slopes(wfs, downlink, 500e-9, elongation, uplink))
    t_images = best_ms(lambda: sh.exposure_images(wfs, downlink, 500e-9, elongation, uplink))
    images = sh.exposure_images(wfs, downlink, 500e-9, elongation, uplink)
    t_rec = best_ms(lambda: lgs_rms_nm(rec, slopes), number=200)
    print(
        f"WFS 4 LGS x 8x8 ({wfs.n_valid} valid, n_s={wfs.samples_per_subaperture}, "
        f"M={wfs.fft_size}): {t_wfs:.2f} ms per 5 ms exposure (images {t_images:.2f}) "
        f"= {t_wfs / 2:.2f} ms per 2.5 ms step"
    )
    # stages of one exposure (private kernels; ms per exposure, all chunks and steps)
    plan = sh._exposure_plan(wfs, lgs.n_beacons, 2)
    ratio = np.float32(500e-9 / wfs.wavelength_m)
    n_chunks, lanes = plan.sources.shape
    n_s, n_fft, n_lags = wfs.samples_per_subaperture, plan.n_fft, plan.n_lags
    n_q, n_pix = plan.q_index.size, wfs.n_pixels

    def buffer(*shape):
        return np.ones(int(np.prod(shape)), np.float32)

    phi, g = buffer(n_s, n_s, lanes), buffer(2, n_fft, n_s, lanes)
    h = buffer(2, n_fft, n_lags, lanes)
    c, el = buffer(2, n_q, n_lags, lanes), buffer(2, n_q, n_lags, lanes)
    weights, pixels = buffer(2, n_pix, n_q + 1, n_lags), buffer(n_pix, n_pix, lanes)
    spot = np.empty_like(plan.point_spot)
    columns = wk._generated("columns", n_fft, n_s, lanes)
    correlate = wk._generated("correlate", n_fft, n_s, lanes, n_lags)
    spectrum = wk._generated("spectrum", n_fft, lanes, n_lags)
    pixel = wk._generated("pixels", lanes, n_lags, n_pix)
    phase, steps = downlink.reshape(-1), 2 * n_chunks
    stages = {
        "uplink OTF": best_ms(lambda: plan.uplink_otf(uplink.reshape(-1), ratio, plan.launch_amp, spot)),
        "phase gather": steps * best_ms(lambda: wk.gather(phase, plan.sources[0], n, n_s, phi)),
        "fields + y DFTs": steps * best_ms(lambda: columns(phi, ratio, plan.amp[0], g)),
        "x autocorrelation": steps * best_ms(lambda: correlate(g, h, True)),
        "ky DFTs": n_chunks * best_ms(lambda: spectrum(h, c)),
        "OTF x pixels": n_chunks * best_ms(lambda: pixel(c, el, weights, pixels)),
        "centroids + tilt": best_ms(lambda: centroids_rad(wfs, images, remove_tilt=True)),
    }
    stages["driver + Python"] = t_wfs - sum(stages.values())
    print("  ms per exposure: " + ", ".join(f"{name} {t:.3f}" for name, t in stages.items()))
    print(
        f"reconstruction + rms ({rec.shape[0]} points x {rec.shape[1]} slopes): "
        f"{t_rec:.3f} ms per exposure = {t_rec / 2:.3f} ms per step"
    )
    print(f"WFS + reconstruction: {(t_wfs + t_rec) / 2:.2f} ms per step")


if __name__ == "__main__":
    if len(sys.argv) > 1:
        build(int(sys.argv[1]))
    else:
        per_step()
        for order in (8, 16, 32):
            subprocess.run([sys.executable, __file__, str(order)], check=True)
