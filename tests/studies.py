"""The tiny study the tests run, and Snakemake on the repository's workflow: one home for what
the config, sweep and workflow tests share."""

import subprocess
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
TINY = REPO / "tests" / "data" / "tiny.yaml"


def tiny() -> dict:
    """The tiny study's config (``tests/data/tiny.yaml``), a fresh copy."""
    return yaml.safe_load(TINY.read_text())


def with_sweep(parameters: dict, overrides=None) -> dict:
    """The tiny study with a sweep ``grid`` over ``parameters`` and a figure drawing it."""
    study = tiny()
    study["sweeps"]["grid"] = {"parameters": parameters, **({"overrides": overrides} if overrides else {})}
    study["figures"]["grid"] = {
        "kind": "quality_vs_parameter",
        "sweep": "grid",
        "criteria": ["strehl"],
        "fractions": [1.0],
    }
    return study


def snakemake_command(workdir: Path, *args, cores: int = 2, module: str = "snakemake") -> list[str]:
    """Snakemake (or ``module``, e.g. ``luckyao.jobs.live_run``) on the repository's workflow in
    ``workdir``, whose study config is ``workdir/config/config.yaml`` (the workflow's ``configfile:``)."""
    return [
        sys.executable,
        "-m",
        module,
        "-s",
        str(REPO / "Snakefile"),
        "-d",
        str(workdir),
        "--cores",
        str(cores),
        *args,
    ]


def snakemake(workdir: Path, *args, cores: int = 2, module: str = "snakemake", timeout: float = 600):
    """:func:`snakemake_command` run to its end, its output captured."""
    return subprocess.run(
        snakemake_command(workdir, *args, cores=cores, module=module), capture_output=True, text=True, timeout=timeout
    )


def with_name(kind: str, name: str) -> tuple[dict, str]:
    """The tiny study with a case, figure or detector (``kind``) called ``name``, and the config
    key a refusal of the name must cite."""
    study = tiny()
    if kind == "case":
        study["cases"][name] = {}
        return study, "cases"
    if kind == "figure":
        study["figures"][name] = study["figures"]["longexp"]
        return study, "figures"
    study["lucky"]["detectors"][name] = {"photons_per_frame": None, "read_noise_e": 0.0}
    return study, "lucky.detectors"
