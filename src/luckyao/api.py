"""The Python interface: open a study's results as xarray datasets, redraw a figure,
and run one case from a config dict without Snakemake (for exploration)::

    import luckyao
    lucky = luckyao.open_case("ltao_r0_13.5cm")            # results/cases/<case>/lucky.nc
    data = luckyao.open_figure("r0")                         # figures/r0.nc, the figure's tidy data
    fig = luckyao.draw(data)                                 # the figure again, as a matplotlib Figure
    study = luckyao.load_study("config/config.yaml")
    mine = luckyao.run_case(study, {"atmosphere": {"r0_500nm_m": 0.10}})   # an override of base

``run_case`` runs the workflow's own steps (screens, reconstructor, AO commands, time
loop, post-processing) as the workflow runs them, without Snakemake, so its numbers are
the workflow's for the same config and seed. A walk-through: ``docs/examples/tutorial.py``.
"""

import copy
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import xarray as xr

from .studyspec.lucky import fourier_cases, sweep_cases
from .studyspec.schema import ConfigError
from .studyspec.study import load_study as _load_study
from .studyspec.study import validate_study
from .threads import ONE_THREAD

__all__ = ["open_case", "open_telemetry", "open_figure", "draw", "load_study", "run_case", "export_fits"]


def load_study(*paths) -> dict:
    """A study config from YAML files (later ones merged over earlier ones, sweeps
    expanded), validated; raises ``ConfigError`` naming the key."""
    from .studyspec.sweeps import expand_study

    study, _ = _load_study(*paths)
    return expand_study(study)


def _open(path: Path, what: str) -> xr.Dataset:
    from .io.datasets import open_dataset

    return open_dataset(path, what)


def open_case(case: str, study_dir=".") -> xr.Dataset:
    """A finished case's lucky-imaging results (``results/cases/<case>/lucky.nc``):
    integrated-image Strehl, FWHM, d50 per criterion, fraction, detector and target,
    with errors, images and per-frame values."""
    return _open(Path(study_dir) / "results" / "cases" / case / "lucky.nc", f"case {case!r} lucky")


def open_telemetry(case: str, study_dir=".") -> xr.Dataset:
    """A finished case's per-frame telemetry (``results/cases/<case>/telemetry.nc``)."""
    return _open(Path(study_dir) / "results" / "cases" / case / "telemetry.nc", f"case {case!r} telemetry")


def open_figure(fig_id: str, study_dir=".") -> xr.Dataset:
    """A drawn figure's tidy dataset (``figures/<id>.nc``); its settings are in
    ``attrs['config_json']``."""
    return _open(Path(study_dir) / "figures" / f"{fig_id}.nc", f"figure {fig_id!r}")


def draw(data: xr.Dataset, title: str | None = None):
    """The matplotlib Figure of a figure's dataset (:func:`open_figure`), drawn as the
    workflow draws it."""
    from .figures import FIGURE_KINDS
    from .io.kinds import require_kind

    require_kind(data, "luckyao figure ", "luckyao.draw")
    settings = json.loads(data.attrs["config_json"])
    return FIGURE_KINDS[settings["kind"]][1](data, title or str(data.attrs.get("title", "")).split()[-1])


def export_fits(lucky_path, out_path, detectors=None, registrations=None, layout: str = "images") -> int:
    """A case's images as FITS (see ``luckyao export``; ``layout`` ``images`` or ``cube``);
    returns the number of images."""
    from .io.fits import export_fits as export

    return export(lucky_path, out_path, detectors, registrations, layout)


def _step(*argv: str) -> None:
    """One workflow step, run as the workflow runs it: ``python -m luckyao <step> ...``
    with the libraries on one thread (:mod:`luckyao.threads`, as the workflow runs every step: the
    same rounding, so the same numbers); a failure raises with the step's own message."""
    done = subprocess.run(
        [sys.executable, "-m", "luckyao", *argv], env={**os.environ, **ONE_THREAD}, capture_output=True, text=True
    )
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"luckyao {argv[0]} failed: {last}")


def run_case(study: dict, case, name: str = "explore", workdir=None) -> xr.Dataset:
    """Run one case of ``study`` (a study config as :func:`load_study` gives) and return its
    lucky-imaging results (as :func:`open_case`). ``case`` is the name of one of the
    study's cases, or a dict of overrides of its ``base`` (then called ``name``). The files
    go to ``workdir`` (kept), by default to a temporary folder removed afterwards. The screens
    are as long as the case (unless the study pins ``turbulence.duration_s``).
    Each step runs in a process of its own, on one thread, as the workflow's: the time loop
    is the ``simulate`` step's, :class:`luckyao.steps.simulation.TimeLoop` (its LGS
    chain measured in the loop: the numbers of the workflow's replayed slopes and LGS twins,
    ``tests/test_ao_loop.py``). A case with a learned criterion (``ao.learned_training_seed``)
    runs its training twin and fits the model first, as the workflow does."""
    from .io.hashing import canonical_json
    from .studyspec.view import resolve_study

    study = copy.deepcopy(study)
    if isinstance(case, dict):
        if name in study.get("cases", {}):
            raise ConfigError(f"run_case: the study already has a case named {name!r}; pass another name")
        study.setdefault("cases", {})[name] = case
    elif case in study.get("cases", {}):
        name = case
    else:
        raise ConfigError(f"run_case: no case {case!r} in the study; give its name or a dict of overrides of base")
    # the case alone, with the detector sweep if the study gives it one
    lucky = study["lucky"]
    if "detector_sweep" in lucky:
        lucky["detector_sweep"]["cases"] = [c for c in sweep_cases(lucky) if c == name]
    if "fourier" in lucky:
        lucky["fourier"]["cases"] = [c for c in fourier_cases(lucky) if c == name]
    study = {
        **{k: v for k, v in study.items() if k != "sweeps"},
        "cases": {name: study["cases"][name]},
        "figures": {},
    }
    view = resolve_study(study, validate_study(study))
    resolved = view.cases[name].config
    scratch = workdir is None
    root = Path(tempfile.mkdtemp(prefix="luckyao-") if scratch else workdir)
    root.mkdir(parents=True, exist_ok=True)

    def screens_of(turbulence) -> list[str]:
        """The screens' arguments of a step, the screens made first when missing."""
        screens = root / f"{turbulence.key}.npy"
        metadata = screens.with_suffix(".nc")
        if not metadata.exists():
            _step(
                "turbulence",
                "--spec",
                canonical_json(turbulence.spec),
                "--screens",
                str(screens),
                "--metadata",
                str(metadata),
            )
        return ["--screens", str(screens), "--screens-metadata", str(metadata)]

    try:
        screens = screens_of(view.cases[name].screens)
        products = []
        for step in ("reconstructor", "commands", "calibration"):
            product = getattr(view.cases[name], step)
            path = root / f"{product.key}.nc" if product is not None else None
            if path is not None and not path.exists():
                _step(step, "--spec", canonical_json(product.spec), "--out", str(path))
            products += [f"--{step}", str(path) if path else ""]
        frames, telemetry, lucky = (root / name / f for f in ("frames.nc", "telemetry.nc", "lucky.nc"))
        frames.parent.mkdir(exist_ok=True)
        _step(
            "simulate",
            "--case",
            canonical_json(resolved),
            "--name",
            name,
            "--seed",
            str(study["seed"]),
            *screens,
            *products,
            "--frames",
            str(frames),
            "--telemetry",
            str(telemetry),
        )
        learned = []
        twin = view.cases[name].training
        if twin is not None:  # the learned criterion, fitted on the case run with another seed
            training, model = root / name / "training_telemetry.nc", root / name / "learned.nc"
            arguments = ["--case", canonical_json(twin.config), "--name", f"{name}.training", "--seed", str(twin.seed)]
            _step("simulate", *arguments, *screens_of(twin.screens), *products, "--telemetry", str(training))
            _step("learn", "--telemetry", str(training), "--out", str(model))
            learned = ["--learned-model", str(model)]
        _step(
            "lucky",
            "--settings",
            canonical_json(view.cases[name].lucky_settings),
            "--frames",
            str(frames),
            "--telemetry",
            str(telemetry),
            "--out",
            str(lucky),
            *screens,
            *learned,
        )
        return _open(lucky, "lucky")
    finally:
        if scratch:
            shutil.rmtree(root, ignore_errors=True)
