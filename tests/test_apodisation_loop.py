"""Adaptive apodisation in the time loop (ao.apodisation): nothing blocked changes nothing, the
frames' flux is the transmitted flux recorded, and the config key is checked."""

import numpy as np
import pytest

from luckyao.atmosphere.screens import ScreenSet, strip_screen
from luckyao.steps.reconstructor import build_commands, build_reconstructors
from luckyao.steps.screens import TurbulenceSpec, strip_specs
from luckyao.steps.simulation import Replay, lgs_chain, simulate
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import commands_spec, reconstructor_spec, turbulence_spec
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, validate_study

DURATION_S = 0.3  # 30 lucky frames


@pytest.fixture(scope="module")
def loop():
    config, cases = load_study("config/config.yaml")
    base = deep_merge(cases["ltao_r0_13.5cm"], {"duration_s": DURATION_S, "wfs": {"calibration": "none"}})
    spec = dict(turbulence_spec(config, base), duration_s=DURATION_S + 0.05, max_pixel_m=0.033)
    specs = strip_specs(TurbulenceSpec.from_config(spec))
    screens = ScreenSet.from_screens(
        specs, [strip_screen(s, spec["outer_scale_m"], np.random.default_rng([3, i])) for i, s in enumerate(specs)]
    )
    reconstructors = build_reconstructors(reconstructor_spec(base))["reconstructor"].values
    c = build_commands(commands_spec(base))
    commands = (c.command_matrix.values, c.dm_slopes.values)

    def run(apodisation=None):
        cfg = base if apodisation is None else deep_merge(base, {"ao": {"apodisation": apodisation}})
        case = Case.from_config(cfg)
        sensor, estimator = lgs_chain(case, screens, reconstructors, seed=5)
        frames = []
        telemetry = simulate(case, screens, lambda start, f: frames.append(f.copy()), sensor, estimator, commands)
        return telemetry, np.concatenate(frames, axis=1)

    return run


@pytest.mark.parametrize("driver", ["lgs", "oracle"])
def test_nothing_blocked_changes_nothing(loop, driver):
    """blocked_fraction 0: a transmission of ones multiplies the field by 1.0 exactly, so the frames
    and the truth are bit-identical to the case without apodisation."""
    plain, plain_frames = loop()
    apodised, frames = loop({"driver": driver, "blocked_fraction": 0.0})
    assert "transmitted_flux" not in plain
    np.testing.assert_array_equal(frames, plain_frames)
    for name in ("true_rms_nm", "axis_strehl", "lgs_rms_nm", "lgs_residual_rms_nm"):
        np.testing.assert_array_equal(apodised[name].values, plain[name].values)
    np.testing.assert_array_equal(apodised.transmitted_flux.values, 1.0)


@pytest.mark.parametrize("driver", ["lgs", "oracle"])
def test_frame_flux_is_the_transmitted_flux(loop, driver):
    """A quarter of the 60 sub-aperture squares blocked (15): once the first command applies, each
    frame's flux is its recorded transmitted flux (flux proportional to the open area), about
    three quarters; the first exposure's steps see the full pupil."""
    apodised, frames = loop({"driver": driver, "blocked_fraction": 0.25})
    flux = apodised.transmitted_flux.values
    np.testing.assert_allclose(frames[0].sum(axis=(1, 2)), flux, rtol=2e-3)
    assert flux[0] == pytest.approx(0.5 + 0.5 * flux[1:].mean(), abs=0.05)  # half of frame 0 unapodised
    assert np.all((flux[1:] > 0.65) & (flux[1:] < 0.85))
    assert len(np.unique(flux[1:])) > 1  # the mask follows the residual


def test_config_key_checked():
    config, cases = load_study("config/config.yaml")
    study = deep_merge(
        config,
        {
            "cases": {
                "ltao_r0_13.5cm": {"ao": {"mode": "none", "apodisation": {"driver": "lgs", "blocked_fraction": 0.2}}}
            }
        },
    )
    with pytest.raises(ConfigError, match=r"ltao_r0_13.5cm\.ao\.apodisation"):
        validate_study(study)
    study = deep_merge(
        config, {"cases": {"ltao_r0_13.5cm": {"ao": {"apodisation": {"driver": "lgs", "blocked_fraction": 1.0}}}}}
    )
    with pytest.raises(ConfigError, match="blocked_fraction"):
        validate_study(study)


def test_replay_of_an_apodised_case_refused():
    _, cases = load_study("config/config.yaml")
    case = Case.from_config(
        deep_merge(cases["ltao_r0_13.5cm"], {"ao": {"apodisation": {"driver": "oracle", "blocked_fraction": 0.2}}})
    )
    with pytest.raises(ValueError, match="apodis"):
        next(Replay(case, None, [0], None)())
