"""Layer-space tomography (luckyao.layer_tomography): its operators, prior, preconditioner and
solver against independent expectations, its estimate against the dense slope-space path on
the known layered phase of tests/test_tomography.py, and ``tomography.method: iterative`` in the
time loop against the dense path on the same screens, with the key's config handling."""

import re

import numpy as np
import pytest
import scipy.sparse.linalg
import test_ao_loop as loop  # the default system's time loop and its screens
import test_tomography as known  # the known layered phase of the dense tests

from luckyao.ao.control import command_matrix
from luckyao.ao.dm import DeformableMirror
from luckyao.io.datasets import provenance, write_dataset
from luckyao.layer_tomography.assembly import DEFAULT_WARM_RTOL, build_tomography
from luckyao.layer_tomography.operators import bilinear_matrix
from luckyao.layer_tomography.prior import von_karman_psd_m2
from luckyao.layer_tomography.projection import DmProjection, LineOfSight
from luckyao.layer_tomography.solver import pcg
from luckyao.optics.pupil import Telescope, TiltRemover
from luckyao.steps.lgs_slopes import RecordedSlopes, measure_lgs_slopes
from luckyao.steps.simulation import TimeLoop
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import lgs_chain_config, turbulence_spec
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, validate_study
from luckyao.studyspec.view import resolve_study
from luckyao.tomography.prior import TurbulencePrior
from luckyao.tomography.reconstructor import pupil_points
from luckyao.tomography.slopes import SlopeGeometry
from luckyao.wfs.beacons import LgsConfig
from luckyao.wfs.shack_hartmann import ShackHartmann

PRIOR = TurbulencePrior(0.135, 20.0, (0.0, known.TRUE_HEIGHT_M, 9000.0), (1 / 3, 1 / 3, 1 / 3))
LGS = LgsConfig.rayleigh()


def small_tomography(samples_per_subaperture=2, prior=PRIOR, dtype=np.float64, **kwargs):
    wfs = ShackHartmann(Telescope(2.1, 0.6), 4, 532e-9)
    return build_tomography(
        prior,
        wfs,
        LGS.directions_rad,
        LGS.height_m,
        0.02 * 4.85e-6,
        samples_per_subaperture=samples_per_subaperture,
        dtype=dtype,
        **kwargs,
    )


@pytest.mark.parametrize("samples", [1, 2])
def test_measurement_operator_adjoint_and_sparse_matrix(samples):
    """``<H x, s> = <x, H^T s>`` (the stencils' adjoint) and the stencils equal the sparse
    bilinear ray tracing of the same rays; a flat layer gives no slope, a tilted ground layer
    gives its gradient (before the tilt removal) on every sub-aperture."""
    tomo = small_tomography(samples)
    op, rng = tomo.operator, np.random.default_rng(0)
    x = rng.normal(size=op.grids.shape)
    s = rng.normal(size=(len(op.beacons), 2, op.gradient.n_valid))
    np.testing.assert_allclose(np.vdot(op.forward(x), s), np.vdot(x, op.adjoint(s)), rtol=1e-12)
    np.testing.assert_allclose(op.matrix() @ x.ravel(), op.forward(x).ravel(), atol=1e-12)
    np.testing.assert_allclose(op.forward(np.ones(op.grids.shape)), 0, atol=1e-12)
    columns = np.arange(op.grids.n) * op.grids.pitches_m[0]
    tilted = np.zeros(op.grids.shape)
    tilted[0] = 3e-7 * columns[None, :]  # 3e-7 m per m along x on the ground layer
    beacon = op.beacons[0]
    raw = op.gradient.forward(beacon.forward(tilted))
    np.testing.assert_allclose(raw[0], 3e-7, rtol=1e-9)
    np.testing.assert_allclose(raw[1], 0, atol=1e-15)


def test_bilinear_matrix_interpolates_and_refuses_rays_off_the_grid():
    grid = np.arange(16.0).reshape(4, 4)  # value = 4 row + column: bilinear is exact
    m = bilinear_matrix([0.5, 2.25], [1.0, 2.75], 4)
    np.testing.assert_allclose(m @ grid.ravel(), [4 * 1.0 + 0.5, 4 * 2.75 + 2.25])
    with pytest.raises(ValueError, match="leaves the layer grid"):
        bilinear_matrix([3.5], [0.0], 4)


def test_prior_spectrum_is_k_minus_4_matched_to_von_karman():
    """The prior's action on a plane wave in the grid's interior: its implied power spectrum
    ``Delta^2 / (C^-1 symbol)`` equals von Karman's at the match frequency once the 5-point
    Laplacian's response ``sinc^2(pi k Delta)`` (squared) is divided out, and falls as ``k^-4`` well
    above ``1 / L0`` (L0 = 1 km here): halving the frequency multiplies it by 16 (less 1.2 % of
    discretisation at ``k_match / 4``), not von Karman's 2^(11/3) = 12.7."""
    prior_vk = TurbulencePrior(0.135, 1000.0, PRIOR.heights_m, PRIOR.cn2_fractions)
    tomo = small_tomography(prior=prior_vk)
    grids, prior = tomo.operator.grids, tomo.prior
    n, layer = grids.n, 1
    pitch = grids.pitches_m[layer]
    rows, columns = np.mgrid[0:n, 0:n]

    def implied_psd(k_per_m):
        wave = np.zeros(grids.shape)
        wave[layer] = np.cos(2 * np.pi * k_per_m * pitch * columns)
        ratio = prior.apply(wave)[layer, n // 2, n // 2 - 3 : n // 2 + 3] / wave[layer, n // 2, n // 2 - 3 : n // 2 + 3]
        return pitch**2 / np.median(ratio)

    k = prior.match_frequency_per_m
    expected = von_karman_psd_m2(k, 0.135, 1000.0, prior_vk.wavelength_m) * prior_vk.cn2_fractions[layer]
    discretisation = np.sinc(k * pitch) ** 4  # np.sinc(x) = sin(pi x) / (pi x)
    assert implied_psd(k) * discretisation / expected == pytest.approx(1, rel=1e-6)
    assert implied_psd(k / 8) / implied_psd(k / 4) == pytest.approx(16, rel=0.02)


def test_preconditioner_is_the_operator_in_fourier_space():
    """Fried geometry (one sample per sub-aperture), one layer at the ground, one beacon: in the
    pupil's interior the normal operator acts on a plane wave as the preconditioner's symbol says
    (the FDPCG approximation is exact there; it ignores only the edges)."""
    prior = TurbulencePrior(0.135, 20.0, (0.0,), (1.0,))
    wfs = ShackHartmann(Telescope(4.2, 0.0), 8, 532e-9)
    tomo = build_tomography(prior, wfs, [[0.0, 0.0]], LGS.height_m, 1e-7, samples_per_subaperture=1, dtype=np.float64)
    n = tomo.operator.grids.n
    rows, columns = np.mgrid[0:n, 0:n]
    for ix, iy in ((3, 0), (5, 2)):
        wave = np.cos(2 * np.pi * (ix * columns + iy * rows) / n)[None]
        centre = (
            tomo.normal(wave)[0, n // 2 - 1 : n // 2 + 2, n // 2 - 1 : n // 2 + 2]
            / wave[0, n // 2 - 1 : n // 2 + 2, n // 2 - 1 : n // 2 + 2]
        )
        np.testing.assert_allclose(centre, 1 / tomo.preconditioner.inverse[iy, ix, 0, 0].real, rtol=1e-6)


def test_preconditioned_spectrum_is_bounded_above():
    """The largest eigenvalue of ``M^-1 A`` (power iteration on a small system) stays near 1: the
    preconditioner never under-estimates the operator much. Measured 1.93 (the slopes' two-sample
    stride); with a prior zero beyond the grid's edge instead of periodic, 2.8e4 (the layers' piston)."""
    tomo = small_tomography()
    vector = np.random.default_rng(5).normal(size=tomo.operator.grids.shape)
    for _ in range(300):
        vector = tomo.preconditioner.apply(tomo.normal(vector))
        largest = np.linalg.norm(vector)
        vector /= largest
    assert 1.0 < largest < 2.5


def test_pcg_converges_to_the_direct_sparse_solve():
    """On a small system the preconditioned, warm-startable PCG reaches scipy's sparse direct
    solution of the same normal equations, ``H^T N^-1 H + C^-1`` assembled as sparse matrices."""
    tomo = small_tomography()
    op, rng = tomo.operator, np.random.default_rng(3)
    slopes = op.forward(rng.normal(size=op.grids.shape) * 1e-7) + 1e-7 * rng.normal(
        size=(len(op.beacons), 2, op.gradient.n_valid)
    )
    h = op.matrix()
    a = (h.T @ h) / tomo.noise.variance_rad2 + tomo.prior.matrix()
    direct = scipy.sparse.linalg.spsolve(a.tocsc(), h.T @ slopes.ravel() / tomo.noise.variance_rad2)
    b = tomo.right_hand_side(slopes)
    result = pcg(tomo.normal, b, np.zeros_like(b), tomo.preconditioner.apply, 1e-10, 20000)
    assert result.relative_residual <= 1e-10
    np.testing.assert_allclose(result.solution.ravel(), direct, rtol=0, atol=1e-6 * np.abs(direct).max())
    warm = pcg(tomo.normal, b, result.solution, tomo.preconditioner.apply, 1e-10, 20000)
    assert warm.iterations == 0


def test_warm_started_solves_stop_at_the_warm_tolerance():
    """The first exposure (cold) is solved to ``rtol``, the next (from the previous solution) to
    ``warm_rtol``: fewer iterations than to ``rtol``, a residual between the two."""
    tomo = small_tomography(rtol=1e-8, warm_rtol=1e-3)
    op, rng = tomo.operator, np.random.default_rng(4)
    slopes = [op.forward(rng.normal(size=op.grids.shape) * 1e-7) for _ in range(2)]
    tomo.estimate(slopes[0])
    previous = tomo._previous
    b = tomo.right_hand_side(slopes[1])
    warm = tomo.estimate(slopes[1])
    residual = np.linalg.norm(b - tomo.normal(warm)) / np.linalg.norm(b)
    assert 1e-8 < residual <= 1.01e-3
    tight = pcg(tomo.normal, b, previous, tomo.preconditioner.apply, 1e-8, 200)
    assert tomo.iterations[1] < tight.iterations / 2


def on_axis_error(prior, n_beacons):
    directions = LgsConfig(n_beacons=n_beacons).directions_rad
    tomo = build_tomography(prior, known.WFS, directions, LGS.height_m, known.NOISE_RAD, rtol=1e-4)
    tomo.max_iterations = 2000
    estimate = LineOfSight.build(tomo.operator.grids, known.POINTS).path_m(
        tomo.estimate(known.geometric_slopes(directions))
    )
    return np.sqrt(np.mean((estimate - known.TRUTH) ** 2) / np.mean(known.TRUTH**2))


def test_error_falls_as_beacons_are_added():
    """As tests/test_tomography.py's dense test, on the same known layer at 4.5 km (8x8 WFS, Rayleigh
    LGS): with 4 beacons most of the tilt-removed variance is recovered (dense: 0.18, here 0.21)."""
    errors = [on_axis_error(PRIOR, n) for n in (1, 2, 4)]
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.3


def test_phase_is_recovered_at_the_right_height():
    """With single-layer priors at trial heights the known layer is best explained at its height."""
    errors = {
        h: on_axis_error(TurbulencePrior(known.LAYER_R0_M, 20.0, (h,), (1.0,)), 4)
        for h in (0.0, 2250.0, known.TRUE_HEIGHT_M, 9000.0)
    }
    best = errors.pop(known.TRUE_HEIGHT_M)
    assert best < 0.35
    assert all(best < 0.6 * other for other in errors.values())


@pytest.mark.parametrize("diameter_m, n_sub", [(4.2, 8), (8.2, 16)])
def test_dm_corrected_residual_agrees_with_the_dense_path(diameter_m, n_sub, monkeypatch):
    """The same slopes (the known 4.5 km layer seen by the 4 Rayleigh LGS) through the dense command
    matrix and through the layer tomography then the DM fit: the tilt-removed residual of the
    DM-corrected layer on axis. Measured: 1.037 and 1.054 times the dense residual at the default
    tolerance (3e-4), 1.039 and 1.041 converged (1e-6); asserted within 5 % converged and 7 % at
    the default. Not the 2 % aimed at: the bi-harmonic prior is not von Karman's covariance (a
    spectrum k^(1/3) steeper) and the layers are bilinear at half the sub-aperture pitch."""
    telescope = Telescope(diameter_m, round(diameter_m * 2 / 7, 3))
    wfs = ShackHartmann(telescope, n_sub, LGS.wavelength_m)
    monkeypatch.setattr(known, "WFS", wfs)
    slopes = known.geometric_slopes(LGS.directions_rad)
    dm = DeformableMirror(telescope, n_sub + 1)
    points = pupil_points(telescope, wfs.subaperture_m / 4)[2]
    tilt = TiltRemover(*points.T)
    truth = tilt.residual(known.screen_at(*points.T))
    influence = dm.influence_matrix(points[:, 0], points[:, 1])
    noise = 2 * known.NOISE_RAD
    geometry = SlopeGeometry(wfs.subaperture_xy_m, wfs.subaperture_m, LGS.directions_rad, LGS.height_m)
    dense = command_matrix(PRIOR, geometry, noise, dm, "ltao") @ slopes.ravel().astype(np.float32)

    def residual(commands):
        return np.sqrt(np.mean(tilt.residual(truth - influence @ commands) ** 2))

    assert residual(dense) < 0.3 * np.sqrt(np.mean(truth**2))  # the correction is real
    for rtol, tolerance in ((None, 0.07), (1e-6, 0.05)):
        tomo = build_tomography(PRIOR, wfs, LGS.directions_rad, LGS.height_m, noise, **({"rtol": rtol} if rtol else {}))
        tomo.max_iterations = 2000
        iterative = DmProjection.build(tomo.operator.grids, dm, "ltao").commands(tomo.estimate(slopes))
        assert residual(iterative) < (1 + tolerance) * residual(dense)


LOOP_S = 0.1  # 10 lucky frames, 20 WFS exposures
ITERATIVE = {"tomography": {"method": "iterative"}}
SHIPPED = {  # tests/test_resolved.py's pins of the default study's ltao_r0_15cm
    "config_sha256": "4723f51791c76f9b",
    "reconstructor": "reconstructor_22060f27bd2e",
    "slopes": "slopes_ca254bcc5dc5",
}


def _keys(study: dict, name: str) -> dict:
    case = resolve_study(study, validate_study(study)).cases[name]
    return {
        "config_sha256": case.config_sha256[:16],
        "reconstructor": case.reconstructor and case.reconstructor.key,
        "commands": case.commands and case.commands.key,
        "slopes": case.slopes and case.slopes.key,
    }


@pytest.fixture(scope="module")
def default_study():
    return load_study("config/config.yaml")[0]


def test_dense_spelled_out_keeps_every_key(default_study):
    """``tomography.method: dense`` (the default) and the iterative tolerance, spelled out, leave the
    resolved case as it was: the same config hash and product keys as the shipped study's."""
    shipped = _keys(default_study, "ltao_r0_15cm")
    assert {k: shipped[k] for k in SHIPPED} == SHIPPED
    spelled = deep_merge(default_study, {"base": {"tomography": {"method": "dense", "iterative_rtol": 1e-3}}})
    assert _keys(spelled, "ltao_r0_15cm") == shipped
    assert Case.from_config(validate_study(spelled)["ltao_r0_15cm"]).tomography.method == "dense"


def test_iterative_case_has_no_dense_products_and_shares_the_slopes(default_study):
    """An iterative case builds no reconstructor or command matrix (the simulation makes its layer
    tomography), replays the same LGS slopes as its dense twin, and a dense no-AO case does not take
    its lgs_rms from it (they estimate it differently)."""
    study = deep_merge(default_study, {"cases": {"ltao_r0_15cm": {"tomography": {"method": "iterative"}}}})
    iterative, dense = _keys(study, "ltao_r0_15cm"), _keys(default_study, "ltao_r0_15cm")
    assert iterative["reconstructor"] is None and iterative["commands"] is None
    assert iterative["slopes"] == dense["slopes"] and iterative["config_sha256"] != dense["config_sha256"]
    assert resolve_study(study, validate_study(study)).cases["noao_r0_15cm"].lgs_twin != "ltao_r0_15cm"
    case = Case.from_config(validate_study(study)["ltao_r0_15cm"])
    assert case.tomography.iterative and case.tomography.iterative_rtol == DEFAULT_WARM_RTOL


@pytest.mark.parametrize(
    "override, key",
    [
        ({"tomography": {"method": "cg"}}, "tomography.method"),
        ({"tomography": {"method": "iterative", "iterative_rtol": 0}}, "tomography.iterative_rtol"),
        ({**ITERATIVE, "ao": {"residual_budget": True}}, "ao.residual_budget"),
        ({**ITERATIVE, "ao": {"laser_criteria": True}}, "ao.laser_criteria"),
        ({**ITERATIVE, "ao": {"apodisation": {"driver": "lgs", "blocked_fraction": 0.1}}}, "ao.apodisation.driver"),
    ],
)
def test_bad_iterative_settings_name_their_key(default_study, override, key):
    """A bad method or tolerance, or what needs the dense matrices with the iterative method: a
    config error naming the key."""
    study = deep_merge(default_study, {"cases": {"ltao_r0_15cm": override}})
    with pytest.raises(ConfigError, match=re.escape(f"'cases.ltao_r0_15cm.{key}'")):
        validate_study(study)


@pytest.fixture(scope="module")
def loop_runs(default_study, tmp_path_factory):
    """The default LTAO system (9 layers, 4 Rayleigh LGS, 8x8 WFS, 9x9 DM, on axis) over
    :data:`LOOP_S` on the same screens and sensor slopes: dense (the command matrix and
    reconstructors), dense spelled out, and ``tomography.method: iterative`` through the same
    :class:`luckyao.steps.simulation.TimeLoop` (its layer tomography built there)."""
    _, cases = load_study("config/config.yaml")
    base = dict(cases["ltao_r0_13.5cm"], duration_s=LOOP_S)
    spec = dict(turbulence_spec(default_study, base), duration_s=LOOP_S + 0.05, max_pixel_m=loop.PIXEL_M)
    setup = loop._Setup(base, loop._screens(spec, 5))
    cfg = setup.config(mode="ltao")
    runs = {"dense": setup.simulate(cfg, setup.commands("ltao"))}
    spelled = deep_merge(cfg, {"tomography": {"method": "dense"}})
    runs["spelled"] = setup.simulate(spelled, setup.commands("ltao"))
    iterative_cfg = deep_merge(cfg, ITERATIVE)
    iterative = TimeLoop(Case.from_config(iterative_cfg), setup.screens, 5)
    runs["iterative"] = iterative.run(lambda start, frames: None)
    runs["iterations"] = iterative.estimator.tomography.iterations
    # as the workflow runs it: the slopes product of the dense case's LGS chain, replayed
    path = tmp_path_factory.mktemp("slopes") / "slopes.nc"
    spec = {"seed": 5, "screens": "loop", "case": lgs_chain_config(cfg)}
    product = measure_lgs_slopes(spec, setup.screens, None)
    product.attrs.update(provenance("slopes", spec, 5))
    write_dataset(product, path, compress=False)
    slopes = RecordedSlopes.open(path, iterative_cfg, 5)
    runs["replayed"] = TimeLoop(Case.from_config(iterative_cfg), setup.screens, 5, slopes=slopes).run(
        lambda start, frames: None
    )
    return runs


def test_iterative_case_replays_its_dense_twins_slopes(loop_runs):
    """The iterative case accepts the slopes product measured for its dense twin's LGS chain (the
    workflow's path) and replaying it gives the telemetry of measuring the slopes in its own loop."""
    assert loop_runs["replayed"].identical(loop_runs["iterative"])


def test_dense_path_is_unchanged_by_the_key(loop_runs):
    """The default is dense: spelling it out changes no number of the telemetry."""
    for name in ("true_rms_nm", "lgs_rms_nm", "lgs_residual_rms_nm", "dm_commands_m", "axis_strehl"):
        np.testing.assert_array_equal(loop_runs["spelled"][name].values, loop_runs["dense"][name].values)


def test_time_loop_residual_agrees_with_the_dense_path(loop_runs):
    """``tomography.method: iterative`` against dense, on the same screens and slopes: the mean
    corrected tilt-removed rms on axis within 2 % (docs/methods/layer-tomography.md: 174.2 nm against
    the dense 176.6 over this test's 0.1 s, 0.986), every exposure through the layer tomography."""
    dense, iterative = (loop_runs[k].true_rms_nm.values[0] for k in ("dense", "iterative"))
    print(f"dense {dense.mean():.1f} nm, layer {iterative.mean():.1f} nm, {np.mean(loop_runs['iterations']):.0f} its")
    assert len(loop_runs["iterations"]) == 2 * len(dense)
    assert iterative.mean() == pytest.approx(dense.mean(), rel=0.02)
    assert not np.array_equal(iterative, dense)  # the layer tomography did correct, not the dense matrix


def test_lgs_rms_agrees_with_the_dense_reconstructors(loop_runs):
    """The iterative ``lgs_rms`` (the layer estimate along the target, tilt removed, at the dense
    reconstructors' points) against the dense reconstructors' from the same slopes: frame by frame
    a near-constant ratio (correlation above 0.98, what selection ranks by) and the mean within
    10 %. Measured: 415.5 nm against 384.2 (1.081, every frame 1.07-1.09), correlation 0.992. The
    layer estimate holds more of the phase above the WFS's Nyquist frequency than the dense one
    (bilinear layers at half the sub-aperture, the bi-harmonic prior's extrapolation), which the
    corrected residual, fitted onto the DM, does not see (the test above: 1.4 % lower)."""
    dense, iterative = (loop_runs[k].lgs_rms_nm.values[0] for k in ("dense", "iterative"))
    print(f"lgs_rms: dense {dense.mean():.1f} nm, layer {iterative.mean():.1f} nm")
    assert np.corrcoef(dense, iterative)[0, 1] > 0.98
    assert iterative.mean() == pytest.approx(dense.mean(), rel=0.10)
    residual = [loop_runs[k].lgs_residual_rms_nm.values[0] for k in ("dense", "iterative")]
    print("lgs_residual_rms: dense {:.1f} nm, layer {:.1f} nm".format(*(r.mean() for r in residual)))
    assert np.all(np.isfinite(residual[1])) and np.all(residual[1] < iterative)  # the DM corrects
