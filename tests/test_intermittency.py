"""Intermittent turbulence (atmosphere.layer_variability, issue 43 item 3) against theory.

Each layer's Cn2 factor is ``exp(x - sigma^2 / 2)``, ``x`` a stationary Ornstein-Uhlenbeck
process of variance ``sigma^2`` and correlation time ``T``, drawn exactly at the time step
(an AR(1) with ``a = exp(-dt / T)``). Theory used, for ``N`` samples of such a process:

* the sample variance's standard error: ``sigma^2 sqrt(2 (1 + a^2) / ((1 - a^2) N))``;
* the sample autocorrelation at lag ``m`` steps has mean ``a^m`` and variance (Bartlett's
  formula for an AR(1)) ``[(1 + a^2)(1 - a^(2m)) / (1 - a^2) - 2 m a^(2m)] / N``;
* the factor's mean is 1, and the variance of its sample mean is
  ``(1/N) sum_|k|<N (1 - |k|/N) (exp(sigma^2 a^|k|) - 1)`` (``E[c_i c_j] = exp(sigma^2 rho_ij)``).

The tolerances are 4 of these standard errors (the layers are independent, so their
estimates are pooled).
"""

import numpy as np
import pytest
from test_ao_loop import _screens

from luckyao.atmosphere.intermittency import LayerVariability
from luckyao.steps.simulation import TimeLoop
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import (
    calibration_spec,
    commands_spec,
    reconstructor_spec,
    slopes_spec,
    turbulence_spec,
)
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, validate_study

DT_S = 0.0025
TOLERANCE_SE = 4.0


@pytest.fixture(scope="module")
def long_run():
    """Nine layers of 400,000 steps (1,000 s) of a 0.5 s process (2,000 correlation times each)."""
    variability = LayerVariability(sigma_ln=0.8, correlation_time_s=0.5, seed=2014)
    return variability, variability.log_factors(9, 400_000, DT_S)


def test_log_factors_have_the_stated_variance(long_run):
    variability, x = long_run
    n_layers, n = x.shape[1], x.shape[0]
    a = np.exp(-DT_S / variability.correlation_time_s)
    expected = variability.sigma_ln**2
    se = expected * np.sqrt(2 * (1 + a * a) / ((1 - a * a) * n)) / np.sqrt(n_layers)
    assert abs(np.mean(x * x) - expected) < TOLERANCE_SE * se
    assert abs(np.mean(x)) < TOLERANCE_SE * variability.sigma_ln * np.sqrt((1 + a) / ((1 - a) * n * n_layers))


@pytest.mark.parametrize("lag_correlation_times", [0.25, 1.0, 2.0])
def test_log_factors_decorrelate_as_exp_minus_lag_over_t(long_run, lag_correlation_times):
    variability, x = long_run
    n_layers, n = x.shape[1], x.shape[0]
    m = round(lag_correlation_times * variability.correlation_time_s / DT_S)
    a = np.exp(-DT_S / variability.correlation_time_s)
    r = np.mean(x[:-m] * x[m:]) / np.mean(x * x)
    variance = ((1 + a * a) * (1 - a ** (2 * m)) / (1 - a * a) - 2 * m * a ** (2 * m)) / (n * n_layers)
    assert r == pytest.approx(np.exp(-m * DT_S / variability.correlation_time_s), abs=TOLERANCE_SE * np.sqrt(variance))


def test_factors_keep_the_mean_cn2(long_run):
    """``E[c] = 1``: each layer's mean Cn2, so the profile the tomography's prior assumes, is kept."""
    variability, x = long_run
    n_layers, n = x.shape[1], x.shape[0]
    factors = np.exp(x - variability.sigma_ln**2 / 2)
    a = np.exp(-DT_S / variability.correlation_time_s)
    k = np.arange(1, n)
    covariance = np.exp(variability.sigma_ln**2 * a**k) - 1
    variance = (np.exp(variability.sigma_ln**2) - 1 + 2 * np.sum((1 - k / n) * covariance)) / n / n_layers
    assert abs(np.mean(factors) - 1) < TOLERANCE_SE * np.sqrt(variance)
    # without the -sigma^2/2 the mean would be exp(sigma^2/2) = 1.38: far outside
    assert abs(np.exp(variability.sigma_ln**2 / 2) - 1) > 10 * TOLERANCE_SE * np.sqrt(variance)


def test_same_seed_same_factors_each_layer_its_own_stream():
    """Deterministic from the seed and the layer index; a longer run starts with a shorter
    one's factors; the layers and another seed differ."""
    variability = LayerVariability(sigma_ln=0.6, correlation_time_s=10.0, seed=5)
    short = variability.cn2_factors(3, 1000, DT_S)
    np.testing.assert_array_equal(short, variability.cn2_factors(3, 1000, DT_S))
    np.testing.assert_array_equal(short, variability.cn2_factors(4, 3000, DT_S)[:1000, :3])
    assert not np.allclose(short[:, 0], short[:, 1])
    other = LayerVariability(sigma_ln=0.6, correlation_time_s=10.0, seed=6).cn2_factors(3, 1000, DT_S)
    assert not np.allclose(short, other)


@pytest.fixture(scope="module")
def study():
    return load_study("config/config.yaml")


def with_variability(config: dict, case: str, block: dict) -> dict:
    """The study with case ``case`` given ``atmosphere.layer_variability: block``, its cases resolved."""
    return validate_study(deep_merge(config, {"cases": {case: {"atmosphere": {"layer_variability": block}}}}))


def test_zero_variability_reproduces_the_scales_bit_for_bit(study):
    config, cases = study
    constant = Case.from_config(cases["ltao_r0_variable"])
    still = Case.from_config(with_variability(config, "ltao_r0_variable", {"sigma_ln": 0.0})["ltao_r0_variable"])
    steps = np.arange(constant.clock.n_steps)
    assert constant.layer_variability is None and still.layer_variability.sigma_ln == 0.0
    np.testing.assert_array_equal(still.layer_scales(steps), constant.layer_scales(steps))
    np.testing.assert_allclose(still.r0_samples_m(), constant.r0_samples_m(), rtol=1e-12)


def test_resolved_case_holds_the_defaults_and_the_seed(study):
    """Left out, the block's keys are the schema's and its seed the study's: the resolved
    config alone makes the factors. The scales squared over the constant case's are the
    factors; r0 is the whole profile's."""
    config, cases = study
    resolved = with_variability(config, "ltao_r0_13.5cm", {})["ltao_r0_13.5cm"]
    block = resolved["atmosphere"]["layer_variability"]
    assert block == {"sigma_ln": 0.6, "correlation_time_s": 1020.0, "seed": config["seed"]}
    assert (
        with_variability(config, "ltao_r0_13.5cm", {"seed": 3})["ltao_r0_13.5cm"]["atmosphere"]["layer_variability"][
            "seed"
        ]
        == 3
    )
    case, constant = Case.from_config(resolved), Case.from_config(cases["ltao_r0_13.5cm"])
    steps = np.arange(0, case.clock.n_steps, 7)
    factors = LayerVariability(**block).cn2_factors(len(case.layers), case.clock.n_steps, case.time_step_s)[steps]
    np.testing.assert_allclose((case.layer_scales(steps) / constant.layer_scales(steps)) ** 2, factors, rtol=1e-12)
    fractions = np.array([layer.cn2_fraction for layer in case.layers])
    np.testing.assert_allclose(case.r0_m(steps), 0.135 * (factors @ fractions / fractions.sum()) ** -0.6, rtol=1e-12)


def test_no_existing_case_or_product_moves(study):
    """The block is absent from every case of the default and paper studies: their resolved
    configs have no such key, and a case with it shares the screens, the reconstructor, the
    command matrix and the WFS calibration of its constant twin (only its slopes differ)."""
    config, cases = study
    paper, paper_cases = load_study("config/config.yaml", "config/paper.yaml")
    for resolved in list(cases.values()) + list(paper_cases.values()):
        assert "layer_variability" not in resolved["atmosphere"]
    intermittent = with_variability(config, "ltao_r0_13.5cm", {"correlation_time_s": 10.0})["ltao_r0_13.5cm"]
    constant = cases["ltao_r0_13.5cm"]
    assert turbulence_spec(config, intermittent) == turbulence_spec(config, constant)
    for spec in (reconstructor_spec, commands_spec):
        assert spec(intermittent) == spec(constant)
    assert calibration_spec(config, intermittent) == calibration_spec(config, constant)
    assert slopes_spec(config, intermittent) != slopes_spec(config, constant)


def test_bad_variability_is_refused_by_key(study):
    config, _ = study
    with pytest.raises(ConfigError, match=r"ltao_r0_13.5cm.atmosphere.layer_variability.correlation_time_s"):
        with_variability(config, "ltao_r0_13.5cm", {"correlation_time_s": 0.0})
    with pytest.raises(ConfigError, match=r"layer_variability.sigma"):
        with_variability(config, "ltao_r0_13.5cm", {"sigma": 0.5})


def one_layer_case(config: dict, cases: dict, **variability) -> dict:
    """One frozen ground layer, no LGS and no AO, a frame per time step, a 64-pixel camera."""
    block = {"layer_variability": variability} if variability else {}
    return deep_merge(
        cases["noao_r0_13.5cm"],
        {
            "duration_s": 0.1,
            "camera": {"n_pixels": 64, "frame_time_s": DT_S},
            "lgs": {"enabled": False},
            "atmosphere": {
                "height_m": [0.0],
                "cn2_fraction": [1.0],
                "wind_speed_m_s": [10.0],
                "wind_direction_deg": [0.0],
                **block,
            },
        },
    )


def test_the_science_path_sees_the_factors(study):
    """One layer, a frame per step: the true rms squared over the constant case's (the same
    screen) is the layer's factor, and the telemetry's r0 is r0 c^(-3/5)."""
    config, cases = study
    constant_cfg = one_layer_case(config, cases)
    intermittent_cfg = one_layer_case(config, cases, sigma_ln=0.7, correlation_time_s=0.05, seed=3)
    spec = dict(turbulence_spec(config, constant_cfg), duration_s=0.15, max_pixel_m=0.033)
    screens = _screens(spec, 5)
    runs = [
        TimeLoop(Case.from_config(c), screens, 5).run(lambda start, f: None) for c in (constant_cfg, intermittent_cfg)
    ]
    case = Case.from_config(intermittent_cfg)
    factors = case.cn2_factors[:, 0]
    ratio = (runs[1].true_rms_nm.values[0].astype(float) / runs[0].true_rms_nm.values[0]) ** 2
    np.testing.assert_allclose(ratio, factors, rtol=2e-5)  # float32 telemetry
    np.testing.assert_allclose(runs[1].r0_500nm_m.values, 0.135 * factors**-0.6, rtol=1e-12)
    assert np.ptp(np.log(factors)) > 0.5  # the factors do vary over the run


def test_every_consumer_of_the_scales_gets_the_case_s(study, monkeypatch):
    """The LGS sensor (and with it the residual budget's twin) and the science path of an AO
    case are handed the case's layer scales, step by step: the same factors everywhere."""
    from luckyao.steps import simulation
    from luckyao.steps.reconstructor import build_commands, build_reconstructors
    from luckyao.wfs.sensor import LgsSensor

    config, cases = study
    cfg = deep_merge(
        with_variability(config, "ltao_r0_13.5cm", {"correlation_time_s": 0.05})["ltao_r0_13.5cm"],
        {
            "duration_s": 0.02,
            "camera": {"n_pixels": 64},
            "wfs": {"calibration": "none"},
            "ao": {"residual_budget": True},
        },
    )
    case = Case.from_config(cfg)
    spec = dict(turbulence_spec(config, cfg), duration_s=0.05, max_pixel_m=0.033)
    seen = []
    sample, frame = LgsSensor.sample, simulation.SciencePath.frame

    def sensor_sample(self, steps, layer_scales):
        seen.append(("wfs", np.array(steps), np.array(layer_scales)))
        return sample(self, steps, layer_scales)

    def science_frame(self, index, steps, layer_scales, *args, **kwargs):
        seen.append(("science", np.array(steps), np.array(layer_scales)))
        return frame(self, index, steps, layer_scales, *args, **kwargs)

    monkeypatch.setattr(LgsSensor, "sample", sensor_sample)
    monkeypatch.setattr(simulation.SciencePath, "frame", science_frame)
    built = build_commands(commands_spec(cfg))
    reconstructors = build_reconstructors(reconstructor_spec(cfg))["reconstructor"].values
    TimeLoop(
        case,
        _screens(spec, 5),
        5,
        reconstructors=reconstructors,
        commands=(built.command_matrix.values, built.dm_slopes.values),
    ).run(lambda start, f: None)
    kinds = {kind for kind, _, _ in seen}
    assert kinds == {"wfs", "science"}
    assert sum(kind == "wfs" for kind, _, _ in seen) == 2 * case.clock.n_exposures  # the sensor and its noiseless twin
    for _, steps, scales in seen:
        np.testing.assert_array_equal(scales, case.layer_scales(steps))
        assert not np.allclose(scales, Case.from_config(cases["ltao_r0_13.5cm"]).layer_scales(steps))
