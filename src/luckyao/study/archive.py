"""Archived reproducibility runs: one file per finished study, and its verification.

``archive`` packs a finished study into one tar file (members under one folder):
``config.yaml``, the resolved study config (the config files merged as Snakemake
merges them); every case's ``lucky.nc`` and ``telemetry.nc``; every figure and its
dataset; the benchmark times of the archived cases' jobs; ``requirements.lock``,
the exact versions of the runtime packages that ran; ``MANIFEST.json`` (code version,
git commit, Python, platform, CPU, config hash, cases, figures), with ``code.diff``
when the checkout has uncommitted changes; and ``SHA256SUMS``, the checksum of
every other member (``sha256sum -c SHA256SUMS`` checks an extracted archive
without luckyao). Frame cubes and phase screens are not archived (GB; rerun them).

``verify`` checks every checksum, warns when this environment or code differs from
the archived one, reruns one case with Snakemake from the archived config in a
scratch folder (by default the one whose jobs took least time when archived) and
compares every variable of its fresh ``lucky.nc`` and ``telemetry.nc`` with the
archived ones: identical, within a tolerance, or different.
"""

import datetime
import hashlib
import io
import json
import platform
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from importlib import metadata
from pathlib import Path

import netCDF4
import numpy as np
import xarray as xr
import yaml

from .. import __version__
from .config import (
    canonical_json,
    commands_key,
    commands_spec,
    frame_count,
    load_study,
    lucky_settings,
    reconstructor_key,
    reconstructor_spec,
    sha256,
    turbulence_key,
    turbulence_spec,
    validate_study,
)
from .datasets import atomic_path, code_version

FORMAT = "luckyao-archive/1"
REPO = Path(__file__).resolve().parents[3]
"""The checkout this package runs from (its ``Snakefile`` reruns a case)."""
CASE_FILES = ("lucky.nc", "telemetry.nc")
FIGURE_EXTENSIONS = ("nc", "png", "pdf")
CHECKSUMS = "SHA256SUMS"
REQUIRED = ("MANIFEST.json", "config.yaml", "requirements.lock")


class ArchiveError(ValueError):
    """An archive that cannot be made or read; one line per problem."""


def runtime_packages() -> dict[str, str]:
    """Name -> version of every installed distribution luckyao needs at run time: its
    requirements, recursively, markers evaluated here (no extras), luckyao excluded."""
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    pinned, seen, todo = {}, set(), [("luckyao", frozenset())]
    while todo:
        name, extras = todo.pop()
        if (canonicalize_name(name), extras) in seen:
            continue
        seen.add((canonicalize_name(name), extras))
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            continue
        if canonicalize_name(dist.metadata["Name"]) != "luckyao":
            pinned[dist.metadata["Name"]] = dist.version
        for requirement in map(Requirement, dist.requires or []):
            marker = requirement.marker
            if marker is None or any(marker.evaluate({"extra": extra}) for extra in extras | {""}):
                todo.append((requirement.name, frozenset(requirement.extras)))
    return dict(sorted(pinned.items(), key=lambda item: item[0].lower()))


def requirements_lock() -> str:
    """``requirements.lock`` text: ``name==version`` of every runtime package of this environment."""
    header = (f"# luckyao's runtime dependencies, exact versions (Python {platform.python_version()}, "
              f"{platform.system()} {platform.machine()}); made by `luckyao lock`.\n"
              "# Environment: pip install -r requirements.lock && pip install --no-deps -e .\n")
    return header + "".join(f"{name}=={version}\n" for name, version in runtime_packages().items())


def parse_lock(text: str) -> dict[str, str]:
    """Name -> version of the ``name==version`` lines of a requirements lock."""
    pins = (line.split("#")[0].strip().split("==") for line in text.splitlines())
    return {pin[0].strip(): pin[1].strip() for pin in pins if len(pin) == 2}


def package_differences(archived: dict[str, str], here: dict[str, str]) -> list[str]:
    """One line per package whose version differs between two name -> version maps."""
    return [f"{name} {archived.get(name, 'absent')} archived, {here.get(name, 'absent')} here"
            for name in sorted(set(archived) | set(here), key=str.lower) if archived.get(name) != here.get(name)]


def git_state(repo: Path = REPO) -> dict:
    """Commit of the checkout, its uncommitted changes to tracked files and its untracked
    files (``None``, ``""``, ``[]`` without git)."""
    def git(*args):
        return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, timeout=30,
                              check=True).stdout
    try:
        return {"commit": git("rev-parse", "HEAD").strip(), "diff": git("diff", "HEAD"),
                "untracked": git("ls-files", "--others", "--exclude-standard").split()}
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "diff": "", "untracked": []}


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def case_jobs(study: dict, cases: dict, case: str) -> list[str]:
    """``step/name`` of every job ``results/cases/<case>/lucky.nc`` needs from scratch."""
    config = cases[case]
    jobs = [f"turbulence/{turbulence_key(turbulence_spec(study, config))}"]
    if (spec := reconstructor_spec(config)) is not None:
        jobs.append(f"reconstructor/{reconstructor_key(spec)}")
    if (spec := commands_spec(config)) is not None:
        jobs.append(f"commands/{commands_key(spec)}")
    return jobs + [f"simulate/{case}", f"lucky/{case}"]


def _stale(path: Path, member: str, study: dict, cases: dict) -> list[str]:
    """Problems if ``path`` (an archived netCDF) was made from another config than ``study``."""
    with netCDF4.Dataset(path) as nc:
        attrs = {name: nc.getncattr(name) for name in nc.ncattrs()}
    problems = []
    if "seed" in attrs and int(attrs["seed"]) != study["seed"]:
        problems.append(f"seed {attrs['seed']}, the config has {study['seed']}")
    if member.startswith("results/cases/"):
        case = member.split("/")[2]
        if attrs.get("config_sha256") != sha256(cases[case]):
            problems.append(f"case '{case}' differs from the config's (config_sha256)")
        settings = {k: v for k, v in lucky_settings(study, cases, case).items() if k != "case_config"}
        if "lucky_settings_json" in attrs and attrs["lucky_settings_json"] != canonical_json(settings):
            problems.append("lucky settings differ from the config's")
    elif "case_config_sha256" in attrs:
        used = json.loads(attrs["case_config_sha256"])
        changed = sorted(c for c, digest in used.items() if c not in cases or digest != sha256(cases[c]))
        if changed:
            problems.append(f"cases {', '.join(changed)} differ from the config's")
    return [f"{member}: made from another config ({p})" for p in problems]


def checksum_list(members: dict[str, bytes]) -> bytes:
    """``SHA256SUMS`` text (``sha256sum`` format) of every member but itself."""
    return "".join(f"{hashlib.sha256(data).hexdigest()}  {name}\n"
                   for name, data in sorted(members.items()) if name != CHECKSUMS).encode()


def write_members(path, members: dict[str, bytes]) -> None:
    """Write ``members`` (name -> bytes) as a tar file atomically, under one folder named as the file."""
    path = Path(path)
    top, now = path.name.removesuffix(".tar"), time.time()
    with atomic_path(path) as tmp, tarfile.open(tmp, "w") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(f"{top}/{name}")
            info.size, info.mtime, info.mode = len(data), now, 0o644
            tar.addfile(info, io.BytesIO(data))


def read_members(path) -> dict[str, bytes]:
    """Name (without the top folder) -> bytes of every file in the archive ``path``."""
    try:
        with tarfile.open(path, "r:*") as tar:
            return {info.name.partition("/")[2]: tar.extractfile(info).read() for info in tar if info.isfile()}
    except (OSError, tarfile.TarError) as err:
        raise ArchiveError(f"archive '{path}' is missing or not a tar file ({err})") from err


def archive(study_dir=".", configfiles=(), out=None, echo=print) -> Path:
    """Archive the finished study in ``study_dir`` (config ``config/config.yaml`` with the
    overlays ``configfiles``, as given to Snakemake's ``--configfile``); returns the path.
    Refuses results that the config did not make, and a study without all its figures."""
    start = time.perf_counter()
    study_dir = Path(study_dir)
    sources = [study_dir / "config" / "config.yaml", *map(Path, configfiles)]
    study, cases = load_study(*sources)
    config_text = yaml.safe_dump(study, sort_keys=False)
    if yaml.safe_load(config_text) != study:
        raise ArchiveError("the resolved config does not survive a YAML round trip")
    files = [f"figures/{fig}.{ext}" for fig in study["figures"] for ext in FIGURE_EXTENSIONS]
    missing = [name for name in files if not (study_dir / name).is_file()]
    if missing:
        raise ArchiveError("\n".join(f"{name}: missing; finish the study (snakemake) before archiving"
                                     for name in missing))
    archived_cases = [c for c in cases if (study_dir / "results" / "cases" / c / "lucky.nc").is_file()]
    for case in archived_cases:
        files += [f"results/cases/{case}/{name}" for name in CASE_FILES
                  if (study_dir / "results" / "cases" / case / name).is_file()]
        files += [f"results/benchmarks/{job}.tsv" for job in case_jobs(study, cases, case)
                  if (study_dir / "results" / "benchmarks" / f"{job}.tsv").is_file()]
    files = list(dict.fromkeys(files))  # shared jobs once
    stale = [p for name in files if name.endswith(".nc") for p in _stale(study_dir / name, name, study, cases)]
    if stale:
        raise ArchiveError("\n".join(stale + [f"archive with the config files the study ran with "
                                              f"(given: {' + '.join(map(str, sources))}) or rerun it"]))
    code_versions = set()
    for name in (n for n in files if n.endswith(".nc")):
        with netCDF4.Dataset(study_dir / name) as nc:
            code_versions.add(getattr(nc, "code_version", "unknown"))
    git = git_state()
    lock = requirements_lock()
    manifest = {
        "format": FORMAT,
        "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "study_dir": str(study_dir.resolve()),
        "config_files": [str(p) for p in sources],
        "config_sha256": sha256(study),
        "seed": study["seed"],
        "cases": archived_cases,
        "figures": list(study["figures"]),
        "luckyao_version": __version__,
        "code_version": code_version(),
        "results_code_versions": sorted(code_versions),
        "git_commit": git["commit"],
        "git_dirty": bool(git["diff"]),
        "git_untracked": git["untracked"],
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": _cpu_model(),
        "packages": parse_lock(lock),
    }
    members = {"MANIFEST.json": (json.dumps(manifest, indent=1) + "\n").encode(),
               "config.yaml": config_text.encode(), "requirements.lock": lock.encode()}
    if git["diff"]:
        members["code.diff"] = git["diff"].encode()
    members |= {name: (study_dir / name).read_bytes() for name in files}
    members[CHECKSUMS] = checksum_list(members)
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    path = Path(out) if out else study_dir / "archives" / f"luckyao-{manifest['config_sha256'][:12]}-{stamp}.tar"
    write_members(path, members)
    size_mb = path.stat().st_size / 1e6
    echo(f"archived {len(members)} files of {len(archived_cases)} cases and {len(study['figures'])} figures "
         f"({size_mb:.1f} MB) in {time.perf_counter() - start:.1f} s: {path}")
    if git["diff"]:
        echo("warning: the checkout has uncommitted changes (archived as code.diff over the commit)")
    if git["untracked"]:
        echo(f"warning: files not in git (listed in MANIFEST.json, not archived): {' '.join(git['untracked'])}")
    repo_lock = REPO / "requirements.lock"
    if repo_lock.is_file():
        for line in package_differences(parse_lock(repo_lock.read_text()), manifest["packages"]):
            echo(f"warning: this environment differs from requirements.lock: {line.replace('archived', 'locked')}")
    return path


def check_checksums(members: dict[str, bytes]) -> list[str]:
    """One problem per member that is changed, missing or unlisted against ``SHA256SUMS``."""
    if CHECKSUMS not in members:
        return [f"{CHECKSUMS}: missing from the archive"]
    listed, problems = {}, []
    for line in members[CHECKSUMS].decode(errors="replace").splitlines():
        digest, _, name = line.partition("  ")
        if name:
            listed[name] = digest
        elif line.strip():
            problems.append(f"{CHECKSUMS}: unreadable line '{line}'")
    for name, digest in listed.items():
        if name not in members:
            problems.append(f"{name}: missing from the archive (listed in {CHECKSUMS})")
        elif hashlib.sha256(members[name]).hexdigest() != digest:
            problems.append(f"{name}: checksum differs from {CHECKSUMS} (changed after archiving)")
    problems += [f"{name}: not in {CHECKSUMS} (added after archiving)"
                 for name in members if name not in listed and name != CHECKSUMS]
    return problems + [f"{name}: missing from the archive" for name in REQUIRED if name not in members]


def cheapest_case(members: dict[str, bytes], study: dict, cases: dict) -> tuple[str, float | None]:
    """The archived case whose jobs took least time when archived (from their benchmarks),
    with that time in s; when no case has all its benchmarks, the case with fewest time
    steps and least AO/LGS/WFS/camera work (time ``None``)."""
    archived = [c for c in cases if f"results/cases/{c}/lucky.nc" in members]
    if not archived:
        raise ArchiveError("the archive holds no case's lucky.nc")
    times = {}
    for case in archived:
        tables = [members.get(f"results/benchmarks/{job}.tsv") for job in case_jobs(study, cases, case)]
        if all(tables):
            times[case] = sum(float(t.decode().splitlines()[1].split("\t")[0]) for t in tables)
    if times:
        case = min(times, key=lambda c: (times[c], c))
        return case, times[case]

    def work(c):
        config = cases[c]
        return (frame_count(config) * round(config["camera"]["frame_time_s"] / config["time_step_s"]),
                len(config["targets_arcsec"]), config["lgs"]["enabled"], config["ao"]["mode"] != "none",
                config["wfs"]["n_subapertures"], config["camera"]["n_pixels"], c)
    return min(archived, key=work), None


def compare_variables(fresh: xr.Dataset, archived: xr.Dataset, rtol: float, atol: float) -> list[tuple[str, bool, str]]:
    """(variable, agrees, how) for every variable and coordinate of two datasets, and the
    ``config_sha256`` and ``seed`` attributes: identical, within ``atol + rtol |archived|``
    (with the largest absolute and relative differences), or different; a variable of
    the rerun only (newer code) agrees, one missing from the rerun does not."""
    rows = [(f"attribute {key}", fresh.attrs.get(key) == archived.attrs.get(key),
             "identical" if fresh.attrs.get(key) == archived.attrs.get(key) else
             f"{fresh.attrs.get(key)} in the rerun, {archived.attrs.get(key)} archived")
            for key in ("config_sha256", "seed")]
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
            rows.append((name, agrees, f"max abs diff {diff.max():.3g}, max rel diff {np.nanmax(relative):.3g}: "
                                       + (f"within rtol={rtol:g}, atol={atol:g}" if agrees else "DIFFERS")))
    return rows


def verify(path, case=None, workdir=None, rtol=0.0, atol=0.0, cores=2, snakefile=None, rerun=True,
           echo=print) -> bool:
    """Check the archive ``path`` and rerun one of its cases; True when everything agrees.

    Checksums first (a damaged archive is not rerun). Then warnings when this
    environment's runtime packages, Python or code version differ from the archived
    ones. Then ``case`` (default: ``cheapest_case``) is rerun by Snakemake on
    ``snakefile`` (this checkout's) with the archived config, in ``workdir`` (kept;
    a finished rerun there is reused) or a scratch folder (removed when it agrees), and
    each variable of its files compared with the archive: equal within
    ``atol + rtol |archived|``; the default 0, 0 asks for bit-identical numbers.
    """
    members = read_members(path)
    problems = check_checksums(members)
    for problem in problems:
        echo(f"FAILED: {problem}")
    if problems:
        echo(f"verify: FAILED, archive '{path}' is damaged: {len(problems)} members; not rerun")
        return False
    echo(f"checksums: all {len(members) - 1} members agree with {CHECKSUMS}")
    manifest = json.loads(members["MANIFEST.json"])
    if manifest.get("format") != FORMAT:
        raise ArchiveError(f"archive '{path}' has format {manifest.get('format')}, this code reads {FORMAT}")
    here = runtime_packages()
    differences = package_differences(parse_lock(members["requirements.lock"].decode()), here)
    if manifest["python"] != platform.python_version():
        differences.insert(0, f"Python {manifest['python']} archived, {platform.python_version()} here")
    for line in differences:
        echo(f"warning: environment differs: {line}")
    if not differences:
        echo(f"environment: the archived versions of all {len(here)} runtime packages and Python")
    if manifest["code_version"] != code_version():
        echo(f"warning: archived by code {manifest['code_version']}; this code is {code_version()} "
             f"(to rerun the archived code: git checkout {manifest['git_commit']}"
             f"{', then git apply code.diff' if manifest['git_dirty'] else ''})")
    if not rerun:
        return True

    study = yaml.safe_load(members["config.yaml"])
    cases = validate_study(study)
    if case is None:
        case, seconds = cheapest_case(members, study, cases)
    else:
        seconds = None
        if f"results/cases/{case}/lucky.nc" not in members:
            raise ArchiveError(f"case '{case}' is not in the archive; archived: {', '.join(manifest['cases'])}")
    snakefile = Path(snakefile) if snakefile else REPO / "Snakefile"
    if not snakefile.is_file():
        raise ArchiveError(f"no Snakefile at '{snakefile}': give the checkout's with --snakefile")
    scratch = workdir is None
    workdir = Path(tempfile.mkdtemp(prefix="luckyao-verify-") if scratch else workdir)
    (workdir / "config").mkdir(parents=True, exist_ok=True)
    (workdir / "config" / "config.yaml").write_bytes(members["config.yaml"])
    target = f"results/cases/{case}/lucky.nc"
    command = [sys.executable, "-m", "snakemake", "-s", str(snakefile), "-d", str(workdir), "--cores", str(cores),
               target]
    echo(f"rerun: case '{case}'" + (f" (its jobs took {seconds:.0f} s when archived)" if seconds else "")
         + f" in {workdir}")
    start = time.perf_counter()
    log = workdir / "verify-snakemake.log"
    with open(log, "w") as stream:
        result = subprocess.run(command, stdout=stream, stderr=subprocess.STDOUT)
    if result.returncode:
        tail = log.read_text().splitlines()[-15:]
        echo("\n".join(tail))
        echo(f"verify: FAILED, the rerun of case '{case}' failed (Snakemake exit {result.returncode}, log {log})")
        return False
    echo(f"rerun took {time.perf_counter() - start:.0f} s")

    failures = []
    for name in CASE_FILES:
        member = f"results/cases/{case}/{name}"
        if member not in members:
            continue
        archived_path = workdir / "archived" / name
        archived_path.parent.mkdir(exist_ok=True)
        archived_path.write_bytes(members[member])
        with xr.open_dataset(workdir / member) as fresh, xr.open_dataset(archived_path) as archived:
            fresh_version = fresh.attrs.get("code_version")
            if fresh_version != archived.attrs.get("code_version"):
                echo(f"{member}: made by code {archived.attrs.get('code_version')}, rerun by {fresh_version}")
            for variable, agrees, how in compare_variables(fresh.load(), archived.load(), rtol, atol):
                echo(f"{member}: {variable}: {how}")
                if not agrees:
                    failures.append(f"{member}: {variable}: {how}")
    for failure in failures:
        echo(f"FAILED: {failure}")
    if failures:
        echo(f"verify: FAILED, the rerun of case '{case}' differs from the archive in {len(failures)} variables "
             f"(rerun kept in {workdir})")
        return False
    if scratch:
        shutil.rmtree(workdir, ignore_errors=True)
    echo(f"verify: OK, checksums and the rerun of case '{case}' agree with archive '{path}'")
    return True
