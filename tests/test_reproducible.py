"""Same config and seed give the same numbers; another seed gives others; nor do they depend on
whether numba compiled the kernels in this process or loaded them from its cache."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from luckyao.atmosphere.screens import ScreenSet, strip_screen
from luckyao.lucky.detector import Detector
from luckyao.lucky.pipeline import run_lucky
from luckyao.optics.imaging import Imager
from luckyao.steps.screens import TurbulenceSpec, strip_specs
from luckyao.steps.simulation import simulate
from luckyao.studyspec.case import Case

CASE = yaml.safe_load((Path(__file__).parent / "data" / "tiny.yaml").read_text())["base"]
"""0.2 s, 4.2 m telescope, two layers at 0 and 5 km, no LGS, 64-pixel camera."""
SPEC = {
    "seed": 0,
    "duration_s": 0.2,
    "max_pixel_m": 0.1,
    "field_radius_arcsec": 1.0,
    "min_along_m": 20.0,
    "min_across_m": 10.0,
    "time_step_s": 0.0025,
    "diameter_m": 4.2,
    "outer_scale_m": 20.0,
    "height_m": [0.0, 5000.0],
    "wind_speed_m_s": [10.0, 20.0],
    "wind_direction_deg": [0.0, 90.0],
}


def _run(seed):
    specs = strip_specs(TurbulenceSpec.from_config(SPEC))
    screens = ScreenSet.from_screens(
        specs, [strip_screen(s, 20.0, np.random.default_rng([seed, i])) for i, s in enumerate(specs)]
    )
    system = Case.from_config(CASE)
    frames = []
    telemetry = simulate(system, screens, lambda start, block: frames.append(block.copy()))
    cube = np.concatenate(frames, axis=1)[0]
    imager = Imager(system.telescope, system.camera)
    lucky = run_lucky(
        lambda: iter([(0, cube)]),
        len(cube),
        [Detector("faint", 500.0, 1.0)],
        [0.1, 1.0],
        imager.diffraction_limited_peak,
        1.25 / 64,
        seed,
    )
    return cube, telemetry, lucky


def test_same_seed_same_numbers_other_seed_other_numbers():
    cube_a, telemetry_a, lucky_a = _run(3)
    cube_b, telemetry_b, lucky_b = _run(3)
    np.testing.assert_array_equal(cube_a, cube_b)
    np.testing.assert_array_equal(telemetry_a.true_rms_nm, telemetry_b.true_rms_nm)
    np.testing.assert_array_equal(lucky_a.strehl, lucky_b.strehl)  # detector noise too
    cube_c, _, lucky_c = _run(4)
    assert not np.array_equal(cube_a, cube_c)
    assert not np.array_equal(lucky_a.strehl, lucky_c.strehl)


_CACHE_SCRIPT = """
import sys
import numpy as np
from luckyao.lucky import radial_sums
from luckyao.lucky.detector import Detector, KeyedNoise
from luckyao.lucky.metrics import EncircledEnergy
ee = EncircledEnergy(64)
image = np.random.default_rng(9).random((1, 64, 64)).astype(np.float32)
centres = np.random.default_rng(10).uniform(20, 44, (1, 2 * radial_sums.RADIAL_CENTRES_INNER, 2))
out = [ee.radial_sums_about(image, centres[:, :m]) for m in (3, 2 * radial_sums.RADIAL_CENTRES_INNER)]
out.append(ee.energies_binned(image, centres[:, 0]))
chunk = KeyedNoise(64, 2).prepare(np.concatenate([image, image]) / image.sum())
for photons in (100.0, 3000.0):  # photons placed one by one, and pixel by pixel
    out += chunk.detect(Detector("rn", photons, 0.5), 7, 0)
sys.stdout.write(b"".join(np.ascontiguousarray(a).tobytes() for a in out).hex())
"""


def test_lucky_kernels_give_the_same_bits_compiled_here_or_loaded_from_numbas_cache(tmp_path):
    """The encircled-energy and detector-noise kernels give the same bits in the process that
    compiles them as in one that loads them from numba's cache (a kernel's callee compiled apart,
    as ``_phases`` once was, can be optimised differently in the two: a fresh clone's first job
    then differed from the next ones at 1e-14 in every sub-pixel method's d50)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    runs = [
        subprocess.run(
            [sys.executable, "-c", _CACHE_SCRIPT], env=env, capture_output=True, text=True, check=True
        ).stdout
        for _ in range(2)
    ]
    assert any(tmp_path.rglob("*.nbc")), "the first run wrote no cache"
    assert runs[0] and runs[0] == runs[1]
