"""Archived reproducibility runs: one file per finished study (verified by ``verify.py``).

``archive`` packs a finished study into one tar file (members under one folder):
``config.yaml``, the resolved study config (the config files merged as Snakemake
merges them); every case's ``lucky.nc`` and ``telemetry.nc``; every figure and its
dataset; the benchmark times of the archived cases' jobs; ``requirements.lock``,
the exact versions of the runtime packages that ran; ``MANIFEST.json`` (code version,
git commit, Python, platform, CPU, config hash, cases, figures), with ``code.diff``
when the checkout has uncommitted changes; and ``SHA256SUMS``, the checksum of
every other member (``sha256sum -c SHA256SUMS`` checks an extracted archive
without luckyao). Frame cubes and phase screens are not archived (GB; rerun them).
"""

import datetime
import hashlib
import io
import json
import platform
import subprocess
import tarfile
import time
from importlib import metadata
from pathlib import Path

import netCDF4
import yaml

from ..io.datasets import atomic_path, code_version, open_dataset, require_finite_lucky
from ..io.hashing import canonical_json, sha256
from ..studyspec.lucky import lucky_settings
from ..studyspec.study import drawn_cases, load_study
from ..studyspec.sweeps import expand_study
from ..studyspec.view import resolve_study
from ..version import __version__

FORMAT = "luckyao-archive/1"
REPO = Path(__file__).resolve().parents[3]
"""The checkout this package runs from (its ``Snakefile`` reruns a case)."""
CASE_FILES = ("lucky.nc", "telemetry.nc")
FIGURE_EXTENSIONS = ("nc", "png", "pdf")
CHECKSUMS = "SHA256SUMS"
REQUIRED = ("MANIFEST.json", "config.yaml", "requirements.lock")
STUDY_EXTRAS = ("workflow", "plots", "fits")
"""pyproject's extras a study runs with: Snakemake, the figures, the FITS export."""


class ArchiveError(ValueError):
    """An archive that cannot be made or read; one line per problem."""


def runtime_packages() -> dict[str, str]:
    """Name -> version of every installed distribution a study needs at run time: luckyao's
    requirements with its extras :data:`STUDY_EXTRAS`, recursively, markers evaluated here,
    luckyao excluded."""
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    pinned, seen, todo = {}, set(), [("luckyao", frozenset(STUDY_EXTRAS))]
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
    header = (
        f"# luckyao's runtime dependencies, exact versions (Python {platform.python_version()}, "
        f"{platform.system()} {platform.machine()}); made by `luckyao lock`.\n"
        "# Environment: pip install -r requirements.lock && pip install --no-deps -e .\n"
    )
    return header + "".join(f"{name}=={version}\n" for name, version in runtime_packages().items())


def parse_lock(text: str) -> dict[str, str]:
    """Name -> version of the ``name==version`` lines of a requirements lock."""
    pins = (line.split("#")[0].strip().split("==") for line in text.splitlines())
    return {pin[0].strip(): pin[1].strip() for pin in pins if len(pin) == 2}


def package_differences(archived: dict[str, str], here: dict[str, str]) -> list[str]:
    """One line per package whose version differs between two name -> version maps."""
    return [
        f"{name} {archived.get(name, 'absent')} archived, {here.get(name, 'absent')} here"
        for name in sorted(set(archived) | set(here), key=str.lower)
        if archived.get(name) != here.get(name)
    ]


def git_state(repo: Path = REPO) -> dict:
    """Commit of the checkout, its uncommitted changes to tracked files and its untracked
    files (``None``, ``""``, ``[]`` without git)."""

    def git(*args):
        return subprocess.run(
            ["git", "-C", str(repo), *args], capture_output=True, text=True, timeout=30, check=True
        ).stdout

    try:
        return {
            "commit": git("rev-parse", "HEAD").strip(),
            "diff": git("diff", "HEAD"),
            "untracked": git("ls-files", "--others", "--exclude-standard").split(),
        }
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
    """``step/name`` of every job ``results/cases/<case>/lucky.nc`` needs from scratch: with
    an LGS twin (``studyspec.products.lgs_twin``), the twin's simulation and its products too (an AO
    case's slopes: ``studyspec.products.slopes_spec``)."""
    view = resolve_study(study, cases)
    twin = view.cases[case].lgs_twin
    simulated = [twin, case] if twin else [case]
    jobs = [f"turbulence/{view.cases[case].screens.key}"]
    for name in simulated:
        resolved = view.cases[name]
        for step in ("reconstructor", "calibration", "commands", "slopes"):
            if (product := getattr(resolved, step)) is not None and (job := f"{step}/{product.key}") not in jobs:
                jobs.append(job)
    return jobs + [f"simulate/{name}" for name in simulated] + [f"lucky/{case}"]


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
    return "".join(
        f"{hashlib.sha256(data).hexdigest()}  {name}\n" for name, data in sorted(members.items()) if name != CHECKSUMS
    ).encode()


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
    """Name (without the top folder) -> bytes of every file in the archive ``path``, all
    held in memory (for a trusted archive; ``verify`` streams instead)."""
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
        raise ArchiveError(
            "\n".join(f"{name}: missing; finish the study (snakemake) before archiving" for name in missing)
        )
    archived_cases = [c for c in cases if (study_dir / "results" / "cases" / c / "lucky.nc").is_file()]
    for case in archived_cases:
        files += [
            f"results/cases/{case}/{name}"
            for name in CASE_FILES
            if (study_dir / "results" / "cases" / case / name).is_file()
        ]
        files += [
            f"results/benchmarks/{job}.tsv"
            for job in case_jobs(study, cases, case)
            if (study_dir / "results" / "benchmarks" / f"{job}.tsv").is_file()
        ]
    files = list(dict.fromkeys(files))  # shared jobs once
    stale = [p for name in files if name.endswith(".nc") for p in _stale(study_dir / name, name, study, cases)]
    if stale:
        raise ArchiveError(
            "\n".join(
                stale
                + [
                    f"archive with the config files the study ran with "
                    f"(given: {' + '.join(map(str, sources))}) or rerun it"
                ]
            )
        )
    drawn = drawn_cases(expand_study(study))
    absent = [
        f"case '{case}': results/cases/{case}/{name} missing; rerun the study (snakemake) before archiving"
        for case in drawn
        for name in CASE_FILES
        if not (study_dir / "results" / "cases" / case / name).is_file()
    ]
    if absent:  # a study is never archived with a case its figures show missing (after the config's check:
        # results of another config name their cause better)
        raise ArchiveError("\n".join(absent))
    bad = []
    for case in archived_cases:  # the rule lucky.nc is written with, checked again (nothing NaN archived)
        path = study_dir / "results" / "cases" / case / "lucky.nc"
        try:
            require_finite_lucky(open_dataset(path, f"case '{case}' lucky"), f"case '{case}': lucky file '{path}'")
        except (OSError, ValueError) as err:
            bad.append(str(err))
    if bad:
        raise ArchiveError("\n".join(bad + ["rerun the study (snakemake) before archiving"]))
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
    members = {
        "MANIFEST.json": (json.dumps(manifest, indent=1) + "\n").encode(),
        "config.yaml": config_text.encode(),
        "requirements.lock": lock.encode(),
    }
    if git["diff"]:
        members["code.diff"] = git["diff"].encode()
    members |= {name: (study_dir / name).read_bytes() for name in files}
    members[CHECKSUMS] = checksum_list(members)
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    path = Path(out) if out else study_dir / "archives" / f"luckyao-{manifest['config_sha256'][:12]}-{stamp}.tar"
    write_members(path, members)
    size_mb = path.stat().st_size / 1e6
    echo(
        f"archived {len(members)} files of {len(archived_cases)} cases and {len(study['figures'])} figures "
        f"({size_mb:.1f} MB) in {time.perf_counter() - start:.1f} s: {path}"
    )
    if git["diff"]:
        echo("warning: the checkout has uncommitted changes (archived as code.diff over the commit)")
    if git["untracked"]:
        echo(f"warning: files not in git (listed in MANIFEST.json, not archived): {' '.join(git['untracked'])}")
    repo_lock = REPO / "requirements.lock"
    if repo_lock.is_file():
        for line in package_differences(parse_lock(repo_lock.read_text()), manifest["packages"]):
            echo(f"warning: this environment differs from requirements.lock: {line.replace('archived', 'locked')}")
    return path
