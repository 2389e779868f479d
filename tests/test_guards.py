"""Nothing wrong is taken as a result: non-finite values and impossible combinations
are refused with a message naming where, before any compute when they can be known."""

import numpy as np
import pytest
import yaml

from luckyao.io.datasets import FrameWriter
from luckyao.steps.screens import read_screens, write_screens
from luckyao.studyspec.schema import ConfigError
from luckyao.studyspec.study import validate_study
from luckyao.wfs.kernels import centroids

from studies import TINY, tiny, with_name


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_config_values_are_rejected_naming_the_key(value):
    study = tiny()
    study["cases"]["good"]["atmosphere"]["r0_500nm_m"] = value
    with pytest.raises(ConfigError, match=r"cases\.good\.atmosphere\.r0_500nm_m"):
        validate_study(study)


def test_a_criterion_the_case_cannot_give_is_rejected_before_any_job():
    study = tiny()
    study["figures"]["quality"]["criteria"] = ["lgs_rms"]  # cases good, bad have no LGS
    with pytest.raises(ConfigError, match=r"figures\.quality\.cases.*'good'.*lgs_rms"):
        validate_study(study)
    study = tiny()
    study["figures"]["lgsrms"]["criteria"] = ["lgs_residual_rms"]  # case lgs has LGS but no AO
    with pytest.raises(ConfigError, match=r"lgs_residual_rms \(needs AO\)"):
        validate_study(study)


def test_error_blocks_need_frames_and_fractions_are_distinct():
    study = tiny()
    study["lucky"]["error_blocks"] = 15  # 0.2 s = 20 frames < 2 x 15
    with pytest.raises(ConfigError, match=r"lucky\.error_blocks"):
        validate_study(study)
    study = tiny()
    study["lucky"]["fractions"] = [0.1, 0.1, 1.0]
    with pytest.raises(ConfigError, match=r"lucky\.fractions"):
        validate_study(study)


def test_nan_in_the_screens_file_is_a_named_error(tmp_path):
    study = tiny()
    spec = {
        "seed": 1,
        **study["turbulence"],
        "time_step_s": 0.0025,
        "diameter_m": 4.2,
        "outer_scale_m": 20.0,
        "height_m": [0.0],
        "wind_speed_m_s": [10.0],
        "wind_direction_deg": [0.0],
    }
    screens, metadata = tmp_path / "s.npy", tmp_path / "s.nc"
    write_screens(spec, screens, metadata, {})
    flat = np.load(screens, mmap_mode="r+")
    flat[1234] = np.nan  # same size, still a valid .npy
    flat.flush()
    del flat
    with pytest.raises(ValueError, match=r"turbulence file '.*s\.npy'.*'screens'.*\(1234,\)"):
        read_screens(screens, metadata)


def test_the_centroid_of_a_nan_image_is_nan_not_zero():
    images = np.ones((1, 3, 4, 4), dtype=np.float32)
    images[0, 1, 2, 2] = np.nan
    out = np.empty((1, 2, 3), dtype=np.float32)
    centroids(images, np.arange(4, dtype=np.float64), True, out)
    assert np.all(np.isnan(out[0, :, 1]))


def test_a_non_finite_frame_is_never_written(tmp_path):
    path = tmp_path / "frames.nc"
    with pytest.raises(ValueError, match=r"frames file .*'frames'.*frame=1"):
        with FrameWriter(path, [0], 4, 8, 0.1, {}) as writer:
            block = np.ones((1, 2, 8, 8), dtype=np.float32)
            block[0, 1, 3, 3] = np.inf
            writer.write(0, block)
    assert not path.exists() and not path.with_name("frames.nc.partial").exists()


def test_every_problem_is_reported_one_line_each():
    study = tiny()
    study["cases"]["good"]["atmosphere"]["r0_500nm_m"] = -0.2
    study["cases"]["bad"]["ao"] = {**study["base"]["ao"], "mode": "ltao"}  # AO without LGS
    study["figures"]["quality"]["detector"] = "nope"
    with pytest.raises(ConfigError) as caught:
        validate_study(study)
    lines = str(caught.value).splitlines()
    assert len(lines) == 3
    assert any("cases.good.atmosphere.r0_500nm_m" in line for line in lines)
    assert any("cases.bad.ao.mode" in line for line in lines)
    assert any("figures.quality.detector" in line for line in lines)


@pytest.mark.parametrize("name", ["..", ".", "-x", "../../X", "q$(touch PWNED)", "a b", "<script>", "a/b", "x..y"])
@pytest.mark.parametrize("kind", ["case", "figure", "detector"])
def test_an_unsafe_name_is_refused_naming_its_key(kind, name):
    """Names become file names and command-line words: one pattern for cases, figures and
    detectors (a letter or digit first; letters, digits, _ . + -; never '..')."""
    study, key = with_name(kind, name)
    with pytest.raises(ConfigError, match=rf"config key '{key}': .* is not a safe name"):
        validate_study(study)


def test_the_safe_names_of_the_studies_pass():
    for path in (TINY, TINY.parents[2] / "config" / "config.yaml"):
        validate_study(yaml.safe_load(path.read_text()))
    study = tiny()
    study["cases"]["ltao_r0_13.5cm+glao-2"] = {}
    validate_study(study)
