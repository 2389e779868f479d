"""The study through SLURM on a real one-node cluster: tools/slurm-local.sh installs slurm-wlm
and munge when missing, starts munged, slurmctld and slurmd, runs the tiny study through
profiles/slurm, checks every job went through sbatch and the outputs equal a local run's, and
stops the daemons. It takes about 5 minutes (a local and a SLURM run of the tiny study), so it
runs only when asked: LUCKYAO_SLURM_TEST=1 bash run.sh test -k slurm"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.workflow  # runs Snakemake, a study or the command line: -m 'not workflow' skips it

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "tools" / "slurm-local.sh"
SLURM_TOOLS = ("slurmctld", "slurmd", "sbatch", "squeue", "munged")


def skip_reason() -> str | None:
    """Why the SLURM test cannot or should not run here, or None."""
    if os.environ.get("LUCKYAO_SLURM_TEST") != "1":
        return (
            "SLURM end-to-end test (about 5 minutes, root, starts SLURM daemons) not requested: "
            "set LUCKYAO_SLURM_TEST=1 to run tools/slurm-local.sh"
        )
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        return "tools/slurm-local.sh must run as root (it installs packages and starts munged, slurmctld, slurmd)"
    missing = [
        tool for tool in SLURM_TOOLS if shutil.which(tool, path=os.environ.get("PATH", "") + ":/usr/sbin:/sbin") is None
    ]
    if missing and shutil.which("apt-get") is None:
        return f"SLURM is not installed ({', '.join(missing)} missing) and there is no apt-get to install slurm-wlm"
    if Path("/etc/slurm/slurm.conf").exists():
        return "this machine has a SLURM configuration of its own (/etc/slurm/slurm.conf); the test would shadow it"
    return None


@pytest.mark.skipif(skip_reason() is not None, reason=skip_reason() or "")
def test_tiny_study_through_a_real_slurm_equals_a_local_run():
    script = subprocess.Popen(
        ["bash", str(SCRIPT)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHON": sys.executable},
    )
    try:
        stdout, stderr = script.communicate(timeout=1800)
    except subprocess.TimeoutExpired:
        script.terminate()  # the script stops its Snakemake run and the daemons it started
        stdout, stderr = script.communicate(timeout=600)
        pytest.fail(f"tools/slurm-local.sh took over 30 minutes:\n{stdout[-3000:]}")
    print(stdout)
    print(stderr[-5000:])
    assert script.returncode == 0, stdout[-3000:] + stderr[-3000:]
    summary = re.search(r"SLURM run: (\d+) jobs, (\d+) through sbatch", stdout)
    local = re.search(r"(\d+) local \(([^)]*)\)", stdout)
    assert local and set(local[2].split(", ")) <= {"all", "figure", "export"}
    assert summary and int(summary[2]) == int(summary[1]) - int(local[1]) > 0  # every job but the short local ones
    assert re.search(r"outputs equal the local run's: (\d+) of \1 netCDF", stdout)
    assert re.search(r"report.html holds (\d+) of \1 figures", stdout)
    assert "stopped the daemons it started: munged slurmctld slurmd" in stdout
    assert stdout.rstrip().endswith("slurm-local: PASSED")
