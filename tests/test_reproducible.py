"""Same config and seed give the same numbers; another seed gives others."""

from pathlib import Path

import numpy as np
import yaml

from luckyao.atmosphere.screens import ScreenSet, strip_screen
from luckyao.lucky.detector import Detector
from luckyao.lucky.pipeline import run_lucky
from luckyao.optics.imaging import Imager
from luckyao.study.case import Case
from luckyao.study.simulation import simulate
from luckyao.study.turbulence import TurbulenceSpec, strip_specs

CASE = yaml.safe_load((Path(__file__).parent / "data" / "tiny.yaml").read_text())["base"]
"""0.2 s, 4.2 m telescope, two layers at 0 and 5 km, no LGS, 64-pixel camera."""
SPEC = {"seed": 0, "duration_s": 0.2, "max_pixel_m": 0.1, "field_radius_arcsec": 1.0, "min_along_m": 20.0,
        "min_across_m": 10.0, "time_step_s": 0.0025, "diameter_m": 4.2, "outer_scale_m": 20.0,
        "height_m": [0.0, 5000.0], "wind_speed_m_s": [10.0, 20.0], "wind_direction_deg": [0.0, 90.0]}


def _run(seed):
    specs = strip_specs(TurbulenceSpec.from_config(SPEC))
    screens = ScreenSet.from_screens(
        specs, [strip_screen(s, 20.0, np.random.default_rng([seed, i])) for i, s in enumerate(specs)])
    system = Case.from_config(CASE)
    frames = []
    telemetry = simulate(system, screens, lambda start, block: frames.append(block.copy()))
    cube = np.concatenate(frames, axis=1)[0]
    imager = Imager(system.telescope, system.camera)
    lucky = run_lucky(lambda: iter([(0, cube)]), len(cube), [Detector("faint", 500.0, 1.0)], [0.1, 1.0],
                      imager.diffraction_limited_peak, 1.25 / 64, seed)
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
