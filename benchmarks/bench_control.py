"""Benchmark: open-loop command-matrix builds (LTAO and GLAO), single thread.

For each WFS + DM pair (8x8 + 9x9, 16x16 + 17x17, 32x32 + 9x9; default WFS:
4.2 m, 0.84"/pixel, 4 pixels, 532 nm; 4 Rayleigh beacons at 22 km on a 40"
circle; the study's 9-layer prior), reports the time of the slope covariance +
Cholesky, of the LTAO and of the GLAO command matrix (sharing the factor), of
the DM slopes matrix, and the peak RSS (each pair in a fresh subprocess).

Run: .venv/bin/python benchmarks/bench_control.py
"""

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from luckyao.ao.control import command_matrix, dm_slopes_matrix  # noqa: E402
from luckyao.ao.dm import DeformableMirror  # noqa: E402
from luckyao.studyspec.case import telescope_from, tomography_from  # noqa: E402
from luckyao.studyspec.study import load_study  # noqa: E402
from luckyao.tomography.reconstructor import factorize  # noqa: E402
from luckyao.tomography.slopes import SlopeGeometry, slope_covariance  # noqa: E402
from luckyao.wfs.beacons import LgsConfig  # noqa: E402
from luckyao.wfs.shack_hartmann import ShackHartmann  # noqa: E402

BASE = load_study(Path(__file__).resolve().parents[1] / "config" / "config.yaml")[1][
    "noao_r0_13.5cm"
]  # the base, resolved
TELESCOPE = telescope_from(BASE["telescope"])
PRIOR = tomography_from(BASE["tomography"]).prior  # the study's default system
NOISE_RAD = tomography_from(BASE["tomography"]).noise_rms_rad
PAIRS = ((8, 9), (16, 17), (32, 9))


def build(n_sub: int, n_act: int) -> None:
    lgs = LgsConfig.rayleigh()
    wfs = ShackHartmann(TELESCOPE, n_sub, lgs.wavelength_m)
    geometry = SlopeGeometry.from_wfs(wfs, lgs)
    dm = DeformableMirror(TELESCOPE, n_act)
    start = time.perf_counter()
    factor = factorize(slope_covariance(PRIOR, geometry, NOISE_RAD))
    factored = time.perf_counter()
    command_matrix(PRIOR, geometry, NOISE_RAD, dm, "ltao", cholesky_lower=factor)
    ltao = time.perf_counter()
    command_matrix(PRIOR, geometry, NOISE_RAD, dm, "glao", cholesky_lower=factor)
    glao = time.perf_counter()
    dm_slopes_matrix(dm, wfs, lgs.n_beacons)
    end = time.perf_counter()
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(
        f"{n_sub}x{n_sub} WFS + {n_act}x{n_act} DM: {geometry.n_slopes} slopes, {dm.n_valid} actuators: "
        f"S+Cholesky {factored - start:.1f} s, LTAO {ltao - factored:.1f} s, GLAO {glao - ltao:.1f} s, "
        f"DM slopes {end - glao:.2f} s, total {end - start:.1f} s, peak RSS {peak_gb:.2f} GB"
    )


if __name__ == "__main__":
    if len(sys.argv) > 1:
        build(int(sys.argv[1]), int(sys.argv[2]))
    else:
        for n_sub, n_act in PAIRS:
            subprocess.run([sys.executable, __file__, str(n_sub), str(n_act)], check=True)
