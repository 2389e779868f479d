"""The laser-only criteria (ao/laser_criteria.py), the ridge regression (lucky/ridge.py) and the
learned criterion (steps/learned.py) against independent expectations."""

import json

import numpy as np
import pytest
import scipy.linalg
import test_tomography
import xarray as xr
import yaml
from test_ao_loop import _screens, _Setup
from test_tomography import LGS, NOISE_RAD, POINTS, TELESCOPE, WFS, geometric_slopes

import luckyao
from luckyao.ao.control import ground_layers
from luckyao.ao.dm import DeformableMirror
from luckyao.ao.laser_criteria import FRAME_CRITERIA, TARGET_CRITERIA, LaserCriteria, dm_residual_projector
from luckyao.io.hashing import sha256
from luckyao.jobs.resources import partial_sums_bytes
from luckyao.lucky.ridge import LAMBDAS, cross_validated_ridge, fit_ridge
from luckyao.optics.pupil import TiltRemover
from luckyao.steps.learned import FEATURES, learned_rms_nm, train_model
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import (
    commands_key,
    commands_spec,
    lgs_spec,
    reconstructor_key,
    reconstructor_spec,
    slopes_key,
    slopes_spec,
    turbulence_spec,
)
from luckyao.studyspec.resolved import criteria_of
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, validate_study
from luckyao.studyspec.view import resolve_study
from luckyao.tomography.prior import TurbulencePrior
from luckyao.tomography.reconstructor import factorize, target_reconstructor
from luckyao.tomography.slopes import SlopeGeometry, slope_covariance

from studies import snakemake, tiny

DM = DeformableMirror(TELESCOPE, 9, 0.3)
INFLUENCE = DM.influence_matrix(POINTS[:, 0], POINTS[:, 1])
TILT = TiltRemover(POINTS[:, 0], POINTS[:, 1])
PRIOR = TurbulencePrior(0.135, 20.0, (0.0, test_tomography.TRUE_HEIGHT_M, 9000.0), (1 / 3, 1 / 3, 1 / 3))


def _tilt_removed_rms(phase: np.ndarray) -> float:
    """Rms over POINTS of ``phase`` less its least-squares piston, tip and tilt (float64)."""
    basis = np.stack([np.ones(len(POINTS)), POINTS[:, 0], POINTS[:, 1]], axis=1)
    return float(np.sqrt(np.mean((phase - basis @ np.linalg.lstsq(basis, phase, rcond=None)[0]) ** 2)))


def test_high_order_part_of_a_dm_shape_vanishes():
    """A surface the DM makes without piston, tip or tilt at the points (commands in the null
    space of ``B^T H``) has no high-order part; a checkerboard at the points' pitch, beyond the
    DM's reach, keeps nearly all of its tilt-removed rms."""
    projector = dm_residual_projector(INFLUENCE, DM.fit_matrix(POINTS))
    basis = np.stack([np.ones(len(POINTS)), POINTS[:, 0], POINTS[:, 1]], axis=1)
    free = scipy.linalg.null_space(basis.T @ INFLUENCE)
    surface = INFLUENCE @ free @ np.random.default_rng(1).normal(size=free.shape[1])
    assert _tilt_removed_rms(projector @ surface) < 1e-8 * _tilt_removed_rms(surface)
    i = np.rint((POINTS - POINTS.min(axis=0)) / (WFS.subaperture_m / 2)).astype(int)
    checkerboard = (-1.0) ** i.sum(axis=1)
    assert _tilt_removed_rms(projector @ checkerboard) > 0.9 * _tilt_removed_rms(checkerboard)


@pytest.fixture(scope="module")
def layer_reconstructors():
    """The on-axis reconstructor of PRIOR, and those of its ground layer and its altitude layers."""
    geometry = SlopeGeometry.from_wfs(WFS, LGS)
    cholesky = factorize(slope_covariance(PRIOR, geometry, NOISE_RAD))
    ground = ground_layers(PRIOR, 100.0)
    altitude = [i for i in range(3) if i not in ground]
    return [
        target_reconstructor(PRIOR, geometry, NOISE_RAD, POINTS, layer_indices=layers, cholesky_lower=cholesky)
        for layers in (None, ground, altitude)
    ]


def test_layer_reconstructors_add_up(layer_reconstructors):
    """Ground plus altitude is the whole reconstruction (the cross covariance sums over layers)."""
    whole, ground, altitude = layer_reconstructors
    np.testing.assert_allclose(ground + altitude, whole, atol=1e-6 * np.abs(whole).max())


@pytest.mark.parametrize("height_m, right", [(0.0, 0), (test_tomography.TRUE_HEIGHT_M, 1)])
def test_a_single_layer_is_reconstructed_in_its_layer(layer_reconstructors, monkeypatch, height_m, right):
    """The slopes of one screen at the ground (at 4.5 km) are mostly reconstructed by the ground
    (altitude) layers' reconstructor: its rms along the axis is at least 1.5 times the other's
    (measured 1.7 and 2.2). A split blind to height would follow the prior, which gives the
    altitude layers twice the ground's Cn2: the ground screen's would favour altitude."""
    monkeypatch.setattr(test_tomography, "TRUE_HEIGHT_M", height_m)
    slopes = geometric_slopes(LGS.directions_rad).reshape(-1).astype(np.float32)
    rms = [float(TILT.rms(r @ slopes)) for r in layer_reconstructors[1:]]
    assert rms[right] > 1.5 * rms[1 - right]


def _criteria(n_slopes: int) -> LaserCriteria:
    """The criteria of one target whose reconstructors are all zero (only the frame's criteria count)."""
    zero = np.zeros((1, len(POINTS), n_slopes))
    return LaserCriteria(zero, np.stack([zero, zero]), INFLUENCE, DM.fit_matrix(POINTS), POINTS, WFS.subaperture_m)


def test_dm_change_vanishes_for_a_frozen_dm():
    """Constant commands: the first frame's change is from the flat DM (the commands' own
    tilt-removed surface), every later one 0; a step in the commands is its surface's rms."""
    criteria = _criteria(4)
    commands = np.random.default_rng(2).normal(size=DM.n_valid) * 1e-7
    slopes = np.zeros((2, 1, 2, 2))
    surface_nm = TILT.rms((INFLUENCE @ commands).astype(np.float32)) * 1e9
    _, first = criteria.frame(slopes, np.stack([commands, commands]))
    assert first[0] == pytest.approx(surface_nm / np.sqrt(2), rel=1e-4)  # one of the frame's 2 exposures moved
    for _ in range(3):
        _, frozen = criteria.frame(slopes, np.stack([commands, commands]))
        assert frozen[0] == 0.0
    _, moved = criteria.frame(slopes, np.stack([2 * commands, 2 * commands]))
    assert moved[0] == pytest.approx(surface_nm / np.sqrt(2), rel=1e-4)


def test_slope_rms_is_the_optical_path_across_a_subaperture():
    """Slopes of +-a [rad] everywhere: the criterion is a d [nm]; the target criteria of zero
    reconstructors are 0."""
    a = 2e-6
    slopes = a * np.where(np.arange(4 * 2 * 5) % 2, 1.0, -1.0).reshape(1, 4, 2, 5)
    per_target, frame = _criteria(40).frame(np.concatenate([slopes, slopes]), np.zeros((2, DM.n_valid)))
    assert frame[1] == pytest.approx(a * WFS.subaperture_m * 1e9, rel=1e-6)
    assert per_target.shape == (len(TARGET_CRITERIA), 1) and np.all(per_target == 0)


def test_ridge_recovers_known_coefficients():
    """y = X b + small noise: the cross-validated fit returns b (in the features' units) and a
    small penalty; on pure noise the penalty chosen is large (the fit shrinks to the mean)."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(600, 4)) * [1.0, 10.0, 0.1, 3.0] + [5.0, -2.0, 0.0, 1.0]
    b = np.array([2.0, -0.3, 15.0, 0.0])
    y = 7.0 + x @ b + rng.normal(scale=0.01, size=600)
    model, errors = cross_validated_ridge(x, y)
    np.testing.assert_allclose(model.raw_coefficients, b, atol=5e-3)
    np.testing.assert_allclose(model.predict(x[:5]), y[:5], atol=0.05)
    assert model.ridge_lambda <= 1e-3 and errors.shape == LAMBDAS.shape
    noise, _ = cross_validated_ridge(x, rng.normal(size=600))
    assert noise.ridge_lambda >= 1.0


def test_ridge_penalty_shrinks():
    """A larger penalty gives smaller coefficients (closed form: (Z^T Z + n lambda I)^-1 Z^T y)."""
    rng = np.random.default_rng(4)
    x = rng.normal(size=(100, 3))
    y = x @ [1.0, 2.0, 3.0]
    norms = [np.linalg.norm(fit_ridge(x, y, lam).coefficients) for lam in (0.0, 1.0, 100.0)]
    assert norms[0] > norms[1] > norms[2] > 0


def _telemetry(config: dict, seed: int, n_frames: int = 400) -> xr.Dataset:
    """A telemetry of the laser features whose true rms is a known linear function of them."""
    rng = np.random.default_rng(seed)
    variables = {}
    for name in FEATURES:
        values = rng.gamma(4.0, 20.0, size=n_frames).astype(np.float32)
        frame_only = name in {n for n, _ in FRAME_CRITERIA}
        variables[f"{name}_nm"] = (
            ("frame",) if frame_only else ("target", "frame"),
            (values if frame_only else values[None]),
        )
    truth = 50.0 + 0.5 * variables["dm_change_rms_nm"][1] + 0.2 * variables["lgs_altitude_rms_nm"][1][0]
    variables["true_rms_nm"] = ("target", "frame"), truth[None]
    attrs = {"config_json": json.dumps(config), "config_sha256": sha256(config), "seed": seed}
    return xr.Dataset(variables, attrs=attrs)


def test_learned_criterion_is_trained_and_scored_on_other_seeds():
    """Trained on one seed's telemetry, the model predicts another seed's truth; scoring the
    training seed's own frames is refused, as is another case's telemetry."""
    config = load_study("config/config.yaml")[1]["ltao_r0_13.5cm"]
    model = train_model(_telemetry(config, 7))
    assert model.attrs["training_seed"] == 7 and list(model["feature"].values) == list(FEATURES)
    scored = _telemetry(config, 2014)
    np.testing.assert_allclose(learned_rms_nm(model, scored, 0), scored["true_rms_nm"].values[0], rtol=1e-3)
    with pytest.raises(ValueError, match="seed 7"):
        learned_rms_nm(model, _telemetry(config, 7), 0)
    with pytest.raises(ValueError, match="another case"):
        learned_rms_nm(model, _telemetry(deep_merge(config, {"duration_s": 5.0}), 2014), 0)


def test_an_intermittent_case_trains_on_its_own_layer_strengths():
    """With intermittent layers the training twin draws the layers' strengths from the training
    seed too (no turbulence history of the scored frames is seen in training), and its model
    scores the case's telemetry."""
    study = deep_merge(
        _study(laser_criteria=True, learned_training_seed=7),
        {"cases": {"ltao_r0_13.5cm": {"atmosphere": {"layer_variability": {"correlation_time_s": 10.0}}}}},
    )
    view = resolve_study(study, validate_study(study))
    case = view.cases["ltao_r0_13.5cm"]
    twin = case.training.config
    assert case.config["atmosphere"]["layer_variability"]["seed"] == study["seed"]
    assert twin["atmosphere"]["layer_variability"]["seed"] == 7
    steps = np.arange(4000)
    assert not np.allclose(
        Case.from_config(twin).layer_scales(steps), Case.from_config(case.config).layer_scales(steps)
    )
    model = train_model(_telemetry(twin, 7))
    scored = _telemetry(case.config, study["seed"])
    np.testing.assert_allclose(learned_rms_nm(model, scored, 0), scored["true_rms_nm"].values[0], rtol=1e-3)
    with pytest.raises(ValueError, match="another case"):
        learned_rms_nm(train_model(_telemetry(case.config, 7)), scored, 0)


def _study(**ao):
    config = load_study("config/config.yaml")[0]
    return deep_merge(config, {"cases": {"ltao_r0_13.5cm": {"ao": ao}}})


def test_config_errors_name_the_key():
    with pytest.raises(ConfigError, match="ao.learned_training_seed.*the study's seed"):
        validate_study(_study(laser_criteria=True, learned_training_seed=2014))
    with pytest.raises(ConfigError, match="ao.learned_training_seed.*needs ao.laser_criteria"):
        validate_study(_study(learned_training_seed=7))
    config = load_study("config/config.yaml")[0]
    config = deep_merge(config, {"cases": {"noao_r0_13.5cm": {"ao": {"laser_criteria": True}}}})
    with pytest.raises(ConfigError, match="noao_r0_13.5cm.ao.laser_criteria"):
        validate_study(config)


def test_criteria_leave_every_product_key_alone():
    """The keys are in no existing case; turned on they change the case's own config hash but
    no shared product (screens, reconstructor, commands, slopes, LGS twin); the training twin has
    screens and slopes of its own seed."""
    default = load_study("config/config.yaml")[0]
    assert all("laser_criteria" not in case.get("ao", {}) for case in default["cases"].values())
    study = _study(laser_criteria=True, learned_training_seed=7)
    cases = validate_study(study)
    plain = validate_study(default)
    on, off = cases["ltao_r0_13.5cm"], plain["ltao_r0_13.5cm"]
    assert commands_key(commands_spec(on)) == commands_key(commands_spec(off))
    assert reconstructor_key(reconstructor_spec(on)) == reconstructor_key(reconstructor_spec(off))
    assert slopes_key(slopes_spec(study, on)) == slopes_key(slopes_spec(default, off))
    assert lgs_spec(on) == lgs_spec(off)
    assert criteria_of(on) - criteria_of(off) == {name for name, _ in TARGET_CRITERIA + FRAME_CRITERIA} | {"learned"}
    view = resolve_study(study, cases)
    twin, case = view.cases["ltao_r0_13.5cm"].training, view.cases["ltao_r0_13.5cm"]
    assert twin.seed == 7 and twin.screens.spec["seed"] == 7 and twin.slopes.spec["seed"] == 7
    assert twin.screens.key != case.screens.key and twin.slopes.key != case.slopes.key
    assert twin.screens.spec["duration_s"] == case.screens.spec["duration_s"]
    assert view.cases["glao_r0_13.5cm"].training is None


@pytest.fixture(scope="module")
def loop():
    """The default LTAO case, 0.1 s, on its own small screens (test_ao_loop's set-up)."""
    config, cases = load_study("config/config.yaml")
    base = deep_merge(cases["ltao_r0_13.5cm"], {"duration_s": 0.1, "camera": {"n_pixels": 64}})
    spec = dict(turbulence_spec(config, base), duration_s=0.15, max_pixel_m=0.0165)
    return _Setup(base, _screens(spec, 11))


def test_time_loop_adds_the_criteria_and_changes_nothing_else(loop):
    """With ao.laser_criteria the telemetry gains the criteria (finite, positive after the first
    frame, ground and altitude both present) and every other variable is bit for bit the same."""
    plain = loop.run("plain", 0.1)
    with_criteria = loop.run("criteria", 0.1, laser_criteria=True)
    for name in plain.data_vars:
        np.testing.assert_array_equal(plain[name].values, with_criteria[name].values, err_msg=name)
    added = set(with_criteria.data_vars) - set(plain.data_vars)
    assert added == {f"{name}_nm" for name, _ in TARGET_CRITERIA + FRAME_CRITERIA}
    for name in added:
        values = with_criteria[name].values
        assert np.all(np.isfinite(values)) and np.all(values[..., 1:] > 0), name


@pytest.mark.workflow
def test_the_workflow_trains_on_the_twin_and_scores_the_case(tmp_path):
    """The tiny study's LTAO case with every criterion: its lucky job ranks by each (the learned
    one from the model the twin's telemetry fitted); the twin ran with the training seed on its
    own screens, and the case's own telemetry is the study seed's. ``luckyao.run_case`` (the LGS
    chain measured in the loop, not replayed) gives the same learned criterion."""
    study = tiny()
    study["cases"]["ltao"]["ao"].update(laser_criteria=True, learned_training_seed=11)
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text(yaml.safe_dump(study))
    result = snakemake(tmp_path, "results/cases/ltao/lucky.nc")
    assert result.returncode == 0, result.stderr[-3000:]
    lucky = xr.open_dataset(tmp_path / "results" / "cases" / "ltao" / "lucky.nc")
    expected = {name for name, _ in TARGET_CRITERIA + FRAME_CRITERIA} | {"learned", "lgs_rms", "true_rms"}
    assert expected <= set(lucky.criterion.values)
    twin = xr.open_dataset(tmp_path / "results" / "training" / "ltao" / "telemetry.nc")
    own = xr.open_dataset(tmp_path / "results" / "cases" / "ltao" / "telemetry.nc")
    assert twin.attrs["seed"] == 11 and own.attrs["seed"] == study["seed"]
    assert twin.attrs["config_sha256"] == own.attrs["config_sha256"]
    assert not np.array_equal(twin["true_rms_nm"].values, own["true_rms_nm"].values)
    model = xr.open_dataset(tmp_path / "results" / "training" / "ltao" / "learned.nc")
    assert model.attrs["training_seed"] == 11
    learned = lucky.frame_criterion.sel(registration="cog", detector="noiseless", criterion="learned").isel(target=0)
    np.testing.assert_allclose(learned.values, learned_rms_nm(model, own, 0), rtol=1e-6)
    alone = luckyao.run_case(study, "ltao", workdir=tmp_path / "alone")
    np.testing.assert_array_equal(
        alone.frame_criterion.sel(registration="cog", detector="noiseless", criterion="learned").isel(target=0),
        learned.values,
    )


def test_lucky_memory_counts_the_criteria():
    """A lucky job's partial sums hold rows per criterion: with the 11 criteria of
    ``ao.laser_criteria`` and ``learned`` its estimate's sums grow as its rows, by more than 2."""
    default = load_study("config/config.yaml")[0]
    off = resolve_study(default, validate_study(default)).cases["glao_r0_13.5cm"]
    ao = {"laser_criteria": True, "learned_training_seed": 7}
    study = deep_merge(default, {"cases": {"glao_r0_13.5cm": {"ao": ao}}})
    on = resolve_study(study, validate_study(study)).cases["glao_r0_13.5cm"]
    sums = [partial_sums_bytes(case.lucky_settings) for case in (on, off)]
    assert 2 < sums[0] / sums[1] < 11 / 5 + 0.01
