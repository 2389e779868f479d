"""The open-loop AO time loop against physics ("Must hold" of the AO issue).

Two shared set-ups (module fixtures, built once):

* ``nine``: the default system (9-layer profile, 4 Rayleigh LGS at 22 km, 8x8
  WFS, 9x9 DM, on-axis target, r0 = 13.5 cm), screens at 0.033 m (as
  ``tests/test_lgs_rms.py``), seed 5.
* ``ground``: one frozen layer at the ground (h = 0) blowing along +x at
  exactly 2 screen samples per 2.5 ms step, and a one-layer prior at the same
  height. At h = 0 every LGS and the science target see the same phase (no
  cone effect, no shift with direction), and a whole-sample frozen flow makes
  "the phase at step k + j" a known integer shift of "the phase at step k".

Every comparison of corrected runs uses the same screens (common random
numbers), so paired differences carry much less Monte-Carlo error than the
means themselves. Standard errors of means over frames use batch means (frames
are correlated over a layer's crossing time, ~0.1 s for the fast layers), so
they are not the naive ``std / sqrt(n_frames)``.
"""

import numpy as np
import pytest

from luckyao.atmosphere.screens import ScreenSet, strip_screen
from luckyao.optics.imaging import Imager
from luckyao.steps import simulation
from luckyao.steps.reconstructor import build_commands, build_reconstructors
from luckyao.steps.screens import TurbulenceSpec, strip_specs
from luckyao.steps.simulation import TimeLoop
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import commands_spec, reconstructor_spec, turbulence_spec
from luckyao.studyspec.schema import deep_merge
from luckyao.studyspec.study import load_study
from luckyao.tomography.reconstructor import pupil_points
from luckyao.units import REFERENCE_WAVELENGTH_M
from luckyao.wfs.sensor import LgsSensor

PIXEL_M = 0.033  # coarse screens, as tests/test_lgs_rms.py
NINE_S = 1.2  # 120 lucky frames on the 9-layer profile
GROUND_S = 0.8


def _screens(spec: dict, seed: int) -> ScreenSet:
    specs = strip_specs(TurbulenceSpec.from_config(spec))
    return ScreenSet.from_screens(
        specs, [strip_screen(s, spec["outer_scale_m"], np.random.default_rng([seed, i])) for i, s in enumerate(specs)]
    )


def _batch_se(x: np.ndarray, n_batches: int = 6) -> float:
    """Standard error of the mean of a correlated series, by batch means."""
    batches = np.array_split(np.asarray(x, dtype=float), n_batches)
    means = np.array([b.mean() for b in batches])
    return float(means.std(ddof=1) / np.sqrt(n_batches))


def _ranks_corr(a, b) -> float:
    return float(np.corrcoef(np.argsort(np.argsort(a)), np.argsort(np.argsort(b)))[0, 1])


class _Setup:
    """Screens, reconstructors and command matrices of one system; runs memoised by name."""

    def __init__(self, base: dict, screens: ScreenSet):
        # the raw centroids (wfs.calibration: none): the loop's properties tested here hold for
        # any slope gain; the calibrated response has its own tests (test_calibration.py)
        self.base, self.screens = deep_merge(base, {"wfs": {"calibration": "none"}}), screens
        self.reconstructors = build_reconstructors(reconstructor_spec(base))["reconstructor"].values
        self._commands, self._runs = {}, {}

    def config(self, **ao) -> dict:
        return deep_merge(self.base, {"ao": ao})

    def commands(self, mode: str):
        if mode not in self._commands:
            c = build_commands(commands_spec(self.config(mode=mode)))
            self._commands[mode] = (c.command_matrix.values, c.dm_slopes.values)
        return self._commands[mode]

    def simulate(self, cfg: dict, commands, frames: list | None = None):
        write = (lambda start, f: None) if frames is None else (lambda start, f: frames.append(f.copy()))
        return TimeLoop(
            Case.from_config(cfg), self.screens, 5, reconstructors=self.reconstructors, commands=commands
        ).run(write)

    def run(self, name: str, duration_s: float, mode: str = "ltao", **ao):
        if name not in self._runs:
            cfg = dict(self.config(mode=mode, **ao), duration_s=duration_s)
            self._runs[name] = self.simulate(cfg, self.commands(mode) if mode != "none" else None)
        return self._runs[name]


@pytest.fixture(scope="module")
def study():
    return load_study("config/config.yaml")


@pytest.fixture(scope="module")
def nine(study):
    config, cases = study
    base = dict(cases["ltao_r0_13.5cm"], duration_s=NINE_S)
    spec = dict(turbulence_spec(config, base), duration_s=NINE_S + 0.05, max_pixel_m=PIXEL_M)
    return _Setup(base, _screens(spec, 5))


@pytest.fixture(scope="module")
def ground(study):
    config, cases = study
    step_s = cases["ltao_r0_13.5cm"]["time_step_s"]
    base = deep_merge(
        cases["ltao_r0_13.5cm"],
        {
            "duration_s": GROUND_S,
            "atmosphere": {
                "height_m": [0.0],
                "cn2_fraction": [1.0],
                "wind_direction_deg": [0.0],
                "wind_speed_m_s": [2 * PIXEL_M / step_s],
            },  # 2 screen samples per step along +x
            "tomography": {"layer_heights_m": [0.0], "layer_cn2_fraction": [1.0]},
            "ao": {"glao_max_height_m": 100.0},
        },
    )
    spec = dict(turbulence_spec(config, base), duration_s=GROUND_S + 0.05, max_pixel_m=PIXEL_M)
    setup = _Setup(base, _screens(spec, 7))
    (s,) = setup.screens.specs
    assert s.major_axis == 0 and s.skew == 0 and abs(s.step_samples[0] - 2) < 1e-9 and s.step_samples[1] == 0
    return setup


def _science_influence(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """DM influence matrix at the science pupil samples [rad at 500 nm per m], and their x, y."""
    imager = Imager(case.telescope, case.camera)
    x, y = imager.grid.xy_m
    x, y = x[imager.mask], y[imager.mask]
    h = case.ao.deformable_mirror(case.telescope).influence_matrix(x, y)
    return h * (2 * np.pi / REFERENCE_WAVELENGTH_M), x, y


def _tip_tilt_fraction(surfaces: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """rms of the least-squares tip/tilt over rms of the piston-removed surface, per surface (rows)."""
    basis = np.stack([np.ones_like(x), x, y], axis=1)
    coef, *_ = np.linalg.lstsq(basis, surfaces.T, rcond=None)
    tt = basis[:, 1:] @ coef[1:]
    tt -= tt.mean(axis=0)
    centred = surfaces.T - surfaces.T.mean(axis=0)
    return np.sqrt((tt**2).mean(axis=0) / (centred**2).mean(axis=0))


# 1 -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["ltao", "glao"])
def test_dm_adds_no_tip_tilt(nine, mode):
    """ "The DM adds no tip-tilt."

    Metric: rms of the surface's least-squares tip/tilt over the rms of the
    piston-removed surface. The command matrix removes tip/tilt over its fitting
    points (pitch d/4 = 0.13 m): there it must vanish up to the float32 rounding
    of the matrix (measured 5e-8; bound 1e-5). On the science pupil samples
    (~0.016 m) it is not exactly 0: the two samplings weight the annulus' edges
    differently. For white random slopes (a worst case: rough, edge-heavy
    surfaces), measured over 3 x 1000 vectors, LTAO and GLAO alike: median
    0.0053-0.0059, 99th percentile 0.013-0.015, max 0.016-0.020. We require
    median <= 0.01 and max <= 0.03 over 200 vectors (2e-4 and 1e-3 of the
    variance). Surfaces of random commands (no constraint) give a median of
    0.31, so a DM that adds tip-tilt fails by a factor ~30.
    """
    case = Case.from_config(nine.config(mode=mode))
    h, x, y = _science_influence(case)
    matrix, _ = nine.commands(mode)
    commands = matrix.astype(np.float64) @ np.random.default_rng(3).standard_normal((matrix.shape[1], 200))
    fraction = _tip_tilt_fraction((h @ commands).T, x, y)
    dm = case.ao.deformable_mirror(case.telescope)
    _, _, points = pupil_points(case.telescope, dm.pitch_m / 4)
    on_fit = _tip_tilt_fraction((dm.influence_matrix(points[:, 0], points[:, 1]) @ commands).T, *points.T)
    print(
        f"{mode}: tip-tilt fraction on fit points max {on_fit.max():.1e}; on the science samples "
        f"median {np.median(fraction):.4f}, max {fraction.max():.4f}"
    )
    assert on_fit.max() <= 1e-5, on_fit.max()
    assert np.median(fraction) <= 0.01 and fraction.max() <= 0.03, (np.median(fraction), fraction.max())
    # the metric sees tip-tilt when it is there: surfaces of random commands carry plenty of it
    free = (h @ np.random.default_rng(4).standard_normal((matrix.shape[0], 50))).T
    assert np.median(_tip_tilt_fraction(free, x, y)) > 0.1


# 2 -------------------------------------------------------------------------------------------
def test_flat_dm_changes_nothing(nine, study):
    """ "With ao.mode: none nothing changes" and "the pseudo-closed-loop residual
    equals the open-loop value when the DM is off".

    Same screens, same LGS chain: the case with ``ao.mode: none`` (no commands)
    and an LTAO case whose command matrix is all zeros (the DM is always flat)
    must give bit-identical frames, truth and ``lgs_rms``, and the latter's
    ``lgs_residual_rms_nm`` must equal ``lgs_rms_nm`` exactly (slopes minus
    zero). No tolerance: subtracting an exactly zero surface is exact in
    floating point. A none case has no command product and no residual variable.
    """
    duration = 0.2
    none_cfg = dict(nine.config(mode="none"), duration_s=duration)
    assert not Case.from_config(none_cfg).ao.enabled and commands_spec(none_cfg) is None
    matrix, dm_slopes = nine.commands("ltao")
    frames_none, frames_flat = [], []
    none = nine.simulate(none_cfg, None, frames_none)
    flat = nine.simulate(
        dict(nine.config(mode="ltao"), duration_s=duration), (np.zeros_like(matrix), dm_slopes), frames_flat
    )
    assert "lgs_residual_rms_nm" not in none
    np.testing.assert_array_equal(np.concatenate(frames_none, 1), np.concatenate(frames_flat, 1))
    for name in ("true_rms_nm", "lgs_rms_nm", "axis_strehl"):
        np.testing.assert_array_equal(none[name].values, flat[name].values)
    np.testing.assert_array_equal(flat.lgs_residual_rms_nm.values, flat.lgs_rms_nm.values)
    # the real DM does change things (the check above can fail)
    corrected = nine.run("ltao", NINE_S)
    assert corrected.true_rms_nm.values[0, :20].mean() < 0.7 * none.true_rms_nm.values[0].mean()


# 2b ------------------------------------------------------------------------------------------
def test_no_ao_case_takes_its_lgs_telemetry_from_its_twin(nine, study, tmp_path):
    """A no-AO case's simulation may take each frame's ``lgs_rms`` from an AO case with the
    same LGS chain (``config.lgs_twin``: the sensor is open loop, it never sees the DM) and
    only image: its telemetry and frames are then bit-identical to measuring them itself.
    The twin's file is refused when its LGS chain differs (here a 16x16 WFS) or its seed."""
    from luckyao.io.datasets import provenance, write_dataset
    from luckyao.steps.simulation import twin_lgs_rms_nm
    from luckyao.studyspec.products import lgs_twin

    config, cases = study
    assert lgs_twin(config, cases, "noao_r0_15cm") == "ltao_r0_15cm"
    assert lgs_twin(config, cases, "ltao_r0_15cm") is None  # AO cases measure their own
    assert (
        lgs_twin(config, {"noao_r0_15cm": cases["noao_r0_15cm"], "ltao_wfs16": cases["ltao_wfs16"]}, "noao_r0_15cm")
        is None
    )  # another WFS: other slopes

    duration = 0.2
    none_cfg = dict(nine.config(mode="none"), duration_s=duration)
    ltao_cfg = dict(nine.config(mode="ltao"), duration_s=duration)
    frames_own, frames_given = [], []
    own = nine.simulate(none_cfg, None, frames_own)
    twin = nine.simulate(ltao_cfg, nine.commands("ltao"))
    path = tmp_path / "twin.nc"
    twin.attrs.update(provenance("twin", ltao_cfg, 5))
    write_dataset(twin, path)
    given = TimeLoop(Case.from_config(none_cfg), nine.screens, 5, lgs_rms_nm=twin_lgs_rms_nm(path, none_cfg, 5)).run(
        lambda start, f: frames_given.append(f.copy())
    )
    assert given.identical(own)
    np.testing.assert_array_equal(np.concatenate(frames_given, 1), np.concatenate(frames_own, 1))
    with pytest.raises(ValueError, match="seed 6"):
        twin_lgs_rms_nm(path, none_cfg, 6)
    with pytest.raises(ValueError, match="LGS chain"):
        twin_lgs_rms_nm(path, deep_merge(none_cfg, {"wfs": {"n_subapertures": 16}}), 5)


# 2c ------------------------------------------------------------------------------------------
def test_ao_cases_replay_the_slopes_their_lgs_chain_measured_once(nine, study, tmp_path):
    """AO cases that differ only in their AO or targets (GLAO, LTAO, another DM, a field)
    share one LGS slopes product (``config.slopes_spec``: the sensor is open loop); an AO
    simulation replaying it gives telemetry and frames bit-identical to measuring the slopes
    in its own loop. The product is refused for another LGS chain (a 16x16 WFS) or seed."""
    from luckyao.io.datasets import provenance, write_dataset
    from luckyao.steps.lgs_slopes import RecordedSlopes, measure_lgs_slopes
    from luckyao.studyspec.products import lgs_chain_config, slopes_key, slopes_spec

    config, cases = study
    shared = {
        slopes_key(slopes_spec(config, cases[name]))
        for name in ("ltao_r0_13.5cm", "glao_r0_13.5cm", "ltao_dm5", "ltao_field")
    }
    assert len(shared) == 1
    assert slopes_key(slopes_spec(config, cases["ltao_wfs16"])) not in shared  # another WFS: other slopes
    assert slopes_spec(config, cases["noao_r0_13.5cm"]) is None  # no AO: lgs_rms from its twin (2b)

    duration = 0.2
    ltao_cfg = dict(nine.config(mode="ltao"), duration_s=duration)
    path = tmp_path / "slopes.nc"
    spec = {"seed": 5, "screens": "nine", "case": lgs_chain_config(ltao_cfg)}
    product = measure_lgs_slopes(spec, nine.screens, None)
    product.attrs.update(provenance("slopes", spec, 5))
    write_dataset(product, path, compress=False)
    for ao in ({"mode": "ltao"}, {"mode": "glao"}, {"mode": "ltao", "n_actuators": 5}):
        cfg = dict(nine.config(**ao), duration_s=duration)
        built = build_commands(commands_spec(cfg))
        commands, frames_own, frames_replayed = (built.command_matrix.values, built.dm_slopes.values), [], []
        own = nine.simulate(cfg, commands, frames_own)
        replayed = TimeLoop(
            Case.from_config(cfg),
            nine.screens,
            5,
            reconstructors=nine.reconstructors,
            slopes=RecordedSlopes.open(path, cfg, 5),
            commands=commands,
        ).run(lambda start, f: frames_replayed.append(f.copy()))
        assert replayed.identical(own), ao
        np.testing.assert_array_equal(np.concatenate(frames_replayed, 1), np.concatenate(frames_own, 1))
    with pytest.raises(ValueError, match="seed 6"):
        RecordedSlopes.open(path, ltao_cfg, 6)
    with pytest.raises(ValueError, match="LGS chain"):
        RecordedSlopes.open(path, deep_merge(ltao_cfg, {"wfs": {"n_subapertures": 16}}), 5)


# 3 -------------------------------------------------------------------------------------------
class _Recorder(simulation.OpenLoopCorrection):
    """The loop's correction, recording the DM surface it applies at each science step."""

    last = None

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.applied = {}
        _Recorder.last = self

    def surface_at(self, step):
        surface = super().surface_at(step)
        self.applied[step] = np.array(surface, copy=True)
        return surface


@pytest.mark.parametrize("delay", [2, 3, 6])
def test_dm_shape_is_the_fit_of_the_delayed_measurement(ground, monkeypatch, delay):
    """ "The DM shape applied at a step is exactly the fit of the measurement that
    ended the configured delay earlier", on one frozen layer.

    The ground layer moves by exactly 2 screen samples per step, so the phase
    seen at step k + j is the phase at step k of the screen rolled by 2 j
    samples along the wind. For every science step k of a run we take the
    exposure start s = E floor((k - delay) / E) (E = 2 steps), roll the screen
    by 2 s samples, measure a fresh LGS sensor's exposure over steps [0, E) and
    fit it onto the DM (command matrix, then influence functions at the science
    samples): that must be the surface the loop subtracted at step k (flat when
    s < 0). Independent of the loop's bookkeeping: the measurement is
    identified by its phase content, not its step label. delay = 3 checks the
    rounding down to an exposure start. Tolerance 1e-4 of the surface rms:
    float32 products (M s, H c over ~400 slopes and ~80 actuators, ~1e-6
    relative) and bilinear weights of 2.0000000000000004-sample steps; the
    surface of the neighbouring exposure (s +- E, 0.13 m of wind) differs by
    26 % rms (measured; asserted > 1 %), so an off-by-one-exposure delay
    fails. Measured mismatch: 2.5e-7 for delays 2, 3 and 6.
    """
    monkeypatch.setattr(simulation, "OpenLoopCorrection", _Recorder)
    cfg = dict(ground.config(mode="ltao", delay_steps=delay), duration_s=0.1)
    case = Case.from_config(cfg)
    matrix, dm_slopes = ground.commands("ltao")
    ground.simulate(cfg, (matrix, dm_slopes))
    applied = _Recorder.last.applied
    e = case.wfs.exposure_steps
    h, _, _ = _science_influence(case)
    (spec,) = ground.screens.specs
    base_screen = ground.screens.screen(0)
    wfs = case.shack_hartmann()

    expected = {}

    def fit_of_exposure(s):
        if s not in expected:
            rolled = ScreenSet.from_screens([spec], [np.roll(base_screen, 2 * s, axis=0)])
            sensor = LgsSensor(case.lgs, wfs, e, list(case.layers), rolled, seed=5)
            slopes = sensor.exposure_slopes(np.arange(e), case.layer_scales(np.arange(e)))
            expected[s] = h @ (matrix.astype(np.float64) @ slopes.ravel().astype(np.float64))
        return expected[s]

    n_steps = case.n_frames * case.steps_per_frame
    assert sorted(applied) == list(range(n_steps))
    worst, neighbour = 0.0, np.inf
    for k in range(n_steps):
        s = (k - delay) // e * e
        if s < 0:
            assert not np.any(applied[k]), k
            continue
        want = fit_of_exposure(s)
        scale = np.sqrt(np.mean(want**2))
        worst = max(worst, np.sqrt(np.mean((applied[k] - want) ** 2)) / scale)
        for other in (s - e, s + e):
            if other >= 0:
                neighbour = min(neighbour, np.sqrt(np.mean((applied[k] - fit_of_exposure(other)) ** 2)) / scale)
    print(f"delay {delay}: worst relative mismatch {worst:.1e}, nearest other exposure {neighbour:.3f}")
    assert worst < 1e-4, worst
    assert neighbour > 100 * 1e-4, neighbour


def test_corrected_residual_grows_with_the_delay(nine):
    """ "The corrected residual grows with the delay": mean true (corrected) rms
    on the 9-layer profile (fast high layers: 24, 39, 20 m/s at 4.5, 9, 18 km),
    LTAO, delay 2, 4, 8 steps (5, 10, 20 ms), same screens and frames.

    Measured (seed 5, 1.2 s): 210, 220, 251 nm; over 2.4 s with seeds 7 and 8:
    189/201/235 and 189/200/233 nm. Each step up in delay must raise the mean
    by more than 3 batch-means standard errors of the paired per-frame
    difference (common random numbers): measured +10.6 nm (se 2.6) from 2 to 4
    steps and +31.0 nm (se 4.9) from 4 to 8.
    """
    means, previous = [], None
    for delay in (2, 4, 8):
        true = nine.run("ltao" if delay == 2 else f"ltao_d{delay}", NINE_S, delay_steps=delay).true_rms_nm.values[0]
        means.append(true.mean())
        if previous is not None:
            diff = true - previous
            print(f"delay {delay}: +{diff.mean():.1f} nm, se {_batch_se(diff):.1f}")
            assert diff.mean() > 3 * _batch_se(diff), (delay, diff.mean(), _batch_se(diff))
        previous = true
    print("mean true rms (delay 2, 4, 8):", np.round(means, 1))


# 4 -------------------------------------------------------------------------------------------
def test_ground_layer_ltao_equals_glao(ground):
    """ "One turbulent layer at the ground: LTAO and GLAO give the same correction."

    Atmosphere and prior are one layer at h = 0 (GLAO takes the layers up to
    100 m, i.e. that one): the tomographic estimate along the on-axis target
    and the ground-layer estimate are the same, so command matrices agree to
    float32 rounding (rtol 1e-5 of the largest element) and the per-frame
    corrected rms to 1e-4 relative (float32 sums over ~50 000 pupil samples).
    Measured: the two are bit-identical.
    """
    ltao, glao = ground.commands("ltao")[0], ground.commands("glao")[0]
    np.testing.assert_allclose(ltao, glao, rtol=0, atol=1e-5 * np.abs(ltao).max())
    a = ground.run("ltao", GROUND_S).true_rms_nm.values[0]
    b = ground.run("glao", GROUND_S, mode="glao").true_rms_nm.values[0]
    print("ground layer ltao/glao max relative difference", np.max(np.abs(a - b) / a))
    np.testing.assert_allclose(a, b, rtol=1e-4)
    none = ground.run("none", GROUND_S, mode="none").true_rms_nm.values[0]
    assert a.mean() < 0.6 * none.mean()  # and it is a correction


def test_ltao_beats_glao_on_axis(nine):
    """ "On the 9-layer profile LTAO corrects the on-axis target better than GLAO."

    Measured mean true rms (seed 5, 1.2 s): LTAO 210 nm, GLAO 325 nm; with
    seeds 6-8: 191/317, 189/300, 189/315 nm. We require the paired difference
    to exceed 5 batch-means standard errors and GLAO to be at least 20 % worse
    (GLAO leaves the 48 % of Cn2 above 100 m uncorrected). Measured paired
    difference 115 nm, batch-means se 15.6 nm.
    """
    ltao = nine.run("ltao", NINE_S).true_rms_nm.values[0]
    glao = nine.run("glao", NINE_S, mode="glao").true_rms_nm.values[0]
    diff = glao - ltao
    print(f"ltao {ltao.mean():.1f} nm, glao {glao.mean():.1f} nm, diff se {_batch_se(diff):.1f}")
    assert diff.mean() > 5 * _batch_se(diff)
    assert glao.mean() > 1.2 * ltao.mean()


# 5 -------------------------------------------------------------------------------------------
def test_pseudo_closed_loop_residual_default_profile(nine):
    """ "The pseudo-closed-loop residual is lower than the open-loop rms, tracks the
    true corrected rms (state the correlation you measure)", default profile, LTAO.

    Mean residual < 0.3 x mean open-loop rms (measured 62 vs 389 nm, seed 5;
    62-65 vs 358-463 nm with seeds 6-8) and below the true corrected rms (the
    LGS cannot see fitting error, the cone effect on the 9 and 18 km layers or
    tip-tilt): measured 62 vs 210 nm.

    Correlation with the corrected truth, measured (Pearson / Spearman):
    seed 5, 1.2 s: residual 0.24 / 0.10, open-loop 0.20 / 0.24; seed 6, 1.2 s:
    0.44 / 0.25 vs 0.44 / 0.50; seeds 7, 8, 2.4 s: 0.14 / -0.05 vs 0.16 / 0.17
    and 0.52 / 0.19 vs 0.08 / 0.09. On this profile the truth's frame-to-frame
    spread is dominated by what the LGS do not see (fitting error ~110 nm,
    unseen high-altitude turbulence ~100 nm, against a 62 nm residual), so the
    correlation is weak and, with effectively ~20 independent frames per 1.2 s,
    its Monte-Carlo spread (+-0.2) swamps the residual-vs-open-loop gap: no
    correlation threshold is asserted here (see the ground-layer test below,
    where the physics does require one). We only require it to be finite.
    """
    tel = nine.run("ltao", NINE_S)
    true, lgs, res = (tel[v].values[0] for v in ("true_rms_nm", "lgs_rms_nm", "lgs_residual_rms_nm"))
    print(
        f"means: residual {res.mean():.1f}, open loop {lgs.mean():.1f}, true {true.mean():.1f}; "
        f"r(res, true) {np.corrcoef(res, true)[0, 1]:.3f} / {_ranks_corr(res, true):.3f}, "
        f"r(lgs, true) {np.corrcoef(lgs, true)[0, 1]:.3f} / {_ranks_corr(lgs, true):.3f}"
    )
    assert np.all(np.isfinite(res)) and np.all(res > 0)
    assert res.mean() < 0.3 * lgs.mean()
    assert res.mean() < true.mean()
    assert np.isfinite(np.corrcoef(res, true)[0, 1])


def test_pseudo_closed_loop_residual_tracks_the_truth(ground):
    """ "The pseudo-closed-loop residual ... tracks the true corrected rms", where
    the physics requires it: one ground layer (seen identically by every LGS and
    the target, no cone effect) at 26 m/s with a 4-step (10 ms) delay, so the
    corrected error is dominated by the lag error (0.26 m of wind, half the DM
    pitch), which the LGS measure, while the open-loop rms follows the
    uncorrected turbulence, most of which the DM removes.

    Measured over 0.8 s = 80 frames (Pearson / Spearman with the truth):
    residual 0.91 / 0.85 vs open loop 0.35 / 0.50 (seed 7, the fixture's);
    0.68 / 0.66 vs 0.38 / 0.37 (seed 8); 0.90 / 0.86 vs 0.38 / 0.50 (seed 9).
    Means: residual 167-178 nm, open loop 338-409 nm, truth 230-243 nm
    (uncorrected 424 nm). The layer crosses the pupil in 0.16 s, so 80 frames
    hold only ~5-10 independent stretches and r has a Monte-Carlo error of
    ~0.1-0.15: we require r >= 0.6 for both coefficients and the residual's to
    exceed the open-loop rms's by >= 0.15 (the smallest gap over the three
    seeds is 0.28), and the mean residual to be below the open-loop rms.
    With the default delay of 2 steps the lag share is smaller and the
    measured correlations are lower and noisier (0.55-0.86 / 0.42-0.69).
    """
    tel = ground.run("ltao_d4", GROUND_S, delay_steps=4)
    true, lgs, res = (tel[v].values[0] for v in ("true_rms_nm", "lgs_rms_nm", "lgs_residual_rms_nm"))
    r_res, r_lgs = np.corrcoef(res, true)[0, 1], np.corrcoef(lgs, true)[0, 1]
    s_res, s_lgs = _ranks_corr(res, true), _ranks_corr(lgs, true)
    print(
        f"ground, delay 4: means residual {res.mean():.1f}, open loop {lgs.mean():.1f}, true {true.mean():.1f}; "
        f"r(res, true) {r_res:.3f} / {s_res:.3f}, r(lgs, true) {r_lgs:.3f} / {s_lgs:.3f}"
    )
    assert res.mean() < lgs.mean()
    assert r_res >= 0.6 and s_res >= 0.6, (r_res, s_res)
    assert r_res >= r_lgs + 0.15 and s_res >= s_lgs + 0.15, (r_res, r_lgs, s_res, s_lgs)
