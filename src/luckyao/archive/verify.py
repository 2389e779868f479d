"""Verification of an archived run (``luckyao verify``): its checksums, then a rerun.

The archive is read as a stream, one member at a time in 1 MiB pieces: every
member is hashed without being held, so memory stays bounded whatever the
archive holds (a member claiming more than ``MEMBER_LIMIT_BYTES`` is refused
unread, a small one (config, manifest, lock) more than ``TEXT_LIMIT_BYTES`` too, a
benchmark table more than ``BENCHMARK_LIMIT_BYTES``, the small members together more
than ``HELD_LIMIT_BYTES``, more than ``MEMBER_COUNT_LIMIT`` members, and tar's own
extended headers together more than ``HEADER_LIMIT_BYTES``). Only regular files (and
folders) are read: a link or any other kind of member is refused, as is a name
archived twice (a tar file may hold two copies; which one is "the" member?). Every checksum is checked against
``SHA256SUMS``;
warnings follow when this environment or code differs from the archived one;
then one case (by default the one whose jobs took least time when archived), or
every case, is rerun with Snakemake from the archived config, and every
variable of its fresh ``lucky.nc`` and ``telemetry.nc`` is compared with the
archived one: identical, within a tolerance, or different.

What this proves: the checksums show that no member changed after archiving
unless ``SHA256SUMS`` was rewritten with it (they are not a signature); the
rerun shows that this code, from the archived config, remakes the rerun cases'
numbers. A case that is not rerun is covered by the checksums alone.

The rerun's folder (``--workdir``) must be new, empty, or one an earlier verify made (it
holds ``WORKDIR_MARKER``): verify writes ``config/config.yaml`` and ``results/`` there, so a
study folder or any other folder with files in it is refused untouched.
"""

import hashlib
import json
import platform
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np
import xarray as xr

from ..clock import FrameClock
from ..io.datasets import code_version
from ..studyspec.study import validate_study
from ..studyspec.yamlfile import read_config_text
from .create import (
    CASE_FILES,
    CHECKSUMS,
    FORMAT,
    REPO,
    REQUIRED,
    ArchiveError,
    case_jobs,
    package_differences,
    parse_lock,
    runtime_packages,
)

CHUNK_BYTES = 1 << 20
MEMBER_LIMIT_BYTES = 2 << 30
"""Largest member read (a paper-fidelity ``lucky.nc`` or ``telemetry.nc``: under 100 MB)."""
TEXT_LIMIT_BYTES = 16 << 20
"""Largest member held in memory: config, manifest, lock, checksums, code diff."""
BENCHMARK_LIMIT_BYTES = 64 << 10
"""Largest benchmark table held (a Snakemake benchmark: one header and one row, ~200 bytes)."""
HELD_LIMIT_BYTES = 64 << 20
"""Most bytes of all the members held together."""
MEMBER_COUNT_LIMIT = 100_000
"""Most members read (a paper-fidelity study's archive: a few hundred)."""
HEADER_LIMIT_BYTES = 16 << 20
"""Most bytes of tar's extended headers (long names, pax records) together, read by tarfile whole."""
WORKDIR_MARKER = ".luckyao-verify"
"""The file that marks a folder verify made for a rerun (verify may reuse it)."""


def _held_limit(name: str) -> int:
    return BENCHMARK_LIMIT_BYTES if name.startswith("results/benchmarks/") else TEXT_LIMIT_BYTES


class _BoundedTarInfo(tarfile.TarInfo):
    """A member header whose extended headers are bounded before tarfile reads them whole,
    and no GNU sparse member (its map is read block after block)."""

    def _proc_member(self, tar):
        if self.type == tarfile.GNUTYPE_SPARSE:
            raise ArchiveError(
                f"archive '{tar.name}': member {self.name} is a sparse file; verify reads only regular files"
            )
        if self.type in (
            tarfile.GNUTYPE_LONGNAME,
            tarfile.GNUTYPE_LONGLINK,
            tarfile.XHDTYPE,
            tarfile.XGLTYPE,
            tarfile.SOLARIS_XHDTYPE,
        ):
            tar.luckyao_header_bytes = getattr(tar, "luckyao_header_bytes", 0) + self.size
            if tar.luckyao_header_bytes > HEADER_LIMIT_BYTES:
                raise ArchiveError(
                    f"archive '{tar.name}': its extended tar headers hold more than "
                    f"{HEADER_LIMIT_BYTES:,} bytes together (names, pax records); not read"
                )
        return super()._proc_member(tar)


def _held(name: str) -> bool:
    """Whether verify reads the member's bytes (else it only hashes them)."""
    return name in (*REQUIRED, CHECKSUMS, "code.diff") or name.startswith("results/benchmarks/")


def _members(path):
    """(name without the top folder, chunk iterator) of every file member, streamed; an
    ArchiveError for a link or other non-regular member, or past a limit."""
    with tarfile.open(path, "r|*", tarinfo=_BoundedTarInfo) as tar:
        count = 0
        while (info := tar.next()) is not None:
            tar.members.clear()  # tarfile keeps every header read: one at a time is enough here
            count += 1
            if count > MEMBER_COUNT_LIMIT:
                raise ArchiveError(f"archive '{path}' has more than {MEMBER_COUNT_LIMIT:,} members; not read further")
            if info.isdir():
                continue
            name = info.name.partition("/")[2]
            if not info.isreg():
                kind = (
                    "a symbolic link"
                    if info.issym()
                    else "a hard link"
                    if info.islnk()
                    else "a device or FIFO, not a file"
                )
                raise ArchiveError(
                    f"archive '{path}': member {name or info.name} is {kind}"
                    f"{' to ' + repr(info.linkname) if info.issym() or info.islnk() else ''}; "
                    "an archive holds regular files only"
                )
            limit = _held_limit(name) if _held(name) else MEMBER_LIMIT_BYTES
            if info.size > limit:
                raise ArchiveError(
                    f"archive '{path}': member {name} claims {info.size:,} bytes, more than "
                    f"verify reads ({limit:,}); not read"
                )
            stream = tar.extractfile(info)
            yield name, iter(lambda stream=stream: stream.read(CHUNK_BYTES), b"")


def scan_members(path) -> tuple[dict[str, str], dict[str, bytes]]:
    """Name -> sha256 of every file member of the archive ``path``, and name -> bytes of
    the small members verify reads (``_held``)."""
    digests, held, held_bytes = {}, {}, 0
    try:
        for name, chunks in _members(path):
            if name in digests:
                raise ArchiveError(
                    f"archive '{path}': member {name} is archived twice; an archive holds each name once"
                )
            digest, data = hashlib.sha256(), bytearray()
            for chunk in chunks:
                digest.update(chunk)
                if _held(name):
                    data += chunk
                    if held_bytes + len(data) > HELD_LIMIT_BYTES:
                        raise ArchiveError(
                            f"archive '{path}': its config, lock, manifest and benchmark members "
                            f"hold more than {HELD_LIMIT_BYTES:,} bytes together; not read further"
                        )
            digests[name] = digest.hexdigest()
            if _held(name):
                held[name] = bytes(data)
                held_bytes += len(data)
    except (OSError, EOFError, tarfile.TarError, zlib.error, RecursionError) as err:
        raise ArchiveError(f"archive '{path}' is missing, not a tar file or damaged ({err})") from err
    return digests, held


def extract_member(path, name: str, out: Path) -> None:
    """Copy one member of the archive ``path`` to the file ``out``, streamed."""
    try:
        for member, chunks in _members(path):
            if member == name:
                with open(out, "wb") as f:
                    for chunk in chunks:
                        f.write(chunk)
                return
    except (OSError, EOFError, tarfile.TarError, zlib.error) as err:
        raise ArchiveError(f"archive '{path}': member {name} cannot be read ({err})") from err
    raise ArchiveError(f"archive '{path}' has no member {name}")


def check_checksums(digests: dict[str, str], held: dict[str, bytes]) -> list[str]:
    """One problem per member that is changed, missing or unlisted against ``SHA256SUMS``
    (``digests``: name -> sha256 of every member; ``held``: the small members' bytes)."""
    if CHECKSUMS not in held:
        return [f"{CHECKSUMS}: missing from the archive"]
    listed, problems = {}, []
    for line in held[CHECKSUMS].decode(errors="replace").splitlines():
        digest, _, name = line.partition("  ")
        if name:
            listed[name] = digest
        elif line.strip():
            problems.append(f"{CHECKSUMS}: unreadable line '{line}'")
    for name, digest in listed.items():
        if name not in digests:
            problems.append(f"{name}: missing from the archive (listed in {CHECKSUMS})")
        elif digests[name] != digest:
            problems.append(f"{name}: checksum differs from {CHECKSUMS} (changed after archiving)")
    problems += [
        f"{name}: not in {CHECKSUMS} (added after archiving)"
        for name in digests
        if name not in listed and name != CHECKSUMS
    ]
    return problems + [f"{name}: missing from the archive" for name in REQUIRED if name not in digests]


def archived_cases(names, study: dict, cases: dict) -> list[str]:
    """The config's cases whose ``lucky.nc`` the archive holds."""
    archived = [c for c in cases if f"results/cases/{c}/lucky.nc" in names]
    if not archived:
        raise ArchiveError("the archive holds no case's lucky.nc")
    return archived


def cheapest_case(names, held: dict[str, bytes], study: dict, cases: dict) -> tuple[str, float | None]:
    """The archived case whose jobs took least time when archived (from their benchmarks in
    ``held``), with that time in s; when no case has all its benchmarks, the case with
    fewest time steps and least AO/LGS/WFS/camera work (time ``None``)."""
    archived, times = archived_cases(names, study, cases), {}
    for case in archived:
        tables = [held.get(f"results/benchmarks/{job}.tsv") for job in case_jobs(study, cases, case)]
        if all(tables):
            times[case] = sum(float(t.decode().splitlines()[1].split("\t")[0]) for t in tables)
    if times:
        case = min(times, key=lambda c: (times[c], c))
        return case, times[case]

    def work(c):
        config = cases[c]
        return (
            FrameClock.from_config(config).n_steps,
            len(config["targets_arcsec"]),
            config["lgs"]["enabled"],
            config["ao"]["mode"] != "none",
            config["wfs"]["n_subapertures"],
            config["camera"]["n_pixels"],
            c,
        )

    return min(archived, key=work), None


def compare_variables(fresh: xr.Dataset, archived: xr.Dataset, rtol: float, atol: float) -> list[tuple[str, bool, str]]:
    """(variable, agrees, how) for every variable and coordinate of two datasets, and the
    ``config_sha256`` and ``seed`` attributes: identical, within ``atol + rtol |archived|``
    (with the largest absolute and relative differences), or different; a variable of
    the rerun only (newer code) agrees, one missing from the rerun does not."""
    rows = [
        (
            f"attribute {key}",
            fresh.attrs.get(key) == archived.attrs.get(key),
            "identical"
            if fresh.attrs.get(key) == archived.attrs.get(key)
            else f"{fresh.attrs.get(key)} in the rerun, {archived.attrs.get(key)} archived",
        )
        for key in ("config_sha256", "seed")
    ]
    for name in sorted(set(fresh.variables) | set(archived.variables), key=str):
        if name not in archived.variables:  # newer code adds it: every archived number is still compared
            rows.append((name, True, "new in the rerun, not archived (not compared)"))
            continue
        if name not in fresh.variables:
            rows.append((name, False, "missing in the rerun: DIFFERS"))
            continue
        a, b = fresh[name].values, archived[name].values
        numeric = a.dtype.kind in "fciu" and b.dtype.kind in "fciu"
        if a.shape != b.shape:
            rows.append((name, False, f"shape {a.shape} in the rerun, {b.shape} archived"))
        elif np.array_equal(a, b, equal_nan=numeric and (a.dtype.kind in "fc" or b.dtype.kind in "fc")):
            rows.append((name, True, "identical"))
        elif not numeric:
            rows.append((name, False, "DIFFERS"))
        else:
            a, b = a.astype(np.result_type(a, b, np.float64)), b.astype(np.result_type(a, b, np.float64))
            with np.errstate(invalid="ignore", divide="ignore"):
                diff = np.where((a == b) | (np.isnan(a) & np.isnan(b)), 0.0, np.abs(a - b))
                diff = np.where(np.isnan(diff), np.inf, diff)
                relative = np.where(diff > 0, diff / np.abs(b), 0.0)
            agrees = bool(np.all(diff <= atol + rtol * np.abs(b)))
            rows.append(
                (
                    name,
                    agrees,
                    f"max abs diff {diff.max():.3g}, max rel diff {np.nanmax(relative):.3g}: "
                    + (f"within rtol={rtol:g}, atol={atol:g}" if agrees else "DIFFERS"),
                )
            )
    return rows


def check_archive(path, echo=print) -> tuple[dict, set[str], dict[str, bytes]] | None:
    """Checksums and environment of the archive ``path``: (manifest, member names, small
    members' bytes), or ``None`` when a member is changed, missing or added (each named)."""
    digests, held = scan_members(path)
    problems = check_checksums(digests, held)
    for problem in problems:
        echo(f"FAILED: {problem}")
    if problems:
        echo(f"verify: FAILED, archive '{path}' is damaged: {len(problems)} members; not rerun")
        return None
    echo(f"checksums: all {len(digests) - 1} members agree with {CHECKSUMS}")
    manifest = json.loads(held["MANIFEST.json"])
    if manifest.get("format") != FORMAT:
        raise ArchiveError(f"archive '{path}' has format {manifest.get('format')}, this code reads {FORMAT}")
    here = runtime_packages()
    differences = package_differences(parse_lock(held["requirements.lock"].decode()), here)
    if manifest["python"] != platform.python_version():
        differences.insert(0, f"Python {manifest['python']} archived, {platform.python_version()} here")
    for line in differences:
        echo(f"warning: environment differs: {line}")
    if not differences:
        echo(f"environment: the archived versions of all {len(here)} runtime packages and Python")
    if manifest["code_version"] != code_version():
        echo(
            f"warning: archived by code {manifest['code_version']}; this code is {code_version()} "
            f"(to rerun the archived code: git checkout {manifest['git_commit']}"
            f"{', then git apply code.diff' if manifest['git_dirty'] else ''})"
        )
    return manifest, set(digests), held


def compare_case(
    path, case: str, names: set[str], workdir: Path, rtol: float, atol: float, echo=print
) -> tuple[list[str], list[str]]:
    """Every variable of a rerun case's files against the archived ones, one line each:
    (differences, unreadable files), each line naming the member."""
    differences, unreadable = [], []
    for name in CASE_FILES:
        member = f"results/cases/{case}/{name}"
        if member not in names:
            continue
        archived_path = workdir / "archived" / case / name
        archived_path.parent.mkdir(parents=True, exist_ok=True)
        extract_member(path, member, archived_path)
        try:
            with xr.open_dataset(workdir / member) as fresh, xr.open_dataset(archived_path) as archived:
                fresh, archived = fresh.load(), archived.load()
        except (OSError, ValueError, RuntimeError) as err:
            unreadable.append(f"{member}: unreadable, not a netCDF file the rerun can be compared with ({err})")
            continue
        if fresh.attrs.get("code_version") != archived.attrs.get("code_version"):
            echo(
                f"{member}: made by code {archived.attrs.get('code_version')}, rerun by "
                f"{fresh.attrs.get('code_version')}"
            )
        for variable, agrees, how in compare_variables(fresh, archived, rtol, atol):
            echo(f"{member}: {variable}: {how}")
            if not agrees:
                differences.append(f"{member}: {variable}: {how}")
    return differences, unreadable


def rerun_cases(
    held: dict[str, bytes], rerun: list[str], workdir: Path, snakefile: Path, cores: int, echo=print
) -> bool:
    """Snakemake remakes the ``lucky.nc`` of the cases ``rerun`` from the archived config in
    ``workdir``; False (with the log's tail) when it fails."""
    (workdir / "config").mkdir(parents=True, exist_ok=True)
    (workdir / "config" / "config.yaml").write_bytes(held["config.yaml"])
    targets = [f"results/cases/{case}/lucky.nc" for case in rerun]
    command = [
        sys.executable,
        "-m",
        "snakemake",
        "-s",
        str(snakefile),
        "-d",
        str(workdir),
        "--cores",
        str(cores),
        *targets,
    ]
    start = time.perf_counter()
    log = workdir / "verify-snakemake.log"
    with open(log, "w") as stream:
        result = subprocess.run(command, stdout=stream, stderr=subprocess.STDOUT)
    if result.returncode:
        echo("\n".join(log.read_text().splitlines()[-15:]))
        echo(f"verify: FAILED, the rerun of {_cases(rerun)} failed (Snakemake exit {result.returncode}, log {log})")
        return False
    echo(f"rerun took {time.perf_counter() - start:.0f} s")
    return True


def claim_workdir(workdir: Path) -> None:
    """Make ``workdir`` the rerun's folder (marked with ``WORKDIR_MARKER``): it must be new,
    empty, or marked by an earlier verify; an ArchiveError, before anything is written, for a
    file, a study folder or any other folder holding files."""
    if workdir.exists() and not workdir.is_dir():
        raise ArchiveError(f"--workdir '{workdir}' is a file, not a folder")
    if workdir.is_dir() and not (workdir / WORKDIR_MARKER).is_file() and any(workdir.iterdir()):
        study = [p for p in ("Snakefile", "config", "results", ".snakemake") if (workdir / p).exists()]
        what = f"a study folder (it has {', '.join(study)})" if study else "not empty"
        raise ArchiveError(
            f"--workdir '{workdir}' is {what}: the rerun writes config/config.yaml and results/ "
            "there; give a new or empty folder (or one an earlier verify made)"
        )
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / WORKDIR_MARKER).write_text("a folder luckyao verify made for a rerun; verify may reuse it\n")


def _cases(names: list[str]) -> str:
    return f"case '{names[0]}'" if len(names) == 1 else f"cases {', '.join(names)}"


def verify(
    path, case=None, workdir=None, rtol=0.0, atol=0.0, cores=2, snakefile=None, rerun=True, all_cases=False, echo=print
) -> bool:
    """Check the archive ``path`` and rerun cases of it; True when everything agrees.

    Checksums first (a damaged archive is not rerun), with warnings when this
    environment's runtime packages, Python or code version differ from the archived
    ones. Then ``case`` (default: ``cheapest_case``), or with ``all_cases`` every
    archived case, is rerun by Snakemake on ``snakefile`` (this checkout's) with the
    archived config, in ``workdir`` (kept; a finished rerun there is reused) or a
    scratch folder (kept only when a rerun fails or differs), and each variable of its
    files compared with the archive: equal within ``atol + rtol |archived|``; the
    default 0, 0 asks for bit-identical numbers.
    """
    checked = check_archive(path, echo)
    if checked is None:
        return False
    manifest, names, held = checked
    if not rerun:
        return True
    study = read_config_text(held["config.yaml"], f"config.yaml of archive '{path}'")
    cases = validate_study(study)
    seconds = None
    if all_cases:
        chosen = archived_cases(names, study, cases)
    elif case is None:
        case, seconds = cheapest_case(names, held, study, cases)
        chosen = [case]
    elif f"results/cases/{case}/lucky.nc" in names:
        chosen = [case]
    else:
        raise ArchiveError(f"case '{case}' is not in the archive; archived: {', '.join(manifest['cases'])}")
    snakefile = Path(snakefile) if snakefile else REPO / "Snakefile"
    if not snakefile.is_file():
        raise ArchiveError(f"no Snakefile at '{snakefile}': give the checkout's with --snakefile")
    scratch = workdir is None
    workdir = Path(tempfile.mkdtemp(prefix="luckyao-verify-") if scratch else workdir)
    claim_workdir(workdir)
    keep = False  # a failed or differing rerun is kept for inspection
    try:
        echo(
            f"rerun: {_cases(chosen)}"
            + (f" (its jobs took {seconds:.0f} s when archived)" if seconds else "")
            + f" in {workdir}"
        )
        if not rerun_cases(held, chosen, workdir, snakefile, cores, echo):
            keep = True
            return False
        differences, unreadable = [], []
        for name in chosen:
            found = compare_case(path, name, names, workdir, rtol, atol, echo)
            differences += found[0]
            unreadable += found[1]
        for failure in unreadable + differences:
            echo(f"FAILED: {failure}")
        if unreadable or differences:
            keep = bool(differences)
            echo(
                f"verify: FAILED, the rerun of {_cases(chosen)} differs from the archive in {len(differences)} "
                f"variables"
                + (f", {len(unreadable)} archived files unreadable" if unreadable else "")
                + (f" (rerun kept in {workdir})" if keep else "")
            )
            return False
        echo(f"verify: OK, checksums and the rerun of {_cases(chosen)} agree with archive '{path}'")
        return True
    finally:
        if scratch and not keep:
            shutil.rmtree(workdir, ignore_errors=True)
