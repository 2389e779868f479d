"""The set-up: the .venv pinned by the lock, the optional extras, the licence and the citation."""

import subprocess
import sys
import tomllib

import pytest
import yaml
from packaging.utils import canonicalize_name

from studies import REPO

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())


def pins(path) -> dict[str, str]:
    """Canonical name -> version of a lock's ``name==version`` lines."""
    lines = [line.strip() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    assert all(line.count("==") == 1 for line in lines), path
    return {canonicalize_name(name): version for name, version in (line.split("==") for line in lines)}


@pytest.mark.skipif(sys.prefix != str(REPO / ".venv"), reason="checks run.sh's .venv of this checkout")
def test_the_venv_equals_the_lock_package_for_package():
    """run.sh's .venv holds exactly requirements.lock (and requirements-docs.lock once the docs
    were built), the package itself aside (before: unpinned lower bounds, 6 packages off)."""
    freeze = subprocess.run(
        [sys.executable, "-m", "pip", "freeze", "--exclude-editable"], capture_output=True, text=True, check=True
    ).stdout
    installed = {canonicalize_name(n): v for n, v in (line.split("==") for line in freeze.split() if "==" in line)}
    expected = pins(REPO / "requirements.lock")
    if (REPO / ".venv" / ".luckyao-docs-installed").exists():
        expected |= pins(REPO / "requirements-docs.lock")
    differences = {
        name: (expected.get(name, "absent"), installed.get(name, "absent"))
        for name in set(expected) | set(installed)
        if expected.get(name) != installed.get(name)
    }
    assert not differences, f"(lock, .venv): {differences}"


def test_the_locks_pin_registry_releases_only():
    """Every pin a release that pip finds on any machine: no local version (+cpu), URL or path."""
    for name in ("requirements.lock", "requirements-docs.lock"):
        for package, version in pins(REPO / name).items():
            assert "+" not in version and "/" not in version and "@" not in package, (name, package, version)
    assert not set(pins(REPO / "requirements.lock")) & set(pins(REPO / "requirements-docs.lock"))
    assert "luckyao" not in pins(REPO / "requirements.lock")


def test_run_sh_installs_from_the_lock_and_refreshes_it():
    run_sh = (REPO / "run.sh").read_text()
    assert "-r requirements.lock" in run_sh and "lock)" in run_sh


def test_the_physics_installs_without_the_workflow_the_figures_and_fits():
    """``pip install luckyao``: the physics alone; Snakemake, matplotlib and astropy are extras
    (before: all 79 packages, 885 MB, for everyone)."""
    core = {canonicalize_name(r.split(">")[0].split("=")[0]) for r in PYPROJECT["project"]["dependencies"]}
    assert {"numpy", "scipy", "numba", "pyfftw", "xarray", "netcdf4"} <= core
    assert not core & {"snakemake", "matplotlib", "astropy"}
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert extras["workflow"][0].startswith("snakemake") and extras["plots"][0].startswith("matplotlib")
    assert extras["fits"][0].startswith("astropy") and "luckyao[workflow,plots,fits]" in extras["test"]


def test_the_physics_imports_without_the_extras():
    """A case's simulation and lucky post-processing import none of the extras' packages."""
    blocked = ("snakemake", "matplotlib", "astropy")
    code = (
        "import sys\n"
        "class Block:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        f"        if name.split('.')[0] in {blocked!r}: raise ImportError(name)\n"
        "sys.meta_path.insert(0, Block())\n"
        "import luckyao.steps.screens, luckyao.steps.simulation, luckyao.steps.postprocess, luckyao.api\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]


def test_the_licence_is_bsd_3_clause_everywhere():
    assert PYPROJECT["project"]["license"] == "BSD-3-Clause"
    assert (REPO / "LICENSE").read_text().startswith("BSD 3-Clause License")
    citation = yaml.safe_load((REPO / "CITATION.cff").read_text())
    assert citation["license"] == "BSD-3-Clause"


def test_the_citation_file_cites_the_paper_the_study_reproduces():
    """CITATION.cff (CFF 1.2.0; checked with cffconvert --validate when written): the software,
    its version, and Basden (2014) as its reference."""
    citation = yaml.safe_load((REPO / "CITATION.cff").read_text())
    assert citation["cff-version"] == "1.2.0" and citation["type"] == "software"
    assert citation["version"] == PYPROJECT["project"]["version"] and citation["authors"]
    paper = citation["references"][0]
    assert paper["authors"][0]["family-names"] == "Basden" and paper["year"] == 2014
    assert paper["doi"] == "10.1093/mnras/stu941"
