"""Monte-Carlo error bars from time blocks against the spread over independent seeds.

The study quotes each value with a standard error from ``n`` independent time blocks
of one run (batch means). Here a small system (the 1 m telescope with three layers
of ``tests/test_longexposure.py``, winds slowed to 10-15 m/s) is run with ``N_SEEDS`` independent
turbulence seeds: the standard deviation of a value over the seeds is its true
Monte-Carlo error, which the block errors of single runs must reproduce.

Statistics of the check: with ``N_SEEDS = 12`` the spread's estimate has a relative
standard error ~ 1/sqrt(2 (N_SEEDS - 1)) = 21 %, and the root-mean-square of the 12
block errors (5 blocks each) ~ 1/sqrt(2 x 12 x 4) = 10 %; their ratio is held to
[0.55, 1.6], about two standard deviations of the ratio either side of 1 (a block
error that ignored the correlation of successive frames, the naive std/sqrt(frames),
would be 3-5 x too small here, and fail).
"""

import numpy as np
import pytest
from test_longexposure import CASE, SPEC

from luckyao.atmosphere.screens import ScreenSet, strip_screen
from luckyao.lucky.accumulation import batch_mean_error
from luckyao.lucky.detector import Detector
from luckyao.lucky.pipeline import run_lucky
from luckyao.optics.imaging import Imager
from luckyao.steps.screens import TurbulenceSpec, strip_specs
from luckyao.steps.simulation import simulate
from luckyao.studyspec.case import Case
from luckyao.studyspec.schema import deep_merge

N_SEEDS = 12
N_BLOCKS = 5
DURATION_S = 4.0
PEAK = Imager(Case.from_config(CASE).telescope, Case.from_config(CASE).camera).diffraction_limited_peak
WIND_M_S = [10.0, 12.5, 15.0]  # 0.1-0.15 m per 10 ms frame on the 1 m pupil: successive frames are correlated


@pytest.fixture(scope="module")
def seeds():
    """Per seed: the per-frame axis values and the frames (frame, y, x)."""
    spec = dict(SPEC, duration_s=DURATION_S + 0.05, wind_speed_m_s=WIND_M_S)
    specs = strip_specs(TurbulenceSpec.from_config(spec))
    system = Case.from_config(deep_merge(CASE, {"duration_s": DURATION_S, "atmosphere": {"wind_speed_m_s": WIND_M_S}}))
    runs = []
    for seed in range(N_SEEDS):
        screens = ScreenSet.from_screens(
            specs, [strip_screen(s, 20.0, np.random.default_rng([100 + seed, i])) for i, s in enumerate(specs)]
        )
        frames = []
        telemetry = simulate(system, screens, lambda start, f: frames.append(f[0].copy()))
        runs.append((telemetry.axis_strehl.values[0].astype(float), np.concatenate(frames)))
    return runs


def _ratio(values, errors) -> float:
    """Spread over seeds over the root-mean-square block error."""
    return float(np.std(values, ddof=1) / np.sqrt(np.mean(np.square(errors))))


def test_long_exposure_error_from_time_blocks_matches_the_spread_over_seeds(seeds):
    values = [axis.mean() for axis, _ in seeds]
    errors = [batch_mean_error(axis, N_BLOCKS) for axis, _ in seeds]
    ratio = _ratio(values, errors)
    naive = np.sqrt(np.mean([np.var(axis, ddof=1) / len(axis) for axis, _ in seeds]))
    print(
        f"long exposure: spread over seeds {np.std(values, ddof=1):.2e}, "
        f"block error {np.sqrt(np.mean(np.square(errors))):.2e}, ratio {ratio:.2f}, naive {naive:.2e}"
    )
    assert 0.55 < ratio < 1.6, (ratio, np.std(values, ddof=1), errors)
    assert np.std(values, ddof=1) > 2 * naive  # frames are correlated: the naive error would fail


@pytest.mark.parametrize("criterion", ["strehl", "d50"])
def test_lucky_image_errors_from_time_blocks_match_the_spread_over_seeds(seeds, criterion):
    """The same for the integrated lucky images (10 % and 50 % of the frames, selected by
    the image's Strehl or d50): each run's error is from its blocks, each selected and
    scored as a short run (``run_lucky(n_blocks=...)``)."""
    fractions = [0.1, 0.5]
    runs = []
    for _, frames in seeds:
        chunks = lambda frames=frames: ((s, frames[s : s + 64]) for s in range(0, len(frames), 64))  # noqa: E731
        runs.append(
            run_lucky(
                chunks,
                len(frames),
                [Detector("noiseless")],
                fractions,
                PEAK,
                0.08,
                1,
                image_crop_px=0,
                n_blocks=N_BLOCKS,
                progress_interval_s=1e9,
            ).sel(detector="noiseless", criterion=criterion)
        )
    for metric in ("strehl", "d50_arcsec"):
        for f in fractions:
            values = [float(r[metric].sel(fraction=f)) for r in runs]
            errors = [float(r[f"{metric}_error"].sel(fraction=f)) for r in runs]
            ratio = _ratio(values, errors)
            print(
                f"{criterion} selection, {metric} at {f:.0%}: spread {np.std(values, ddof=1):.3g}, "
                f"block error {np.sqrt(np.mean(np.square(errors))):.3g}, ratio {ratio:.2f}"
            )
            assert 0.55 < ratio < 1.6, (metric, f, ratio)


def test_value_with_error_keeps_two_significant_digits_of_the_error():
    """The README table's ``value ± error``: an error below 0.001 is not printed as 0.000."""
    from luckyao.figures import value_with_error

    assert value_with_error(0.005213, 0.000123) == "0.00521 ± 0.00012"
    assert value_with_error(0.2201, 0.0031) == "0.2201 ± 0.0031"
    assert value_with_error(0.2201, 0.031) == "0.220 ± 0.031"
    assert value_with_error(0.5, 0.0) == "0.500 ± 0.000"
