"""Nothing lost, nothing silently wrong (issue 40): a set-aside or missing intermediate is
remade with what depends on it; NaN in a lucky.nc is refused by every reader; a command
run by hand never moves the files it reads; every job holds the study's run lock, so a
job orphaned by a killed Snakemake keeps the study locked; a copied or moved checkout
rebuilds a .venv made for another."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr
import yaml

from luckyao.cli import main
from luckyao.threads import STUDY_JOB

from studies import REPO, TINY, snakemake, snakemake_command


def planned(result) -> set[tuple[str, str]]:
    """(rule, wildcards) of every job a dry run plans, rule ``all`` left out."""
    jobs, rule = [], None
    for line in result.stdout.splitlines():
        line = line.strip()
        if line.startswith(("rule ", "localrule ")):
            rule = line.split()[1].rstrip(":")
            jobs.append([rule, ""])
        elif line.startswith("wildcards:") and jobs:
            jobs[-1][1] = line.split(":", 1)[1].strip()
    return {(rule, wildcards) for rule, wildcards in jobs if rule != "all"}


def rules(jobs) -> set[str]:
    return {rule for rule, _ in jobs}


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished run of a two-case tiny study (frames kept): ``good`` without AO, ``ltao``
    with the LGS chain's products (screens, reconstructor, command matrix, slopes)."""
    workdir = tmp_path_factory.mktemp("finished")
    study = yaml.safe_load(TINY.read_text())
    study["keep_frames"] = True
    study["cases"] = {name: study["cases"][name] for name in ("good", "ltao")}
    study["lucky"]["detector_sweep"]["cases"] = []
    study["figures"] = {"table": dict(study["figures"]["table"], cases=["good", "ltao"])}
    (workdir / "config").mkdir()
    (workdir / "config" / "config.yaml").write_text(yaml.safe_dump(study))
    result = snakemake(workdir)
    assert result.returncode == 0, result.stderr[-3000:]
    assert planned(snakemake(workdir, "--dry-run")) == set()
    return workdir


def copy_of(finished: Path, tmp_path: Path) -> Path:
    """The finished study copied with its times (as ``cp -a``)."""
    copy = tmp_path / "study"
    shutil.copytree(finished, copy, symlinks=True)
    return copy


def product(workdir: Path, folder: str) -> Path:
    """The one product file of ``results/<folder>/`` (``.nc``; the screens' ``.npy``)."""
    pattern = "*.npy" if folder == "turbulence" else "*.nc"
    (path,) = (workdir / "results" / folder).glob(pattern)
    return path


# --- 1. a set-aside or missing intermediate is remade, with what depends on it -----------------


@pytest.mark.workflow
def test_the_issues_reproduction_a_truncated_telemetry_is_remade_by_the_next_run(finished, tmp_path):
    """``truncate -s 20000 telemetry.nc``: the run fails and sets it aside; the next one remakes
    it, the case's lucky.nc (deleted by Snakemake with the failed job) and the figure and
    FITS file that show it, identical to the first run's; before, it said "Nothing to be done"
    with the case's lucky.nc gone."""
    workdir = copy_of(finished, tmp_path)
    case = workdir / "results" / "cases" / "good"
    before = xr.load_dataset(case / "lucky.nc")
    figure_time = (workdir / "figures" / "table.png").stat().st_mtime
    with open(case / "telemetry.nc", "r+b") as f:
        f.truncate(20000)
    failed = snakemake(workdir)
    assert failed.returncode != 0
    assert "set aside as 'results/cases/good/telemetry.nc.bad': the next run remakes it" in failed.stderr
    assert not (case / "telemetry.nc").exists() and not (case / "lucky.nc").exists()
    again = snakemake(workdir)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "Nothing to be done" not in again.stdout + again.stderr
    assert xr.load_dataset(case / "lucky.nc").drop_attrs().identical(before.drop_attrs())
    assert (workdir / "figures" / "table.png").stat().st_mtime > figure_time
    assert (workdir / "fits" / "good.fits").stat().st_mtime > figure_time
    assert planned(snakemake(workdir, "--dry-run")) == set()


SIMULATION = {"simulate", "lucky", "figure", "export"}
"""What reruns after a case's simulation inputs are remade: the case and all it feeds."""


@pytest.mark.workflow
@pytest.mark.parametrize(
    "what, consumer, outputs, expected",
    [
        ("good/telemetry.nc", "good", ["lucky.nc"], {"simulate", "lucky", "figure", "export"}),
        ("good/frames.nc", "good", ["lucky.nc"], {"simulate", "lucky", "figure", "export"}),
        ("turbulence", "good", ["frames.nc", "telemetry.nc"], {"turbulence", "lgs_slopes", *SIMULATION}),
        ("reconstructors", "ltao", ["frames.nc", "telemetry.nc"], {"reconstructor", *SIMULATION}),
        ("commands", "ltao", ["frames.nc", "telemetry.nc"], {"commands", *SIMULATION}),
        ("slopes", "ltao", ["frames.nc", "telemetry.nc"], {"lgs_slopes", *SIMULATION}),
    ],
)
def test_an_input_set_aside_by_a_failed_job_is_remade_with_what_depends_on_it(
    finished, tmp_path, what, consumer, outputs, expected
):
    """The state a job leaves that found its input bad (truncated, NaN): the input set aside
    as ``.bad``, the job's own ``outputs`` deleted by Snakemake (the lucky job's, the
    simulation's). The next run remakes the input and the case, and redraws what shows it
    (before: nothing planned, the case gone)."""
    workdir = copy_of(finished, tmp_path)
    cases = workdir / "results" / "cases"
    path = cases / what if "/" in what else product(workdir, what)
    path.rename(path.with_name(path.name + ".bad"))
    for name in outputs:
        (cases / consumer / name).unlink(missing_ok=True)
    jobs = planned(snakemake(workdir, "--dry-run"))
    assert rules(jobs) == expected, jobs
    assert ("lucky", f"case={consumer}") in jobs and ("export", f"case={consumer}") in jobs


@pytest.mark.workflow
@pytest.mark.parametrize(
    "what, step", [("reconstructors", "reconstructor"), ("slopes", "lgs_slopes"), ("turbulence", "turbulence")]
)
def test_a_deleted_product_is_remade_and_what_read_it_rerun(finished, tmp_path, what, step):
    """A product deleted whose consumers' outputs are all there is remade, and the cases that
    read it rerun (the simulations read the LGS slopes as ``ancient``, yet a slopes product
    that must be made again reruns them: Snakemake's rule, said in the README)."""
    workdir = copy_of(finished, tmp_path)
    product(workdir, what).unlink()
    assert {step, *SIMULATION} <= rules(planned(snakemake(workdir, "--dry-run")))


@pytest.mark.workflow
def test_a_study_with_a_case_missing_is_not_archived(finished, tmp_path, capsys):
    """``luckyao archive`` names the case whose results are missing (before: archived without it)."""
    workdir = copy_of(finished, tmp_path)
    (workdir / "results" / "cases" / "good" / "telemetry.nc").rename(
        workdir / "results" / "cases" / "good" / "telemetry.nc.bad"
    )
    (workdir / "results" / "cases" / "good" / "lucky.nc").unlink()
    assert main(["archive", "--study-dir", str(workdir), "--out", str(tmp_path / "a.tar")]) == 1
    err = capsys.readouterr().err
    assert "case 'good': results/cases/good/lucky.nc missing" in err
    assert "case 'good': results/cases/good/telemetry.nc missing" in err
    assert not (tmp_path / "a.tar").exists()


# --- 2. NaN in lucky.nc: every reader refuses it, naming the variable and the index -------------


def poke_nan(path: Path, detector: str) -> None:
    """NaN into the integrated Strehl of ``detector`` (first registration, criterion, fraction)."""
    with netCDF4.Dataset(path, "r+") as nc:
        index = [str(d) for d in nc["detector"][:]].index(detector)
        dims = nc["strehl"].dimensions
        where = tuple(index if dim == "detector" else 0 for dim in dims)
        nc["strehl"][where] = np.nan


@pytest.mark.workflow
def test_nan_in_a_lucky_file_is_refused_by_the_figure_the_export_and_the_archive(finished, tmp_path, capsys):
    workdir = copy_of(finished, tmp_path)
    lucky = workdir / "results" / "cases" / "good" / "lucky.nc"
    poke_nan(lucky, "noiseless")
    message = r"variable 'strehl' is not finite at .*detector=\d \('noiseless'\)"
    from luckyao.figures import draw_figure
    from luckyao.io.fits import export_fits

    with pytest.raises(ValueError, match=f"lucky file '{lucky}': {message}"):
        export_fits(lucky, tmp_path / "good.fits")
    assert not (tmp_path / "good.fits").exists()
    settings = sorted((workdir / "results" / "figures" / "settings").glob("table_*.json"))[-1]
    with pytest.raises(ValueError, match=message):
        draw_figure(
            "table",
            json.loads(settings.read_text()),
            [lucky, workdir / "results/cases/ltao/lucky.nc"],
            str(tmp_path / "table"),
        )
    assert not (tmp_path / "table.nc").exists()
    assert main(["archive", "--study-dir", str(workdir), "--out", str(tmp_path / "a.tar")]) == 1
    assert "case 'good': lucky file" in capsys.readouterr().err
    assert not (tmp_path / "a.tar").exists()
    assert lucky.exists(), "a reader run by hand set the file aside"


@pytest.mark.workflow
def test_nan_where_a_noisy_image_has_no_flux_is_accepted(finished, tmp_path):
    """A noisy detector's undefined metric (no positive flux) is no error: the writer allows it."""
    workdir = copy_of(finished, tmp_path)
    lucky = workdir / "results" / "cases" / "good" / "lucky.nc"
    poke_nan(lucky, "faint")
    from luckyao.io.fits import export_fits

    assert export_fits(lucky, tmp_path / "good.fits") > 0


# --- 4. a command run by hand never moves, renames or writes what it reads ----------------------


def test_export_of_a_file_that_is_not_a_lucky_dataset_leaves_it_alone(tmp_path):
    """``luckyao export README.md --out x.fits`` renamed README.md to README.md.bad."""
    readme = tmp_path / "README.md"
    shutil.copy(REPO / "README.md", readme)
    env = {k: v for k, v in os.environ.items() if k != STUDY_JOB}
    done = subprocess.run(
        [sys.executable, "-m", "luckyao", "export", "README.md", "--out", "x.fits"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
    )
    assert done.returncode == 1
    assert "README.md" in done.stderr and ".bad" not in done.stderr and "remakes" not in done.stderr
    assert readme.read_bytes() == (REPO / "README.md").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["README.md"]


def corrupt_study(tmp_path: Path) -> Path:
    """A study folder whose lucky.nc, telemetry.nc and figure data are not netCDF."""
    for name in ("results/cases/c/lucky.nc", "results/cases/c/telemetry.nc", "figures/f.nc"):
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"not a netCDF file" * 100)
    return tmp_path


@pytest.mark.parametrize("opener", ["open_case", "open_telemetry", "open_figure"])
def test_the_python_interface_never_sets_a_file_aside(tmp_path, monkeypatch, opener):
    import luckyao

    study = corrupt_study(tmp_path)
    monkeypatch.chdir(study)
    name = "f" if opener == "open_figure" else "c"
    with pytest.raises(OSError, match="unreadable or corrupt") as raised:
        getattr(luckyao, opener)(name)
    assert "set aside" not in str(raised.value)
    assert sorted(p.name for p in study.rglob("*") if p.is_file()) == ["f.nc", "lucky.nc", "telemetry.nc"]


def test_a_job_sets_aside_only_files_of_its_study_folder(tmp_path, monkeypatch):
    """Even a job of the workflow sets aside only a file under its study folder's results/
    (not one given by another path, nor one that only links into it)."""
    from luckyao.io.datasets import open_dataset

    study = corrupt_study(tmp_path / "study")
    elsewhere = tmp_path / "elsewhere.nc"
    elsewhere.write_bytes(b"not a netCDF file")
    link = study / "results" / "link.nc"
    link.symlink_to(elsewhere)
    monkeypatch.setenv(STUDY_JOB, "1")
    monkeypatch.chdir(study)
    for path in (elsewhere, link, study / "figures" / "f.nc"):
        with pytest.raises(OSError, match="corrupt") as raised:
            open_dataset(path, "x")
        assert "set aside" not in str(raised.value) and path.exists()
    with pytest.raises(OSError, match="set aside"):
        open_dataset("results/cases/c/lucky.nc", "lucky")
    assert (study / "results" / "cases" / "c" / "lucky.nc.bad").exists()
    monkeypatch.delenv(STUDY_JOB)
    with pytest.raises(OSError, match="corrupt") as raised:
        open_dataset("results/cases/c/telemetry.nc", "telemetry")
    assert "set aside" not in str(raised.value)


# --- 5. every job holds the run lock: an orphaned job keeps the study locked ---------------------


def children(pid: int) -> list[int]:
    """Every descendant of ``pid`` (Linux /proc)."""
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    found, todo = [], [pid]
    while todo:
        for child in parents.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def holds_flock(pid: int, path: Path) -> bool:
    """Whether process ``pid`` holds a flock on ``path`` (/proc/locks, by inode)."""
    inode = path.stat().st_ino
    for line in Path("/proc/locks").read_text().splitlines():
        fields = line.split()
        if (
            len(fields) >= 6
            and fields[1] == "FLOCK"
            and fields[4] == str(pid)
            and fields[5].rsplit(":", 1)[-1] == str(inode)
        ):
            return True
    return False


def is_job(pid: int) -> bool:
    try:
        return b"luckyao\x00lucky" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


@pytest.mark.workflow
def test_a_job_orphaned_by_a_killed_snakemake_keeps_the_study_locked(finished, tmp_path):
    """``kill -9`` of Snakemake's main process alone: its running job lives on. It holds the
    study's run lock itself, so ``bash run.sh study`` leaves the study alone (the half-written
    file the job may be writing kept); once the job has ended, the study is cleaned up as after
    any hard kill. Before, run.sh called the lock stale and deleted the orphan's file."""
    workdir = copy_of(finished, tmp_path)
    lock = workdir / ".snakemake" / "luckyao-run.lock"
    run = subprocess.Popen(
        snakemake_command(workdir, "--forcerun", "lucky", "results/cases/good/lucky.nc", cores=1),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    job, orphans = None, []
    try:
        deadline = time.monotonic() + 300
        while job is None:
            assert run.poll() is None and time.monotonic() < deadline, "no job ever held the study's run lock"
            job = next((pid for pid in children(run.pid) if is_job(pid) and holds_flock(pid, lock)), None)
            time.sleep(0.02)
        orphans = children(run.pid)
        os.kill(run.pid, signal.SIGKILL)  # Snakemake's main process alone
        run.wait()
        for pid in orphans:  # the orphans live on, held still while run.sh looks
            os.kill(pid, signal.SIGSTOP)
        partial = workdir / "results" / "cases" / "good" / "lucky.nc.partial"
        partial.write_bytes(b"the orphan's half-written file")
        result = subprocess.run(
            ["bash", str(REPO / "run.sh"), "study", "-d", str(workdir), "-n"],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert "is using" in result.stderr, result.stderr[-2000:]
        assert partial.exists(), "the orphan's file was deleted"
        assert any((workdir / ".snakemake" / "locks").iterdir()), "the killed run's Snakemake lock was removed"
        for pid in orphans:
            os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + 30
        while any(holds_flock(pid, lock) for pid in orphans) and time.monotonic() < deadline:
            time.sleep(0.05)
        result = subprocess.run(
            ["bash", str(REPO / "run.sh"), "study", "-d", str(workdir), "-n"],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert "is using" not in result.stderr and "stale lock" in result.stderr, result.stderr[-2000:]
        assert not partial.exists()
    finally:
        for pid in [run.pid, *children(run.pid), *orphans]:
            for sig in (signal.SIGKILL, signal.SIGCONT):
                try:
                    os.kill(pid, sig)
                except ProcessLookupError:
                    pass
        run.wait()


# --- 6. a copied or moved checkout rebuilds a .venv made for another -----------------------------

FAKE_PYTHON = """#!/usr/bin/env bash
# A stand-in for python: every call logged; "-m venv DIR" makes DIR/bin/python (this script).
echo "$*" >> "$FAKE_LOG"
if [ "$1" = -m ] && [ "$2" = venv ]; then mkdir -p "$3/bin"; cp "$FAKE_PYTHON_SCRIPT" "$3/bin/python"; fi
if [ "$1" = -c ]; then echo /nonexistent; fi
exit 0
"""


@pytest.fixture
def fake_checkout(tmp_path):
    """A checkout of run.sh alone, and ``run(folder)``: ``bash run.sh test`` there with a fake
    python (no packages installed), returning (its calls but the lint checks', stderr)."""
    script = tmp_path / "fake-python"
    script.write_text(FAKE_PYTHON)
    script.chmod(0o755)
    checkout = tmp_path / "checkout"
    checkout.mkdir()
    shutil.copy(REPO / "run.sh", checkout / "run.sh")
    (checkout / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    os.utime(checkout / "pyproject.toml", (1e9, 1e9))

    def run(folder: Path):
        log = tmp_path / "calls.log"
        log.unlink(missing_ok=True)
        env = dict(
            os.environ, PYTHON=str(script), FAKE_PYTHON_SCRIPT=str(script), FAKE_LOG=str(log), LUCKYAO_TEST_WORKERS="2"
        )
        done = subprocess.run(
            ["bash", str(folder / "run.sh"), "test", "-q"],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr
        lint = ("-m ruff ", "-m snakefmt ", "tools/lint_rules.py")  # the lint checks run.sh test runs first
        return [call for call in log.read_text().splitlines() if not call.startswith(lint)], done.stderr

    return checkout, run


SUITE = "-m pytest -n 2 --dist loadfile -q"
"""The suite's call by ``run.sh test -q``: its files over two processes (``LUCKYAO_TEST_WORKERS``)."""


def installs(calls: list[str]) -> bool:
    return any(call.startswith("-m pip install") and "-e" in call.split() for call in calls)


def test_a_venv_is_built_once_and_records_its_checkout(fake_checkout):
    checkout, run = fake_checkout
    calls, _ = run(checkout)
    assert calls[0].startswith("-m venv") and installs(calls) and calls[-1] == SUITE
    assert (checkout / ".venv" / ".luckyao-installed").read_text().strip() == str(checkout.resolve())
    calls, err = run(checkout)
    assert calls == [SUITE] and "rebuilding" not in err


def test_a_moved_checkout_rebuilds_its_venv(fake_checkout, tmp_path):
    """Moved with its .venv: the editable install and the scripts name the old place (before:
    ModuleNotFoundError); run.sh sees it and builds the .venv again for the new one."""
    checkout, run = fake_checkout
    run(checkout)
    (checkout / ".venv" / "old").write_text("a file of the .venv made for the old place")
    moved = tmp_path / "moved"
    checkout.rename(moved)
    calls, err = run(moved)
    assert f"not {moved.resolve()}: rebuilding it" in err
    assert calls[0].startswith("-m venv") and installs(calls)
    assert not (moved / ".venv" / "old").exists()
    assert (moved / ".venv" / ".luckyao-installed").read_text().strip() == str(moved.resolve())
    assert run(moved)[0] == [SUITE]


def test_a_copied_checkout_rebuilds_its_own_venv_and_leaves_the_originals(fake_checkout, tmp_path):
    """``cp -a``: the copy's .venv ran the original's code (its editable install); run.sh in the
    copy rebuilds the copy's .venv, and the original's stays as it was."""
    checkout, run = fake_checkout
    run(checkout)
    (checkout / ".venv" / "old").write_text("the original's")
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-a", str(checkout), str(copy)], check=True)
    calls, err = run(copy)
    assert "rebuilding" in err and calls[0].startswith("-m venv") and installs(calls)
    assert (copy / ".venv" / ".luckyao-installed").read_text().strip() == str(copy.resolve())
    assert (checkout / ".venv" / "old").exists()
    assert (checkout / ".venv" / ".luckyao-installed").read_text().strip() == str(checkout.resolve())
    assert run(checkout)[0] == [SUITE]


def test_a_venv_of_an_older_run_sh_is_judged_by_its_editable_install(fake_checkout):
    """An empty stamp (run.sh before this): the .venv is this checkout's if its editable install
    names this checkout's src/ (no rebuild), else rebuilt."""
    checkout, run = fake_checkout
    run(checkout)
    site = checkout / ".venv" / "lib" / "python3.11" / "site-packages"
    site.mkdir(parents=True)
    (checkout / ".venv" / ".luckyao-installed").write_text("")
    pth = site / "__editable__.luckyao-0.1.0.pth"
    pth.write_text(f"{checkout.resolve()}/src\n")
    assert run(checkout)[0] == [SUITE]
    pth.write_text("/somewhere/else/src\n")
    calls, err = run(checkout)
    assert "built for /somewhere/else" in err and installs(calls)
