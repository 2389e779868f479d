"""Off-axis targets: the field of a case, selected and recentred on the on-axis star.

One LTAO set-up (module fixture): the default system (9-layer profile, 4 Rayleigh
LGS at 22 km, 8x8 WFS, 9x9 DM corrected on axis) with targets at 0, 20 and 40
arcsec on the x axis, coarse screens (0.033 m, as ``tests/test_ao_loop.py``),
0.4 s. The simulation images only the star (target 0) and records the DM
commands; the other targets are replayed from the screens and those commands.
"""

import numpy as np
import pytest

from luckyao.atmosphere.screens import ScreenSet, strip_screen
from luckyao.lucky.accumulation import recentring_shifts_px
from luckyao.lucky.detector import Detector
from luckyao.lucky.metrics import strehl
from luckyao.lucky.pipeline import ImageReference, run_lucky
from luckyao.steps.reconstructor import build_commands, build_reconstructors
from luckyao.steps.screens import TurbulenceSpec, strip_specs
from luckyao.steps.simulation import Replay, lgs_chain, simulate
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import commands_spec, reconstructor_spec, turbulence_spec
from luckyao.studyspec.resolved import imaged_targets
from luckyao.studyspec.schema import deep_merge
from luckyao.studyspec.study import load_study

from reference import shift_frames

DURATION_S = 0.4
TARGETS_ARCSEC = [[0.0, 0.0], [20.0, 0.0], [40.0, 0.0]]


class _Field:
    def __init__(self):
        config, cases = load_study("config/config.yaml")
        # the raw centroids (wfs.calibration: none): the field's geometry does not depend on the slope gain
        self.config = deep_merge(
            cases["ltao_r0_13.5cm"],
            {
                "duration_s": DURATION_S,
                "targets_arcsec": TARGETS_ARCSEC,
                "reference_target": 0,
                "wfs": {"calibration": "none"},
            },
        )
        spec = dict(turbulence_spec(config, self.config), duration_s=DURATION_S + 0.05, max_pixel_m=0.033)
        specs = strip_specs(TurbulenceSpec.from_config(spec))
        self.screens = ScreenSet.from_screens(
            specs, [strip_screen(s, spec["outer_scale_m"], np.random.default_rng([3, i])) for i, s in enumerate(specs)]
        )
        self.case = Case.from_config(self.config)
        self.reconstructors = build_reconstructors(reconstructor_spec(self.config))["reconstructor"].values
        products = build_commands(commands_spec(self.config))
        self.commands = products.command_matrix.values, products.dm_slopes.values

    def run(self, imaged):
        sensor, estimator = lgs_chain(self.case, self.screens, self.reconstructors, seed=5)
        frames = []
        telemetry = simulate(
            self.case, self.screens, lambda start, f: frames.append(f.copy()), sensor, estimator, self.commands, imaged
        )
        return telemetry, np.concatenate(frames, axis=1)


@pytest.fixture(scope="module")
def field():
    return _Field()


@pytest.fixture(scope="module")
def runs(field):
    """Every target imaged by the simulation, and only the star (the study's way)."""
    return field.run(None), field.run(imaged_targets(field.config))


def test_the_simulation_of_a_field_images_only_the_star(field, runs):
    assert imaged_targets(field.config) == [0]
    (_, all_frames), (telemetry, star_frames) = runs
    assert star_frames.shape[0] == 1 and all_frames.shape[0] == 3
    assert list(telemetry.imaged.values) == [1, 0, 0]
    assert np.isnan(telemetry.axis_strehl.values[1:]).all()


def test_replayed_frames_are_the_simulated_frames(field, runs):
    """Recomputing the science path from the screens and the recorded DM commands gives
    the frames the time loop would have stored, bit for bit (and their value on the axis), and the loop's telemetry
    does not depend on which targets it images."""
    (full, all_frames), (telemetry, star_frames) = runs
    np.testing.assert_array_equal(star_frames[0], all_frames[0])
    for name in ("lgs_rms_nm", "lgs_residual_rms_nm", "true_rms_nm", "dm_commands_m", "r0_500nm_m"):
        np.testing.assert_array_equal(telemetry[name].values, full[name].values)
    replay = Replay(field.case, field.screens, [1, 2], telemetry.dm_commands_m.values, block_frames=7)
    replayed = np.concatenate([frames for _, frames in replay()], axis=1)
    np.testing.assert_array_equal(replayed, all_frames[1:])
    # the replay returns the frames' value on the axis as the time loop records it
    np.testing.assert_array_equal(replay.axis_strehl, full.axis_strehl.values[1:])
    # the DM matters: replaying without it gives other frames (the check above can fail)
    flat = Replay(field.case, field.screens, [1], None)
    assert not np.array_equal(next(iter(flat()))[1][0], all_frames[1, :64])


def test_off_axis_residual_grows_with_distance(runs):
    """LTAO corrects on axis: anisoplanatism makes the true residual rms grow with the
    target's distance. Paired over frames (same turbulence), so the differences are
    compared with their own batch-means standard errors."""
    (telemetry, _), _ = runs
    rms = telemetry.true_rms_nm.values.astype(float)  # (target, frame)
    for near, far in ((0, 1), (1, 2)):
        difference = rms[far] - rms[near]
        batches = np.array([b.mean() for b in np.array_split(difference, 5)])
        error = batches.std(ddof=1) / np.sqrt(len(batches))
        assert difference.mean() > 3 * error and difference.mean() > 10.0, (near, far, difference.mean(), error)


def test_off_axis_target_is_selected_and_recentred_by_the_star(field, runs):
    """With a reference, the image criteria and the shifts are the star's: the integrated
    image of the best frames by the star's Strehl is the off-axis target's frames of
    those indices, each shifted by the star's whole-pixel recentring."""
    (telemetry, all_frames), _ = runs
    n_frames, n = all_frames.shape[1], all_frames.shape[-1]
    args = dict(
        detectors=[Detector("noiseless")],
        fractions=[0.25, 1.0],
        diffraction_limited_peak=1e-2,
        pixel_scale_arcsec=field.case.camera.pixel_scale_arcsec,
        seed=1,
        image_crop_px=None,
    )

    def chunks(target):
        return lambda: iter([(0, all_frames[target])])

    star = run_lucky(chunks(0), n_frames, **args)
    target = run_lucky(chunks(2), n_frames, reference=ImageReference.of(star), **args)
    np.testing.assert_array_equal(target.frame_criterion.sel(criterion="strehl").values, star.frame_strehl.values)
    best = np.argsort(-star.frame_strehl.values[0], kind="stable")[: round(0.25 * n_frames)]
    shifts = recentring_shifts_px(star.frame_centroid_px.values[0, best], n)
    expected = shift_frames(all_frames[2, best], shifts).sum(axis=0, dtype=np.float64)
    image = target.image.sel(criterion="strehl", fraction=0.25, detector="noiseless").values
    np.testing.assert_allclose(image, expected / expected.sum(), rtol=1e-5, atol=1e-9)
    # its own Strehl would select other frames (the reference is what changes the result)
    own = np.argsort(-strehl(all_frames[2], 1e-2), kind="stable")[: len(best)]
    assert set(own) != set(best)


def test_lucky_imaging_of_replayed_frames_is_that_of_the_stored_frames(field, runs):
    """Without a cube (``replay_frames``) every pass over a target's frames replays them: the
    lucky result of an AO target, a noisy and a noiseless detector, time blocks (3 passes) is bit
    for bit that of the stored frames read in chunks of the same size (the pipeline's guesses
    follow the chunking: ``postprocess.CHUNK_FRAMES`` for both)."""
    (telemetry, all_frames), _ = runs
    n_frames = all_frames.shape[1]
    args = dict(
        detectors=[Detector("noiseless"), Detector("faint", 300.0, 0.1)],
        fractions=[0.25, 1.0],
        diffraction_limited_peak=1e-2,
        pixel_scale_arcsec=field.case.camera.pixel_scale_arcsec,
        seed=1,
        n_blocks=4,
    )
    replay = Replay(field.case, field.screens, [1], telemetry.dm_commands_m.values, block_frames=9)
    passes = []

    def replayed():
        passes.append(1)
        return ((start, frames[0]) for start, frames in replay())

    stored = run_lucky(lambda: ((s, all_frames[1, s : s + 9]) for s in range(0, n_frames, 9)), n_frames, **args)
    assert run_lucky(replayed, n_frames, **args).identical(stored)
    assert len(passes) == 3  # the noiseless frames, the detected ones, the ones guessed wrong
