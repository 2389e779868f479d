"""One study folder, one run: the lock every run of the workflow holds, and the
cleanup after a hard kill that it makes safe.

Every Snakemake that parses this workflow holds a shared ``flock`` on
``.snakemake/luckyao-run.lock`` in its study folder from its start to its exit
(``hold_shared``, called by ``workflow/rules/common.smk``), however it was
started: ``bash run.sh study``, ``.venv/bin/snakemake`` by any path or symlink,
``python -m snakemake``; and so does every job of the workflow, itself, from its
start to its exit (``hold_job_lock``, called by ``luckyao.cli.main`` in a
process marked a job, ``STUDY_JOB``), so that a job left running by a
Snakemake killed alone (``kill -9`` of its main process) keeps the folder locked
while it lives and writes. The kernel releases the lock when the process ends, a
``SIGKILL`` included. ``bash run.sh study`` (``main``) asks for it exclusively,
without waiting: granted, no run and no job uses the folder, so a killed run's
Snakemake lock and its jobs' ``*.partial`` files are stale and removed; refused,
a run or an orphaned job is live and nothing is touched (Snakemake then refuses
the folder by its own lock until the job has ended). The lock is then turned
shared and passed on to Snakemake (its child, or across ``exec`` with ``--verbose``),
so the folder is never seen idle while it starts.
"""

import contextlib
import fcntl
import io
import os
import signal
import subprocess
import sys
from pathlib import Path

LOCK_FILE = Path(".snakemake") / "luckyao-run.lock"


def _open_lock(folder: Path) -> int:
    path = folder / LOCK_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    return os.open(path, os.O_RDWR | os.O_CREAT, 0o644)


def hold_shared(folder=".") -> int:
    """Hold the study folder's run lock shared until this process exits (waits only
    while ``run.sh`` cleans up); returns the descriptor (keep it open)."""
    fd = _open_lock(Path(folder))
    fcntl.flock(fd, fcntl.LOCK_SH)
    return fd


_JOB_LOCK = None


def hold_job_lock(folder=".") -> int:
    """A job of the workflow (its working folder is the study folder): hold the folder's run
    lock shared until this process exits, as its Snakemake does, so that the job keeps the
    folder locked if that Snakemake is killed alone; returns the descriptor (kept open here,
    not inherited by the processes the job starts)."""
    global _JOB_LOCK
    if _JOB_LOCK is None:
        _JOB_LOCK = hold_shared(folder)
    return _JOB_LOCK


def study_folder(argv: list[str]) -> Path | None:
    """The study folder of a Snakemake command line, parsed by Snakemake's own parser
    (``-d DIR``, ``-dDIR``, ``--directory DIR``, ``--directory=DIR``, abbreviations,
    profiles); ``None`` when it does not parse (Snakemake then reports it)."""
    from snakemake.cli import parse_args

    try:
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            _, args = parse_args(argv)
    except (SystemExit, Exception):  # noqa: BLE001 - any parse failure: Snakemake itself reports it
        return None
    return Path(args.directory or ".")


def clean_if_idle(folder: Path, echo=print) -> int:
    """Take the folder's run lock exclusively if free and then remove a killed run's
    stale Snakemake lock and ``results/**/*.partial`` files; returns the lock's
    descriptor, held shared either way."""
    fd = _open_lock(folder)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        echo(
            f"luckyao: a run of the workflow, or a job of a killed one still running, is using {folder}; "
            "its lock and files are left alone"
        )
        fcntl.flock(fd, fcntl.LOCK_SH)
        return fd
    locks = [p for p in (folder / ".snakemake" / "locks").glob("*") if p.is_file()]
    if locks:
        echo("luckyao: no Snakemake is running here; removing the stale lock of a killed run")
        for path in locks:
            path.unlink(missing_ok=True)
    for path in (folder / "results").rglob("*.partial"):
        path.unlink(missing_ok=True)
    fcntl.flock(fd, fcntl.LOCK_SH)
    return fd


def refuse_unsafe_overlays(argv: list[str]) -> None:
    """Exit naming the file when a ``--configfile`` overlay is not a config Snakemake can be given
    safely (``studyspec.yamlfile``: an alias bomb would hang Snakemake's own merge of it)."""
    from snakemake.cli import parse_args

    from ..studyspec.schema import ConfigError
    from ..studyspec.yamlfile import read_config_file

    try:
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            _, args = parse_args(argv)
    except (SystemExit, Exception):  # noqa: BLE001 - any parse failure: Snakemake itself reports it
        return
    try:
        for path in args.configfile or []:
            if os.path.exists(path):
                read_config_file(path)
    except ConfigError as err:
        sys.exit(f"luckyao: invalid study config: {err}")


def snakemake_words(argv: list[str]) -> list[str]:
    """``bash run.sh study`` words as Snakemake's: the leading ``case=NAME`` and ``key=value``
    overrides (``studyspec.overrides``) become that case's targets (its ``lucky.nc`` and FITS)
    and ``--config`` entries, one per top-level key, as JSON (typed again by the Snakefile)."""
    import json

    from ..studyspec.overrides import parse_overrides, split_words
    from ..studyspec.schema import ConfigError

    case, overrides, rest = split_words(argv)
    if case is None and not overrides:
        return argv
    if {"--config", "-C"} & set(rest):
        sys.exit("luckyao: give overrides as key=value words or with --config, not both")
    try:
        config = parse_overrides(overrides, case)
    except ConfigError as err:
        sys.exit(f"luckyao: {err}")
    targets = [f"results/cases/{case}/lucky.nc", f"fits/{case}.fits"] if case else []
    entries = [f"{key}={json.dumps(value)}" for key, value in config.items()]
    return [*targets, *rest, *(["--config", *entries] if entries else [])]


def run_snakemake(argv: list[str], lock_fd: int | None) -> int:
    """Snakemake with ``argv`` as a child holding the run lock (``lock_fd``), its log shown
    through :class:`~luckyao.jobs.progress.Progress` (one line per job, a progress line);
    returns its exit status. Ctrl-C reaches Snakemake (same process group), which stops its
    jobs; its last lines are still shown."""
    from .progress import Progress, declared_runtimes

    progress = Progress(declared_runtimes())
    child = subprocess.Popen(
        [sys.executable, "-m", "snakemake", *argv],
        stderr=subprocess.PIPE,
        pass_fds=() if lock_fd is None else (lock_fd,),
        text=True,
        errors="replace",
    )
    handlers = signal.signal(signal.SIGINT, signal.SIG_IGN), signal.getsignal(signal.SIGTERM)
    signal.signal(signal.SIGTERM, lambda *_: child.terminate())  # Snakemake gets Ctrl-C itself
    try:
        for line in child.stderr:
            for shown in progress.feed(line):
                print(shown, file=sys.stderr, flush=True)
        for shown in progress.close():
            print(shown, file=sys.stderr, flush=True)
        status = child.wait()
    finally:
        signal.signal(signal.SIGINT, handlers[0])
        signal.signal(signal.SIGTERM, handlers[1])
    return 128 - status if status < 0 else status  # killed by signal N: 128 + N, as a shell says


def verbose(argv: list[str]) -> bool:
    """Snakemake's log unchanged: ``--verbose`` or ``LUCKYAO_VERBOSE=1``."""
    from .progress import VERBOSE_ENV

    return "--verbose" in argv or os.environ.get(VERBOSE_ENV, "") not in ("", "0")


def main(argv: list[str]) -> None:
    """``bash run.sh study ARGS``: clean up if the study folder is idle, then run
    ``python -m snakemake ARGS`` holding the folder's run lock: its log shortened with a
    progress line (``luckyao.jobs.progress``), or as it is with ``--verbose`` (``case=NAME`` and
    ``key=value`` words first turned into Snakemake's, :func:`snakemake_words`)."""
    argv = snakemake_words(argv)
    refuse_unsafe_overlays(argv)
    folder = study_folder(argv)
    fd = None
    if folder is not None and folder.is_dir():
        fd = clean_if_idle(folder, echo=lambda line: print(line, file=sys.stderr))
        os.set_inheritable(fd, True)
    if verbose(argv):
        os.execv(sys.executable, [sys.executable, "-m", "snakemake", *argv])
    sys.exit(run_snakemake(argv, fd))


if __name__ == "__main__":
    main(sys.argv[1:])
