"""Nothing lost: ``bash run.sh study`` clears a killed run's lock and ``*.partial`` files,
but never those of a live run, however that run was started."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from luckyao.jobs.live_run import study_folder

pytestmark = pytest.mark.workflow  # runs Snakemake, a study or the command line: -m 'not workflow' skips it

REPO = Path(__file__).resolve().parents[1]
TINY = REPO / "tests" / "data" / "tiny.yaml"


def one_case_study(workdir: Path) -> None:
    study = yaml.safe_load(TINY.read_text())
    study["cases"] = {"good": study["cases"]["good"]}
    study["lucky"]["detector_sweep"]["cases"] = []
    study["figures"] = {"longexp": dict(study["figures"]["longexp"], cases=["good"])}
    (workdir / "config").mkdir(parents=True)
    (workdir / "config" / "config.yaml").write_text(yaml.safe_dump(study))


def live_command(how: str, tmp_path: Path) -> tuple[list[str], Path]:
    """A Snakemake start on the workflow, and the folder it starts from: the venv's script by
    a relative path, ``python -m snakemake``, or the script through a symlinked folder."""
    bin_dir = Path(sys.executable).parent
    if how == "relative":
        return [os.path.relpath(bin_dir / "snakemake", REPO)], REPO
    if how == "module":
        return [sys.executable, "-m", "snakemake"], REPO
    link = tmp_path / "linked-bin"
    link.symlink_to(bin_dir)
    return [str(link / "snakemake")], tmp_path


@pytest.mark.parametrize("how", ["relative", "module", "symlink"])
def test_the_study_command_leaves_a_live_run_alone(tmp_path, how):
    """A run started by hand is caught holding Snakemake's lock (and stopped there, so it
    stays live); ``bash run.sh study -d DIR -n`` then keeps its lock and its files."""
    workdir = tmp_path / "study"
    one_case_study(workdir)
    planted = workdir / "results" / "cases" / "good" / "frames.nc.partial"
    planted.parent.mkdir(parents=True)
    planted.write_bytes(b"a live job's half-written file")
    command, cwd = live_command(how, tmp_path)
    live = subprocess.Popen(
        [*command, "-s", str(REPO / "Snakefile"), "-d", str(workdir), "--cores", "1"],
        cwd=cwd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        locks = workdir / ".snakemake" / "locks"
        deadline = time.monotonic() + 120
        while not (locks.is_dir() and any(locks.iterdir())):
            assert live.poll() is None and time.monotonic() < deadline, "the live run never took its lock"
            time.sleep(0.05)
        os.killpg(live.pid, signal.SIGSTOP)
        result = subprocess.run(
            ["bash", str(REPO / "run.sh"), "study", "-d", str(workdir), "-n"],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert result.returncode == 0, result.stderr[-2000:]
        assert planted.exists(), "the live job's file was deleted"
        assert any(locks.iterdir()), "the live run's lock was removed"
        assert "is using" in result.stderr
        assert "    input: " not in result.stderr, "the study's terminal lists each job's inputs"
    finally:
        os.killpg(live.pid, signal.SIGKILL)
        live.wait()


@pytest.mark.parametrize(
    "argv", [["-d", "D"], ["-dD"], ["--directory", "D"], ["--directory=D"], ["--cores", "2", "--dir", "D", "-n"]]
)
def test_every_form_of_the_directory_option_is_read(argv):
    assert study_folder(argv) == Path("D")
    assert study_folder(["--cores", "1"]) == Path(".")
