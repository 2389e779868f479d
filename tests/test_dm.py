"""Deformable mirror against fitting-error theory and exact-fit identities."""

import numpy as np
import pytest

from luckyao.ao.dm import DeformableMirror
from luckyao.atmosphere.statistics import von_karman_psd
from luckyao.optics.pupil import Telescope, TiltRemover
from luckyao.tomography.reconstructor import pupil_points

TELESCOPE = Telescope(4.2, 1.2)
OUTER_SCALE_M = 20.0
ORDERS = (5, 9, 17)
SAMPLES_ACROSS = 192  # pupil sampling dx = D / 192 = 22 mm <= d / 12 for every order


def lattice_kappa(coupling: float, pitch_m: float, n_cell: int = 200, n_alias: int = 8) -> float:
    """Fitting-error coefficient of an infinite square lattice of Gaussian influence
    functions, least-squares fit (Fourier theory, independent of the DM code).

    The surface ``sum_k c_k h(x - k d)`` has spectrum ``H(f) C(f)`` with ``C``
    periodic (period 1/d), so at each frequency ``f`` of the Nyquist cell the
    least-squares ``C(f)`` gives the expected residual
    ``sum_m P_m - sum_m |H_m|^2 P_m / sum_m |H_m|^2`` over the aliases
    ``f + m/d`` (``P`` von Karman PSD, ``|H|^2 = exp(-2 pi^2 f^2 / a)`` for
    ``h = exp(-a r^2)``, ``a = ln(1/coupling) / d^2``). Returns
    ``sigma^2 / (d/r0)^(5/3)``, r0 = 1 m.
    """
    a = np.log(1 / coupling) / pitch_m**2
    u = ((np.arange(n_cell) + 0.5) / n_cell - 0.5) / pitch_m
    fx, fy = np.meshgrid(u, u, indexing="ij")
    total = fitted = weight = 0.0
    for mx in range(-n_alias, n_alias + 1):
        for my in range(-n_alias, n_alias + 1):
            f2 = (fx + mx / pitch_m) ** 2 + (fy + my / pitch_m) ** 2
            psd = von_karman_psd(np.sqrt(f2), 1.0, OUTER_SCALE_M)
            transfer = np.exp(-2 * np.pi**2 * f2 / a)
            total, fitted, weight = total + psd, fitted + transfer * psd, weight + transfer
    variance = np.mean(total - fitted / weight) / pitch_m**2  # cell area 1/d^2
    return variance / pitch_m ** (5 / 3)


def fft_screens(n: int, dx_m: float, rng: np.random.Generator):
    """Two independent von Karman screens [rad, r0 = 1 m] (real and imaginary parts
    of one FFT screen, McGlamery 1976), each (n, n)."""
    f = np.fft.fftfreq(n, dx_m)
    amplitude = np.sqrt(von_karman_psd(np.hypot(f[:, None], f[None, :]), 1.0, OUTER_SCALE_M)) / (n * dx_m)
    amplitude[0, 0] = 0.0
    noise = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    screen = np.fft.ifft2(noise * amplitude) * n * n
    return screen.real, screen.imag


def measure_kappas(telescope: Telescope, orders) -> dict:
    """kappa = sigma^2 / (d/r0)^(5/3) for each order over 48 pupils of common screens
    (the same random numbers for any telescope: screens sampled D / SAMPLES_ACROSS)."""
    grid, mask, points = pupil_points(telescope, telescope.diameter_m / SAMPLES_ACROSS)
    remover = TiltRemover(points[:, 0], points[:, 1])
    mirrors = {n: DeformableMirror(telescope, n) for n in orders}
    fits = {n: (dm.influence_matrix(points[:, 0], points[:, 1]), dm.fit_matrix(points)) for n, dm in mirrors.items()}
    rng = np.random.default_rng(2024)
    n_pix, kappas = grid.n_pix, {n: [] for n in orders}
    for _ in range(6):
        for screen in fft_screens(512, grid.dx_m, rng):
            for y0 in (0, 512 - n_pix):
                for x0 in (0, 512 - n_pix):
                    phase = screen[y0 : y0 + n_pix, x0 : x0 + n_pix][mask]
                    for n, (h, fit) in fits.items():
                        residual = remover.residual((phase - h @ (fit @ phase)).astype(np.float32))
                        kappas[n].append(np.mean(residual.astype(float) ** 2) / mirrors[n].pitch_m ** (5 / 3))
    return {n: np.array(values) for n, values in kappas.items()}


@pytest.fixture(scope="module")
def fitting_errors():
    """kappa for each order of ORDERS on the 4.2 m telescope."""
    return measure_kappas(TELESCOPE, ORDERS)


def test_lattice_theory_is_in_the_published_range():
    """The infinite-lattice kappa of a 30 %-coupling Gaussian DM, 0.237, lies in the
    published 0.23-0.30 for continuous facesheets (Hudgin 1977; Rigaut et al. 1998);
    a sharper cut-off of the quadrature changes it by < 1 %."""
    kappa = lattice_kappa(0.3, 0.2625)
    assert 0.23 < kappa < 0.30
    assert lattice_kappa(0.3, 0.2625, n_alias=16) == pytest.approx(kappa, rel=0.01)


def test_fitting_error_approaches_the_lattice_theory(fitting_errors):
    """sigma^2 = kappa (d/r0)^(5/3) over the annular pupil (piston/tip/tilt removed).

    The actuators on and beyond the pupil edge fit the edge better than an
    infinite lattice would (the fitted region has more actuators than cells:
    25/11.5, 77/46, 252/185 for 5, 9, 17), so the measured kappa lies below the
    lattice value and approaches it as the edge band (width ~ d) shrinks.
    Measured (48 pupils): 0.164, 0.186, 0.210 against 0.237 (and 0.218 for
    33x33 in a separate run, not repeated here); Monte-Carlo standard errors
    2.9 %, 1.4 %, 0.7 %. The screen holds no power beyond its Nyquist
    frequency: (dx/d)^(5/3) <= 1.6 % low at 17x17.
    """
    kappa_lattice = lattice_kappa(0.3, TELESCOPE.diameter_m / 16)
    means = {n: values.mean() for n, values in fitting_errors.items()}
    errors = {n: values.std(ddof=1) / np.sqrt(values.size) for n, values in fitting_errors.items()}
    for n in ORDERS:
        assert errors[n] < 0.04 * means[n]
    assert means[5] < means[9] < means[17] < kappa_lattice
    assert means[17] > 0.82 * kappa_lattice
    assert means[9] > 0.72 * kappa_lattice


def test_fitting_error_scales_as_pitch_to_the_five_thirds(fitting_errors):
    """sigma^2(d1) / sigma^2(d2) = (d1/d2)^(5/3) to 20 %: the ratio of the kappas
    measured on the same screens is 0.88 (5 vs 9) and 0.88 (9 vs 17). The
    12 % departure is the edge effect above (systematic); the Monte-Carlo
    error of a ratio is <= 3.2 % (1 sigma, standard errors above), so 20 %
    covers the edge effect plus 2.5 sigma."""
    means = {n: values.mean() for n, values in fitting_errors.items()}
    for coarse, fine in ((5, 9), (9, 17)):
        d_ratio = (TELESCOPE.diameter_m / (coarse - 1)) / (TELESCOPE.diameter_m / (fine - 1))
        sigma2_ratio = (
            means[coarse]
            * (TELESCOPE.diameter_m / (coarse - 1)) ** (5 / 3)
            / (means[fine] * (TELESCOPE.diameter_m / (fine - 1)) ** (5 / 3))
        )
        assert sigma2_ratio == pytest.approx(d_ratio ** (5 / 3), rel=0.2)


def test_fitting_error_at_the_orders_of_each_diameter(fitting_errors):
    """The DMs the study derives for 2.5 m and 8.2 m at a 0.525 m pitch (studyspec/scaling.py):
    6x6 (d = 0.5 m) and 17x17 (d = 0.5125 m), obscuration 2/7 D. sigma^2 = kappa (d/r0)^(5/3)
    with kappa independent of the pitch: the 17x17 on 8.2 m is the 17x17 on 4.2 m scaled by
    1.95 (same geometry, the same random numbers), so its kappa equals the 4.2 m one but for
    the fixed 20 m outer scale (< 1 %; measured 0.2089 against 0.2096, ratio 0.997); the 6x6 has a wider edge band
    than 9x9 and a narrower one than 5x5, so its kappa lies between theirs, below the lattice
    value at its pitch (measured 0.167 between 0.164 and 0.186, lattice 0.237)."""
    from luckyao.studyspec.scaling import subapertures_across

    means = {n: values.mean() for n, values in fitting_errors.items()}
    orders = {}
    for diameter_m, obscuration_m in ((2.5, 0.714), (8.2, 2.343)):
        n_actuators = subapertures_across(diameter_m, 0.525) + 1
        kappas = measure_kappas(Telescope(diameter_m, obscuration_m), (n_actuators,))[n_actuators]
        assert kappas.std(ddof=1) / np.sqrt(kappas.size) < 0.03 * kappas.mean()
        orders[n_actuators] = kappas.mean(), diameter_m / (n_actuators - 1)
    assert sorted(orders) == [6, 17]
    kappa_6, pitch_6 = orders[6]
    assert means[5] < kappa_6 < means[9] < lattice_kappa(0.3, pitch_6)
    kappa_17, _ = orders[17]
    assert kappa_17 == pytest.approx(means[17], rel=0.02)


def tilt_coefficients(points, values):
    """Least-squares piston, tip, tilt (float64) of values at points."""
    basis = np.stack([np.ones(len(points)), points[:, 0], points[:, 1]], axis=1)
    return np.linalg.lstsq(basis, values, rcond=None)[0]


@pytest.mark.parametrize("n_actuators", ORDERS)
def test_fitted_surface_has_no_tip_tilt(n_actuators):
    """A phase with a large tilt (10x its rms) gives a surface with zero least-squares
    piston/tip/tilt over the points, to float64 round-off."""
    dm = DeformableMirror(TELESCOPE, n_actuators)
    _, _, points = pupil_points(TELESCOPE, dm.pitch_m / 6)
    rng = np.random.default_rng(n_actuators)
    bumps = DeformableMirror(TELESCOPE, 2 * n_actuators - 1).influence_matrix(*points.T)
    structure = bumps @ rng.standard_normal(bumps.shape[1]) * 1e-7
    phase = structure + 10 * structure.std() * (points[:, 0] - 0.5 * points[:, 1]) / 4.2 + 3e-7
    surface = dm.influence_matrix(*points.T) @ (dm.fit_matrix(points) @ phase)
    piston, tip, tilt = tilt_coefficients(points, surface)
    scale = phase.std()
    assert abs(piston) < 1e-12 * scale
    assert abs(tip) * TELESCOPE.diameter_m < 1e-12 * scale
    assert abs(tilt) * TELESCOPE.diameter_m < 1e-12 * scale
    assert surface.std() > 0.3 * structure.std()  # the fit did something


def test_surface_the_mirror_can_make_is_recovered_exactly():
    """A sum of the DM's own influence functions with no piston/tip/tilt is fitted
    back to the same commands."""
    dm = DeformableMirror(TELESCOPE, 9)
    _, _, points = pupil_points(TELESCOPE, dm.pitch_m / 4)
    h = dm.influence_matrix(*points.T)
    rng = np.random.default_rng(1)
    commands = rng.standard_normal(dm.n_valid) * 1e-7
    moments = np.stack([np.ones(len(points)), *points.T]) @ h  # (3, n_valid): B^T H
    commands -= moments.T @ np.linalg.solve(moments @ moments.T, moments @ commands)
    surface = h @ commands
    assert np.abs(tilt_coefficients(points, surface)).max() < 1e-12 * surface.std()
    fitted = dm.fit_matrix(points) @ surface
    np.testing.assert_allclose(fitted, commands, atol=1e-9 * np.abs(commands).max())
    np.testing.assert_allclose(h @ fitted, surface, atol=1e-9 * np.abs(surface).max())


def test_valid_actuators():
    """9x9: the 4 corner actuators (their only cell lies outside the 4.2 m circle)
    are excluded, 77 kept; 5x5 keeps all 25; 17x17 keeps 252 (corners and the 5
    central actuators, whose cells lie inside the 1.2 m obscuration, excluded).
    Every kept actuator has pupil within one pitch."""
    counts = {n: DeformableMirror(TELESCOPE, n).n_valid for n in ORDERS}
    assert counts == {5: 25, 9: 77, 17: 252}
    dm9 = DeformableMirror(TELESCOPE, 9)
    assert not dm9.valid[0, 0] and not dm9.valid[-1, -1] and dm9.valid[0, 1] and dm9.valid[4, 4]
    for n in ORDERS:
        dm = DeformableMirror(TELESCOPE, n)
        _, _, points = pupil_points(TELESCOPE, dm.pitch_m / 20)
        nearest = np.sqrt(((dm.actuator_xy_m[:, None] - points[None]) ** 2).sum(-1)).min(axis=1)
        assert nearest.max() < dm.pitch_m * np.sqrt(2)
        assert np.allclose(dm.influence_matrix(*dm.actuator_xy_m.T).diagonal(), 1.0)
    neighbour = dm9.influence_matrix(*(dm9.actuator_xy_m[:1] + [dm9.pitch_m, 0]).T)
    assert neighbour[0, 0] == pytest.approx(0.3)


def test_rejects_unknown_influence():
    with pytest.raises(ValueError):
        DeformableMirror(TELESCOPE, 9, influence="pyramid")


def test_grid_surface_is_the_influence_functions_summed():
    """The separable surface on a pupil grid equals H c from the influence matrix
    (the Gaussian factors into x and y), for every order, to float64 rounding."""
    grid = TELESCOPE.grid_for(TELESCOPE.diameter_m / 108)
    mask = TELESCOPE.mask(grid)
    x_m, y_m = grid.xy_m
    for n in (5, 9, 17):
        dm = DeformableMirror(TELESCOPE, n)
        commands = np.random.default_rng(n).normal(0.0, 1e-6, dm.n_valid)
        expected = dm.influence_matrix(x_m[mask], y_m[mask]) @ commands
        np.testing.assert_allclose(dm.grid_surface(grid, mask)(commands), expected, rtol=0, atol=1e-20)
