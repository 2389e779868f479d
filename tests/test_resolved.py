"""The resolved view of a study and what one's own case needs (issue 45, item 1): overrides
typed on the command line, one case run alone, labels that name what differs, the
tomography prior following the case's r0, screens as long as their longest case, and
``luckyao show``."""

import json
import re
import subprocess
import sys

import pytest
import yaml

from luckyao.figures.settings import CaseSummary
from luckyao.io.hashing import sha256
from luckyao.studyspec.case import Case
from luckyao.studyspec.overrides import parse_overrides, typed
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, plausibility_warnings, validate_study
from luckyao.studyspec.sweeps import expand_study
from luckyao.studyspec.view import resolve_study

from studies import REPO, snakemake, snakemake_command, tiny


def view_of(study: dict):
    return resolve_study(study, validate_study(study))


def test_the_shipped_configs_keep_their_keys():
    """The default study's product keys, as before the view (tools/resolved_hashes.py diffs all)."""
    study, _ = load_study(REPO / "config" / "config.yaml")
    view = view_of(study)
    case = view.cases["ltao_r0_15cm"]
    assert case.config_sha256[:16] == "4723f51791c76f9b"
    assert case.screens.key == "screens_1b65d79a70be"
    assert case.reconstructor.key == "reconstructor_22060f27bd2e"  # the 13.5 cm prior, pinned
    assert case.slopes.key == "slopes_ca254bcc5dc5"
    assert view.cases["noao_r0_15cm"].lgs_twin == "ltao_r0_15cm"


@pytest.mark.parametrize(
    "overlay, case, lucky_sha256",
    [
        (None, "ltao_r0_13.5cm", "13fd59ebbeb1f5a2"),  # the sweep, from lucky.detector_sweep.cases
        (None, "glao_r0_13.5cm", "f4557aeb3f6b1982"),  # none
        ("diameter.yaml", "ltao_r0_13.5cm", "ce18bb9d2370f49a"),
        (("diameter.yaml", "diameter_full.yaml"), "ltao_D16m", "c9a4e3e82da3aa66"),
    ],
)
def test_the_detector_sweep_as_a_config_field_keeps_the_lucky_hashes(overlay, case, lucky_sha256):
    """Each case's lucky settings hash as when the sweep was given by the figures that draw it."""
    overlays = (overlay,) if isinstance(overlay, str) else overlay or ()
    paths = [REPO / "config" / "config.yaml"] + [REPO / "config" / name for name in overlays]
    study, _ = load_study(*paths)
    assert sha256(view_of(study).cases[case].lucky_settings)[:16] == lucky_sha256


def test_overrides_are_typed_as_yaml():
    """Snakemake hands --config "base={duration_s: 0.5}" over as the string '0.5'."""
    from snakemake.cli import parse_config

    raw = parse_config(["base={duration_s: 0.5, telescope: {diameter_m: 8}}"])
    assert raw["base"]["duration_s"] == "0.5"  # what the schema refused
    assert typed(raw) == {"base": {"duration_s": 0.5, "telescope": {"diameter_m": 8}}}
    study = deep_merge(tiny(), typed(parse_config(["base={duration_s: 0.1}"])))
    validate_study(study)
    words = ["telescope.diameter_m=8", "lgs.n_beacons=6", "ao.mode=ltao", "base.duration_s=0.5", "keep_frames=true"]
    assert parse_overrides(words, "mine") == {
        "cases": {"mine": {"telescope": {"diameter_m": 8}, "lgs": {"n_beacons": 6}, "ao": {"mode": "ltao"}}},
        "base": {"duration_s": 0.5},
        "keep_frames": True,
    }
    with pytest.raises(ConfigError, match="needs case=NAME"):
        parse_overrides(["telescope.diameter_m=8"])


def test_the_prior_follows_the_case_r0_unless_pinned():
    study = tiny()
    del study["base"]["tomography"]["prior_r0_500nm_m"]
    study["cases"]["pinned"] = {
        "atmosphere": {"r0_500nm_m": 0.2},
        "tomography": {"prior_r0_500nm_m": 0.135},
        "lgs": {"enabled": True},
    }
    view = view_of(study)
    assert view.cases["good"].config["tomography"]["prior_r0_500nm_m"] == 0.2  # the case's r0
    assert not view.cases["good"].prior_pinned
    assert view.cases["pinned"].config["tomography"]["prior_r0_500nm_m"] == 0.135
    assert view.cases["pinned"].prior_pinned
    (warning,) = [w for w in plausibility_warnings(view.configs) if "prior" in w]
    assert warning.endswith("case's r0)") and "cases pinned " in warning


def test_screens_are_as_long_as_their_longest_case():
    study = tiny()
    del study["turbulence"]["duration_s"]
    study["cases"]["short"] = {"duration_s": 0.1, "telescope": {"diameter_m": 2.1, "obscuration_m": 0.6}}
    study["cases"]["long"] = {"duration_s": 0.4}
    view = view_of(study)
    assert view.cases["short"].screens.duration_s == 0.1  # its own screens (another telescope)
    assert view.cases["good"].screens.duration_s == 0.4  # shared with 'long'
    assert view.cases["good"].screens.key == view.cases["long"].screens.key
    study["turbulence"]["duration_s"] = 0.5  # pinned: every case's screens
    assert view_of(study).cases["short"].screens.duration_s == 0.5


def test_labels_name_the_diameter_and_the_beacons():
    study = tiny()
    study["cases"]["big"] = {
        "telescope": {"diameter_m": 8.0, "obscuration_m": 2.3},
        "lgs": {"enabled": True, "n_beacons": 6},
    }
    configs = validate_study(study)
    summary = CaseSummary.of("big", Case.from_config(configs["big"])).summary()
    assert "8 m" in summary and "6 LGS" in summary


def test_a_summary_names_every_key_set_apart_from_the_base():
    """Besides its parts (AO, diameter, r0, WFS, beacons, height, DM), every other key the case
    sets apart from the base, not the keys it derived (the camera, the obscuration)."""
    study = tiny()
    study["cases"]["big"] = {"telescope": {"diameter_m": 8.0}, "ao": {"coupling": 0.25}, "lgs": {"enabled": True}}
    study["turbulence"].pop("duration_s")
    view = resolve_study(expand_study(study), validate_study(study))
    big = view.cases["big"]
    differences = {k: v for k, v in big.differences.items() if k not in big.derived}
    summary = CaseSummary.of("big", Case.from_config(big.config), differences).summary()
    assert summary.endswith("; ao.coupling 0.25") and "8 m" in summary, summary
    assert "camera" not in summary and "obscuration" not in summary


def test_show_names_the_derived_keys():
    words = ["telescope.diameter_m=8", "lgs.n_beacons=6", "atmosphere.r0_500nm_m=0.12", "duration_s=1"]
    done = subprocess.run(
        [sys.executable, "-m", "luckyao", "show", "mine", *words, "--json"], cwd=REPO, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert {p: d["value"] for p, d in report["derived"].items()} == {
        "telescope.obscuration_m": 2.286,
        "wfs.n_subapertures": 15,
        "ao.n_actuators": 16,
        "camera.n_pixels": 512,
        "tomography.prior_r0_500nm_m": 0.12,
    }
    assert report["screens"]["duration_s"] == 1  # not the default study's 10 s
    assert "8 m telescope" in report["summary"] and "6 LGS" in report["summary"]
    assert any(job["job"] == "simulate mine" for job in report["jobs"])
    text = subprocess.run(
        [sys.executable, "-m", "luckyao", "show", "mine", *words], cwd=REPO, capture_output=True, text=True
    ).stdout
    assert "wfs.n_subapertures = 15" in text and "following the case's r0" in text
    assert all(job["time_s"] > 0 for job in report["jobs"])
    jobs = text[text.index("jobs (estimated time and memory") : text.index("resolved config:")].splitlines()[1:]
    assert len(jobs) == len(report["jobs"]) + 1  # and the total
    assert all(re.search(r" \d+(\.\d)? (s|min|h) +\d+\.\d\d GB", line) for line in jobs[:-1]), jobs
    assert "screens screens_" not in text and "calibration calibration_" not in text  # said once


def _study_folder(tmp_path, study):
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "config.yaml").write_text(yaml.safe_dump(study))
    return tmp_path


@pytest.mark.workflow
def test_a_case_on_the_command_line_is_run_alone(tmp_path):
    """``bash run.sh study case=NAME key=value``: that case (a new one here, which no figure
    lists), its lucky.nc and FITS, typed overrides, and nothing of the rest of the study."""
    folder = _study_folder(tmp_path, tiny())
    command = snakemake_command(folder, "-n", module="luckyao.jobs.live_run")
    words = ["case=mine", "atmosphere.r0_500nm_m=0.15", "base.duration_s=0.1"]
    done = subprocess.run([*command[:3], *words, *command[3:]], cwd=folder, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    out = done.stdout + done.stderr
    assert "fits/mine.fits" in out and "results/cases/mine/lucky.nc" in out
    assert "results/cases/good/" not in out and "figures/" not in out


@pytest.mark.workflow
def test_an_overlay_that_only_adds_a_case_runs_it_alone(tmp_path):
    folder = _study_folder(tmp_path, tiny())
    (folder / "mine.yaml").write_text(yaml.safe_dump({"cases": {"mine": {"atmosphere": {"r0_500nm_m": 0.15}}}}))
    done = snakemake(folder, "-n", "--configfile", str(folder / "mine.yaml"), "--config", "base={duration_s: 0.1}")
    assert done.returncode == 0, done.stderr
    out = done.stdout + done.stderr
    assert "fits/mine.fits" in out and "figures/" not in out and "results/cases/good/" not in out
