"""The residual budget (ao/budget.py) against theory.

One shared set-up (module fixture): the default AO system (9-layer profile, 4 Rayleigh LGS,
8x8 WFS, 9x9 DM, r0 = 13.5 cm, L0 = 20 m) with a noisy WFS, its screens at the default
study's 0.0165 m, the camera cut to 64 pixels (the same 3.3 cm pupil sampling). LTAO runs with
the 2-step delay and with 4 steps, on the same screens (common random numbers).

Theory:

* fitting: ``sigma^2 = kappa (d/r0)^(5/3)``, ``kappa`` of a Gaussian-influence DM of 30 %
  coupling: 0.237 on an infinite lattice (Fourier theory, ``test_dm.lattice_kappa``; the
  Hudgin/Rigaut range 0.23-0.30), lowered by the annular pupil's edge to about 0.19 for 9x9
  (``test_dm.test_fitting_error_follows_kappa``);
* servo lag: frozen flow. A delay ``tau`` leaves ``D(v tau) = (tau / tau0)^(5/3)``,
  ``tau0 = 0.314 r0 / v_5/3`` (Greenwood; e.g. Hardy 1998, Adaptive Optics for Astronomical
  Telescopes, eq. 9.57), over all spatial frequencies; the budget's servo-lag part is that
  of the DM-fitted phase, the frequencies the DM corrects (below ``1 / 2d`` in x and y),
  averaged over the exposure and the steps that hold its command. :func:`frozen_flow_rad2`
  integrates the frozen-flow spectrum over either band; its full band is checked against
  ``(tau / tau0)^(5/3)`` itself.
"""

import numpy as np
import pytest
from test_ao_loop import _screens, _Setup
from test_dm import lattice_kappa

from luckyao.ao.budget import PARTS, budget_statistics, first_corrected_frame, mean_gradient_matrix
from luckyao.ao.control import dm_slopes_matrix
from luckyao.atmosphere.statistics import von_karman_psd
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import turbulence_spec
from luckyao.studyspec.schema import deep_merge
from luckyao.studyspec.study import load_study
from luckyao.units import REFERENCE_WAVELENGTH_M, phase_rad_to_nm

DURATION_S = 0.3
PIXEL_M = 0.0165
NM_PER_RAD = float(phase_rad_to_nm(1.0, REFERENCE_WAVELENGTH_M))


def greenwood_tau0_s(case: Case) -> float:
    """``tau0 = 0.314 r0 / v_5/3``, ``v_5/3 = (sum_l f_l v_l^(5/3))^(3/5)`` [s] at 500 nm."""
    v = sum(layer.cn2_fraction * layer.wind_speed_m_s ** (5 / 3) for layer in case.layers) ** (3 / 5)
    return 0.314 * case.r0.mean_m / v


def frozen_flow_rad2(case: Case, lags_steps: np.ndarray, cutoff_per_m: float | None) -> float:
    """Variance [rad^2 at 500 nm] of ``phi(t) - mean_k phi(t - lag_jk)`` averaged over ``j``
    (``lags_steps`` (j, k) in time steps), frozen flow of the case's layers (von Karman,
    Fourier integral in polar coordinates); with ``cutoff_per_m``, only the frequencies with
    ``|f_x|, |f_y| < cutoff``."""
    f = np.logspace(np.log10(1e-2 / case.outer_scale_m), 3, 4000)[:, None]
    theta = (np.arange(720) + 0.5) * 2 * np.pi / 720
    fx, fy = f * np.cos(theta), f * np.sin(theta)
    band = np.ones_like(fx) if cutoff_per_m is None else (np.abs(fx) < cutoff_per_m) & (np.abs(fy) < cutoff_per_m)
    total = np.zeros_like(fx)
    for layer in case.layers:
        vx, vy = layer.wind_speed_m_s * layer.wind_unit * case.time_step_s  # [m per step]
        phase = 2j * np.pi * (fx * vx + fy * vy)
        transfer = np.mean(
            [np.abs(1 - np.mean([np.exp(phase * lag) for lag in lags], axis=0)) ** 2 for lags in lags_steps], axis=0
        )
        total += layer.cn2_fraction * von_karman_psd(f, case.r0.mean_m, case.outer_scale_m) * transfer
    integrand = np.mean(total * band, axis=1) * 2 * np.pi * f[:, 0] ** 2  # d^2 f = f df dtheta = f^2 dln f dtheta
    return float(np.trapezoid(integrand, np.log(f[:, 0])))


def servo_lags(case: Case) -> np.ndarray:
    """(j, k) lags [steps] of the science steps ``j`` holding an exposure's command from its
    steps ``k``: ``delay + j - k``."""
    e = case.wfs.exposure_steps
    return case.ao.delay_steps + np.arange(e)[:, None] - np.arange(e)[None, :]


class _Budgets(_Setup):
    def budget(self, **ao):
        return self.run(str(sorted(ao.items())), DURATION_S, residual_budget=True, **ao)


@pytest.fixture(scope="module")
def system():
    config, cases = load_study("config/config.yaml")
    base = deep_merge(
        cases["ltao_r0_13.5cm"],
        {"duration_s": DURATION_S, "camera": {"n_pixels": 64}, "wfs": {"photons_per_subaperture": 300.0}},
    )
    spec = dict(turbulence_spec(config, base), duration_s=DURATION_S + 0.05, max_pixel_m=PIXEL_M)
    return _Budgets(base, _screens(spec, 11))


def _variance_rad2(telemetry, part: str, frames=slice(1, None)) -> float:
    """Mean variance of a part [rad^2 at 500 nm] over ``frames`` (the first holds the steps
    before the first command)."""
    return float(np.mean(telemetry[f"residual_{part}_rms_nm"].values[frames].astype(float) ** 2)) / NM_PER_RAD**2


def test_parts_sum_to_the_truth(system):
    """The parts' powers and their cross terms add up to the truth, ``true_rms_nm``, which the
    science path measures on its own: a part left out or wrong breaks the sum."""
    telemetry = system.budget()
    parts = np.array([telemetry[f"residual_{p}_rms_nm"].values.astype(float) for p in PARTS])
    total = np.sum(parts**2, axis=0) + telemetry["residual_cross_nm2"].values
    truth = telemetry["true_rms_nm"].values[0].astype(float) ** 2
    np.testing.assert_allclose(total, truth, rtol=2e-4)
    assert np.all(parts[:, 1:] > 0)  # every part present, noise included
    stats = budget_statistics(telemetry, telemetry["axis_strehl"].values[0])
    assert float(stats["share_of_total_fluctuation"].sum()) == pytest.approx(2.0, rel=1e-3)  # parts + cross, total


def test_budget_leaves_the_loop_alone(system):
    """With the budget the loop's own telemetry is the same to the bit (its noiseless twin
    sensor draws no noise and touches none of the loop's state)."""
    budget, plain = system.budget(), system.run("plain", 0.03)
    frames = plain.sizes["frame"]
    for name in ("true_rms_nm", "axis_strehl", "lgs_rms_nm", "lgs_residual_rms_nm"):
        np.testing.assert_array_equal(budget[name].values[:, :frames], plain[name].values)
    exposures = plain.sizes["exposure"]
    np.testing.assert_array_equal(budget["dm_commands_m"].values[:exposures], plain["dm_commands_m"].values)


def test_fitting_follows_kappa(system):
    """The fitting part: sigma^2 = kappa (d/r0)^(5/3) with kappa between the annular pupil's
    Monte-Carlo 0.19 less 15 % and the infinite lattice's 0.237 (the bounds of test_dm for 9x9
    less the screens' bilinear smoothing)."""
    case = Case.from_config(system.config(mode="ltao"))
    pitch = case.ao.deformable_mirror(case.telescope).pitch_m
    kappa = _variance_rad2(system.budget(), "fitting") / (pitch / case.r0.mean_m) ** (5 / 3)
    assert 0.19 * 0.85 < kappa < lattice_kappa(0.3, pitch)


def test_frozen_flow_integral_is_greenwood():
    """The Fourier integral of a pure delay over all frequencies (L0 -> inf) is (tau/tau0)^(5/3)."""
    config, cases = load_study("config/config.yaml")
    case = Case.from_config(deep_merge(cases["ltao_r0_13.5cm"], {"atmosphere": {"outer_scale_m": 1e8}}))
    tau0 = greenwood_tau0_s(case)
    for lag in (1, 4):
        expected = (lag * case.time_step_s / tau0) ** (5 / 3)
        assert frozen_flow_rad2(case, np.array([[lag]]), None) == pytest.approx(expected, rel=0.02)


def test_servo_lag_follows_frozen_flow(system):
    """The servo-lag part against frozen flow over the DM's band, for 2 and 4 steps of delay;
    and their ratio, which the DM's filter shapes alike (a lag off by one step moves it by 40 %)."""
    measured, expected = {}, {}
    for delay in (2, 4):
        case = Case.from_config(system.config(mode="ltao", delay_steps=delay))
        cutoff = 1 / (2 * case.ao.deformable_mirror(case.telescope).pitch_m)
        measured[delay] = _variance_rad2(system.budget(delay_steps=delay), "servo_lag", slice(2, None))
        expected[delay] = frozen_flow_rad2(case, servo_lags(case), cutoff)
        assert measured[delay] == pytest.approx(expected[delay], rel=0.3)
        greenwood = (delay * case.time_step_s / greenwood_tau0_s(case)) ** (5 / 3)
        assert measured[delay] < greenwood  # the DM's band holds part of the full-band value
    assert measured[4] / measured[2] == pytest.approx(expected[4] / expected[2], rel=0.1)


def test_noise_free_sensor_has_no_noise_part(system):
    """Without photon or read noise the noise part is exactly zero; the rest still sum up."""
    base = system.base
    system.base = deep_merge(base, {"wfs": {"photons_per_subaperture": None}})
    try:
        telemetry = system.run("noiseless", 0.05, residual_budget=True)
    finally:
        system.base = base
    assert np.all(telemetry["residual_noise_rms_nm"].values == 0)
    assert np.all(telemetry["residual_sensor_rms_nm"].values > 0)


def test_glao_tomography_holds_the_altitude(system):
    """GLAO leaves the altitude layers uncorrected: its tomography part exceeds LTAO's, its
    fitting part (the same phase, the same DM) is LTAO's."""
    glao = system.run("glao", 0.05, mode="glao", residual_budget=True)
    ltao = system.run("ltao_short", 0.05, mode="ltao", residual_budget=True)
    assert _variance_rad2(glao, "tomography") > 2 * _variance_rad2(ltao, "tomography")
    np.testing.assert_array_equal(glao["residual_fitting_rms_nm"].values, ltao["residual_fitting_rms_nm"].values)


def test_mean_gradient_matches_the_dm_slopes():
    """The budget's mean gradient of a DM surface sampled on the WFS grid is the DM's slopes
    (control.dm_slopes_matrix, edge quadrature of the influence functions) on the fully
    illuminated sub-apertures; on the others it is the illuminated part's, as the sensor's."""
    config, cases = load_study("config/config.yaml")
    case = Case.from_config(cases["ltao_r0_13.5cm"])
    wfs, dm = case.shack_hartmann(), case.ao.deformable_mirror(case.telescope)
    x, y = wfs.grid.xy_m
    h = dm.influence_matrix(x[wfs.sensed_mask], y[wfs.sensed_mask])
    commands = np.random.default_rng(3).standard_normal((dm.n_valid, 8))
    gradient = (mean_gradient_matrix(wfs) @ h @ commands).reshape(2, wfs.n_valid, -1)
    exact = (dm_slopes_matrix(dm, wfs, 1).astype(float) @ commands).reshape(2, wfs.n_valid, -1)
    full = wfs.illumination[wfs.valid] == 1
    for part in (gradient, exact):  # without the tilt (dm_slopes_matrix removes its own)
        part -= part[:, full].mean(axis=1, keepdims=True)
    error = (gradient - exact)[:, full]
    assert np.sqrt(np.mean(error**2)) < 0.01 * np.sqrt(np.mean(exact[:, full] ** 2))
    edge = (gradient - exact)[:, ~full]
    assert np.sqrt(np.mean(edge**2)) > 0.03 * np.sqrt(np.mean(exact[:, ~full] ** 2))


def test_budget_needs_ao():
    """A budget without AO is refused, naming the key."""
    from luckyao.studyspec.schema import ConfigError
    from luckyao.studyspec.study import validate_study

    config, _ = load_study("config/config.yaml")
    config = deep_merge(config, {"cases": {"bad": {"ao": {"residual_budget": True}}}})
    with pytest.raises(ConfigError, match="residual_budget"):
        validate_study(config)


def test_statistics_need_a_budget(system):
    with pytest.raises(ValueError, match="residual_budget"):
        budget_statistics(system.run("plain", 0.03), np.ones(3))


def test_figure_draws_the_statistics(system):
    """The residual_budget figure's dataset is budget_statistics of each case against its
    frames' recentred Strehl ratio; a part whose variance falls as the Strehl rises anticorrelates."""
    from luckyao.figures import FIGURE_KINDS, FigureSettings

    telemetry = system.budget()
    n = telemetry.sizes["frame"]
    fitting = telemetry["residual_fitting_rms_nm"].values.astype(float)
    strehl = 1.0 / (1.0 + fitting**2)  # falls as the fitting part rises
    lucky = telemetry.assign(
        frame_recentred_strehl=(("target", "detector", "frame"), strehl.reshape(1, 1, n)),
        mean_r0_500nm_m=0.135,
    ).assign_coords(detector=["noiseless"])
    settings = FigureSettings.from_dict(
        {"kind": "residual_budget", "cases": ["budget"], "case_configs": {"budget": system.config(mode="ltao")}}
    )
    make_data, draw = FIGURE_KINDS["residual_budget"]
    ds = make_data(settings, [lucky])
    assert first_corrected_frame(settings.case("budget")) == 1  # the first frame's 2 steps before a command
    expected = budget_statistics(telemetry, strehl, from_frame=1)
    np.testing.assert_allclose(ds.mean_variance_nm2.sel(case="budget"), expected.mean_variance_nm2)
    assert float(ds.strehl_correlation.sel(case="budget", part="fitting")) < -0.9
    assert draw(ds, "budget").axes


def test_declared_time_counts_the_budget():
    """A simulation with the budget declares BUDGET_SHARE more of each step's time."""
    from luckyao.jobs.resources import BUDGET_SHARE, simulate_seconds

    config, cases = load_study("config/config.yaml")
    case = cases["ltao_r0_13.5cm"]
    budget = deep_merge(case, {"ao": {"residual_budget": True}})
    assert simulate_seconds(budget) == pytest.approx((1 + BUDGET_SHARE) * simulate_seconds(case))
