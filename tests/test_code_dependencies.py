"""The workflow reruns exactly the steps whose code changed (and what follows them).

Each rule's code inputs are the import closure of the module its step runs
(``luckyao.jobs.code_deps``). Here a copy of the workflow and package runs a
tiny study; then one module at a time gets a real content edit, and a dry run
must plan exactly the steps that depend on it, by what each step computes.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import yaml

pytestmark = pytest.mark.workflow  # runs Snakemake, a study or the command line: -m 'not workflow' skips it

REPO = Path(__file__).resolve().parents[1]
TINY = REPO / "tests" / "data" / "tiny.yaml"

# module edited -> rules that must rerun (the step that runs it and everything after it)
EXPECTED = {
    "atmosphere/screens.py": {"turbulence", "simulate", "lucky", "figure", "export"},
    "optics/farfield.py": {"simulate", "lucky", "figure", "export"},
    "wfs/kernels.py": {"simulate", "lucky", "figure", "export"},
    "lucky/metrics.py": {"lucky", "figure", "export"},
    "figures/quality.py": {"figure"},
    "optics/long_exposure.py": {"figure"},
    "io/fits.py": {"export"},
}


def _snakemake(copy: Path, workdir: Path, *args):
    env = dict(os.environ, PYTHONPATH=str(copy / "src"))
    command = [
        sys.executable,
        "-m",
        "snakemake",
        "-s",
        str(copy / "Snakefile"),
        "-d",
        str(workdir),
        "--cores",
        "2",
        *args,
    ]
    return subprocess.run(command, capture_output=True, text=True, timeout=600, env=env)


def _rules_planned(result) -> set[str]:
    return {
        line.split()[1].rstrip(":")
        for line in result.stdout.splitlines()
        if line.strip().startswith(("rule ", "localrule "))
    } - {"all"}


@pytest.fixture(scope="module")
def study_copy(tmp_path_factory):
    """A copy of the workflow and package that ran a one-case tiny study (frames kept,
    so that post-processing can rerun alone)."""
    copy = tmp_path_factory.mktemp("repo")
    shutil.copy(REPO / "Snakefile", copy)
    shutil.copytree(REPO / "workflow", copy / "workflow")
    shutil.copytree(REPO / "src", copy / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    study = yaml.safe_load(TINY.read_text())
    study["keep_frames"] = True
    study["cases"] = {"good": study["cases"]["good"]}
    study["lucky"]["detector_sweep"]["cases"] = []
    study["figures"] = {
        "quality": dict(study["figures"]["quality"], cases=["good"]),
        "longexp": dict(study["figures"]["longexp"], cases=["good"]),
    }
    workdir = copy / "run"
    (workdir / "config").mkdir(parents=True)
    (workdir / "config" / "config.yaml").write_text(yaml.safe_dump(study))
    result = _snakemake(copy, workdir)
    assert result.returncode == 0, result.stderr[-3000:]
    assert _rules_planned(_snakemake(copy, workdir, "--dry-run")) == set()
    return copy, workdir


def test_a_copied_checkout_with_its_finished_study_is_up_to_date(study_copy, tmp_path):
    """The checkout copied with its study (times kept, as ``cp -a`` does): its code inputs
    are named relative to the study folder, so the copy's dry run plans nothing."""
    copy, _ = study_copy
    moved = tmp_path / "moved"
    shutil.copytree(copy, moved, symlinks=True)
    assert _rules_planned(_snakemake(moved, moved / "run", "--dry-run")) == set()


def test_a_job_that_finds_nan_in_its_input_names_it_and_the_next_run_remakes_it(study_copy, tmp_path):
    """NaN written into a finished case's telemetry: its post-processing (forced) fails naming
    the telemetry file, not its own output, and the next run of it remakes the telemetry with
    the simulation that made it (the file set aside as ``telemetry.nc.bad``)."""
    copy, _ = study_copy
    moved = tmp_path / "copy"
    shutil.copytree(copy, moved, symlinks=True)
    telemetry = moved / "run" / "results" / "cases" / "good" / "telemetry.nc"
    with netCDF4.Dataset(telemetry, "r+") as nc:
        name, variable = next(
            (name, v)
            for name, v in nc.variables.items()
            if v.dtype.kind == "f" and "frame" in v.dimensions and name != "axis_strehl"
        )
        variable[(0,) * variable.ndim] = np.nan
    failed = _snakemake(moved, moved / "run", "--forcerun", "lucky")
    assert failed.returncode != 0
    log = (moved / "run" / "logs" / "lucky" / "good.log").read_text()
    assert f"telemetry file 'results/cases/good/telemetry.nc': variable '{name}' is not finite" in log, log
    assert telemetry.with_name("telemetry.nc.bad").exists()
    remake = _snakemake(moved, moved / "run", "--dry-run", "results/cases/good/lucky.nc")
    assert _rules_planned(remake) == {"simulate", "lucky"}


@pytest.mark.parametrize("module", sorted(EXPECTED))
def test_a_code_edit_reruns_exactly_the_steps_that_depend_on_it(study_copy, module):
    copy, workdir = study_copy
    path = copy / "src" / "luckyao" / module
    original = path.read_text()
    try:
        path.write_text(original + "\n_EDITED_FOR_THE_DEPENDENCY_TEST = 1\n")
        planned = _rules_planned(_snakemake(copy, workdir, "--dry-run"))
    finally:
        path.write_text(original)
    assert planned == EXPECTED[module]


def test_a_post_processing_setting_reruns_no_time_loop(study_copy):
    """A new selection fraction or detector changes only the lucky step's params: with
    the frames kept (the quick study's default), no simulation reruns."""
    copy, workdir = study_copy
    overlay = workdir / "fractions.yaml"
    overlay.write_text(yaml.safe_dump({"lucky": {"fractions": [0.05, 0.1, 0.5, 1.0]}}))
    assert _rules_planned(_snakemake(copy, workdir, "--dry-run", "--configfile", str(overlay))) == {
        "lucky",
        "figure",
        "export",
    }


def test_a_name_imported_from_a_package_depends_on_the_module_that_defines_it(tmp_path):
    """Packages re-export their public objects lazily (``luckyao.exports``): importing a package
    imports none of its modules, so the closure of ``from luckyao.lucky import run_lucky`` holds
    ``lucky/pipeline.py`` (followed through ``EXPORTS``) and not the package's other modules."""
    from luckyao.jobs.code_deps import PACKAGE_ROOT, import_closure

    copy = tmp_path / "luckyao"
    shutil.copytree(PACKAGE_ROOT, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "user.py").write_text("from luckyao.lucky import run_lucky\nfrom luckyao.optics import Imager\n")
    files = {str(p.relative_to(copy)) for p in import_closure("luckyao.user", copy)}
    assert {"lucky/pipeline.py", "lucky/__init__.py", "optics/imaging.py"} <= files
    assert "optics/long_exposure.py" not in files and "figures.py" not in files
