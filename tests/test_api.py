"""The Python tutorial (docs/examples/tutorial.py) runs as written: a case run without Snakemake,
its results read, its images written as FITS and read back.

It runs in a folder holding only the study's config, so whether a study was run in this
checkout (its last step reads a finished study's files) does not change what it is tested on."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.workflow  # runs Snakemake, a study or the command line: -m 'not workflow' skips it

REPO = Path(__file__).resolve().parents[1]


def test_the_tutorial_runs_and_prints_what_it_promises(tmp_path):
    checkout = tmp_path / "checkout"
    shutil.copytree(REPO / "config", checkout / "config")
    result = subprocess.run(
        [sys.executable, str(REPO / "docs" / "examples" / "tutorial.py"), str(tmp_path)],
        cwd=checkout,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    lines = result.stdout.splitlines()
    assert sum(line.startswith("selection by lgs_rms") for line in lines) == 9  # one per fraction
    fits_line = next(line for line in lines if ".fits:" in line)
    assert "images; 1 % by lgs_rms: Strehl" in fits_line and "800 nm" in fits_line
    assert (tmp_path / "ltao_r0_10cm.fits").stat().st_size > 0
    assert (tmp_path / "run" / "ltao_r0_10cm" / "lucky.nc").exists()
