"""Phase screens against von Karman theory; r0 and wavelength scaling."""

import numpy as np
import pytest

from luckyao.atmosphere.screens import strip_screen, strip_spec
from luckyao.atmosphere.statistics import (
    Layer,
    R0Schedule,
    r0_at_wavelength,
    von_karman_psd,
    von_karman_structure_function,
)

L0_M = 20.0
DX_M = 0.05


def test_structure_function_tends_to_kolmogorov_for_small_separations():
    # D = 6.88 (r/r0)^(5/3) [1 - 1.485 (r/L0)^(1/3) + O((r/L0)^2)]  (Conan 2000; Sasiela)
    r, outer_scale = np.array([1e-3, 1e-2, 1e-1]), 1e4
    expected = 6.883877 * r ** (5 / 3) * (1 - 1.485 * (r / outer_scale) ** (1 / 3))
    assert von_karman_structure_function(r, 1.0, outer_scale) == pytest.approx(expected, rel=2e-4)


def test_structure_function_is_the_transform_of_the_psd():
    """D(r) = 2 int Phi(f) (1 - J0(2 pi f r)) 2 pi f df: numerically up to F, plus the
    analytic tail 4 pi int_F^inf f Phi df where J0 has decayed below 1 %."""
    from scipy.integrate import quad
    from scipy.special import j0

    from luckyao.atmosphere.statistics import _VK_COEFFICIENT

    r0, outer_scale = 0.15, L0_M
    for r in (0.1, 1.0, 4.2, 30.0):
        integrand = lambda f: 4 * np.pi * f * von_karman_psd(f, r0, outer_scale) * (1 - j0(2 * np.pi * f * r))  # noqa: B023, E731
        cut = 2000 / r
        body = sum(
            quad(integrand, a, b, limit=2000)[0]
            for a, b in zip(np.linspace(0, cut, 41)[:-1], np.linspace(0, cut, 41)[1:])
        )
        tail = 4 * np.pi * _VK_COEFFICIENT * r0 ** (-5 / 3) * 0.6 * (cut**2 + outer_scale**-2) ** (-5 / 6)
        assert von_karman_structure_function(r, r0, outer_scale) == pytest.approx(body + tail, rel=1e-4)


def _strip(direction_deg):
    """A 200 m strip >= 4 D wide (the study's minimum) along a wind at ``direction_deg``."""
    return strip_spec(Layer(0.0, 1.0, 10.0, direction_deg), 0.0025, 4000, DX_M, 3.2, 200.0, 16.8)


def _sky_differences(screen, spec, lag):
    """Differences of samples ``lag`` apart on the sky along the major and the minor axis."""
    minor = screen[:, lag:] - screen[:, :-lag]
    shift = spec.line_offset(np.arange(lag, spec.n_major)) - spec.line_offset(np.arange(spec.n_major - lag))
    j = np.arange(max(0, shift.max()), spec.n_minor + min(0, shift.min()))
    major = np.take_along_axis(screen[lag:], j[None, :] - shift[:, None], axis=1) - screen[:-lag, j]
    return major, minor


def _empirical_structure_functions(direction_deg, n_screens):
    """Mean D(r)/theory along the sky's major and minor axes over independent
    screens, and its standard error."""
    spec = _strip(direction_deg)
    lags = np.array([2, 10, 20, 40, 84])  # 0.1 m ... 4.2 m = D
    theory = von_karman_structure_function(lags * DX_M, 1.0, L0_M)
    ratios = []
    for seed in range(n_screens):
        screen = strip_screen(spec, L0_M, np.random.default_rng(seed)).astype(np.float64)
        d = [[np.mean(diff**2) for diff in _sky_differences(screen, spec, k)] for k in lags]
        ratios.append(np.array(d).T / theory)
    ratios = np.array(ratios)
    return lags * DX_M, ratios.mean(axis=0), ratios.std(axis=0, ddof=1) / np.sqrt(n_screens)


@pytest.mark.parametrize("direction_deg, n_screens", [(0.0, 16), (30.0, 16), (108.0, 8)])
def test_screens_follow_von_karman_from_small_to_pupil_scales(direction_deg, n_screens):
    """Along the wind, across it and on skewed strips (winds at 30 and 108 deg)."""
    r_m, mean, error = _empirical_structure_functions(direction_deg, n_screens)
    for axis in range(2):
        # 2 samples: the FFT screen lacks power beyond the sampling frequency; the
        # generator's expected D is 2.7 % low there (computed from its spectrum)
        assert mean[axis, 0] == pytest.approx(0.973, abs=3 * error[axis, 0] + 0.005)
        # 0.5 m to D = 4.2 m, where tip-tilt lives: the expected D is within 1 % of
        # theory; allow that plus 3 standard errors of the Monte Carlo
        np.testing.assert_array_less(np.abs(mean[axis, 1:] - 1), 0.01 + 3 * error[axis, 1:])
    # the test has power: its errors are a few percent at most
    assert error.max() < 0.04


def test_r0_and_wavelength_scaling():
    assert r0_at_wavelength(0.135, 800e-9) == pytest.approx(0.135 * 1.6**1.2)
    # phase in rad scales as 1/lambda; D(r) at lambda with r0(lambda) must agree
    r = np.array([0.05, 0.5, 2.0])
    d500 = von_karman_structure_function(r, 0.135, L0_M)
    d800 = von_karman_structure_function(r, r0_at_wavelength(0.135, 800e-9), L0_M)
    np.testing.assert_allclose(d800, d500 * (500 / 800) ** 2, rtol=1e-10)
    # a normalised screen scaled by r0^(-5/6) has the structure function of r0
    screen = strip_screen(_strip(0.0), L0_M, np.random.default_rng(7)).astype(np.float64)
    for r0 in (0.1, 0.2):
        scaled = r0 ** (-5 / 6) * screen
        d = np.mean((scaled[:, 4:] - scaled[:, :-4]) ** 2)
        assert d / von_karman_structure_function(4 * DX_M, r0, L0_M) == pytest.approx(0.99, abs=0.03)


def test_sinusoidal_r0():
    schedule = R0Schedule(0.15, 0.05, 12.5)
    t = np.linspace(0, 12.5, 1001)[:-1]
    r0 = schedule.r0_m(t)
    assert r0.min() == pytest.approx(0.10, abs=1e-4)
    assert r0.max() == pytest.approx(0.20, abs=1e-4)
    assert r0.mean() == pytest.approx(0.15, abs=1e-9)


def test_strip_spec_holds_the_whole_flow():
    layer = Layer(9000.0, 0.043, 38.8, 252.0)  # closer to -y than to x
    spec = strip_spec(layer, 0.0025, 1000, 0.033, 5.0, 100.0, 16.8)
    assert spec.dx_m == 0.033 and spec.major_axis == 1
    step = np.hypot(*spec.step_samples) * spec.dx_m
    assert step == pytest.approx(38.8 * 0.0025)
    cos = abs(np.sin(np.radians(252.0)))
    # lines follow the wind: slope minor/major = cot(252 deg)
    assert spec.skew / spec.n_major == pytest.approx(
        np.cos(np.radians(252.0)) / np.sin(np.radians(252.0)), abs=1 / spec.n_major
    )
    assert spec.n_major * spec.dx_m >= cos * 1000 * 38.8 * 0.0025 + 10.0
    assert spec.n_major * spec.dx_m / cos >= 100.0  # along-wind period
    assert spec.n_minor * spec.dx_m * cos >= 16.8  # width across the wind


def test_screens_made_layers_at_once_are_the_same_numbers(tmp_path):
    """``write_screens(threads=3)`` makes layers concurrently (largest first): each layer still
    draws from its own ``default_rng([seed, layer])``, so the file is byte for byte that of one
    thread, and each layer is ``strip_screen`` of its own stream."""
    from luckyao.steps.screens import TurbulenceSpec, read_screens, strip_specs, write_screens

    spec = {
        "seed": 5,
        "duration_s": 0.5,
        "max_pixel_m": 0.05,
        "field_radius_arcsec": 10,
        "min_along_m": 20.0,
        "min_across_m": 4.0,
        "time_step_s": 0.0025,
        "diameter_m": 1.0,
        "outer_scale_m": L0_M,
        "height_m": [0.0, 1000.0, 8000.0],
        "wind_speed_m_s": [5.0, 30.0, 12.0],
        "wind_direction_deg": [0.0, 120.0, 250.0],
    }
    for threads in (1, 3):
        write_screens(spec, tmp_path / f"{threads}.npy", tmp_path / f"{threads}.nc", {}, threads=threads)
    assert (tmp_path / "1.npy").read_bytes() == (tmp_path / "3.npy").read_bytes()
    screens = read_screens(tmp_path / "3.npy", tmp_path / "3.nc")
    for i, s in enumerate(strip_specs(TurbulenceSpec.from_config(spec))):
        np.testing.assert_array_equal(
            screens.screen(i), strip_screen(s, L0_M, np.random.default_rng([spec["seed"], i]))
        )
