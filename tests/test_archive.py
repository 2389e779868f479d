"""Archived reproducibility runs on the tiny study: ``luckyao archive`` holds the config,
results, figures, versions and checksums; ``luckyao verify`` checks them and reruns a case,
and fails naming the member, or the file and variable, when anything differs."""

import gzip
import hashlib
import io
import json
import shutil
import subprocess
import sys
import tarfile
import tempfile
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from luckyao.archive.create import CHECKSUMS, checksum_list, read_members, runtime_packages, write_members
from luckyao.archive.verify import MEMBER_LIMIT_BYTES, compare_variables
from luckyao.cli import main
from luckyao.studyspec.study import validate_study

pytestmark = pytest.mark.workflow  # runs Snakemake, a study or the command line: -m 'not workflow' skips it

REPO = Path(__file__).resolve().parents[1]
TINY = REPO / "tests" / "data" / "tiny.yaml"


def no_lgs_study() -> dict:
    """The tiny study cut to its cases without LGS and the figures of only those (the cheapest
    jobs: the archive and verify do not depend on what the cases model)."""
    study = yaml.safe_load(TINY.read_text())
    cheap = {name for name, case in validate_study(study).items() if not case["lgs"]["enabled"]}
    study["figures"] = {fig: f for fig, f in study["figures"].items() if set(f.get("cases", [])) <= cheap}
    shown = {case for f in study["figures"].values() for case in f.get("cases", [])}
    study["cases"] = {name: case for name, case in study["cases"].items() if name in shown}
    study["lucky"]["detector_sweep"]["cases"] = [
        name for name in study["lucky"]["detector_sweep"]["cases"] if name in shown
    ]
    assert study["figures"] and study["cases"]
    return study


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A finished run of ``no_lgs_study`` (about 30 s)."""
    workdir = tmp_path_factory.mktemp("study")
    (workdir / "config").mkdir()
    (workdir / "config" / "config.yaml").write_text(yaml.safe_dump(no_lgs_study()))
    command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d", str(workdir), "--cores", "2"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    return workdir


@pytest.fixture(scope="module")
def archive(study):
    path = study / "run.tar"
    assert main(["archive", "--study-dir", str(study), "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def verified(archive, tmp_path_factory):
    """``verify`` of the untouched archive, rerunning case ``good`` in a kept folder: (exit
    code, output, folder). Later tests reuse the finished rerun there (Snakemake reruns nothing)."""
    workdir = tmp_path_factory.mktemp("rerun")
    output = io.StringIO()
    with redirect_stdout(output):
        code = main(["verify", str(archive), "--case", "good", "--workdir", str(workdir)])
    return code, output.getvalue(), workdir


def verify(capsys, *args) -> tuple[int, str]:
    code = main(["verify", *map(str, args)])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def rewritten(archive: Path, path: Path, changes: dict[str, bytes], update_checksums: bool) -> Path:
    """A copy of ``archive`` with members replaced, and ``SHA256SUMS`` updated or left as archived."""
    members = read_members(archive) | changes
    if update_checksums:
        members[CHECKSUMS] = checksum_list(members)
    write_members(path, members)
    return path


def test_archive_holds_config_results_figures_versions_and_checksums(study, archive):
    members = read_members(archive)
    study_config = yaml.safe_load((study / "config" / "config.yaml").read_text())
    assert yaml.safe_load(members["config.yaml"]) == study_config
    for case in study_config["cases"]:
        assert {
            f"results/cases/{case}/lucky.nc",
            f"results/cases/{case}/telemetry.nc",
            f"results/benchmarks/simulate/{case}.tsv",
        } <= set(members)
    for fig in study_config["figures"]:
        assert {f"figures/{fig}.nc", f"figures/{fig}.png", f"figures/{fig}.pdf"} <= set(members)
    assert not any(name.endswith(("frames.nc", ".npy")) for name in members)
    manifest = json.loads(members["MANIFEST.json"])
    assert manifest["packages"]["numpy"] == np.__version__ and "luckyao" not in manifest["packages"]
    assert manifest["git_commit"] and manifest["code_version"] and manifest["python"]
    assert set(manifest["cases"]) == set(validate_study(study_config))  # with the sweeps' cases
    listed = dict(line.split("  ")[::-1] for line in members[CHECKSUMS].decode().splitlines())
    assert set(listed) == set(members) - {CHECKSUMS}
    assert all(hashlib.sha256(members[name]).hexdigest() == digest for name, digest in listed.items())


def test_verify_passes_with_an_identical_rerun(verified):
    code, output, _ = verified
    assert code == 0, output
    assert "verify: OK" in output
    assert "results/cases/good/lucky.nc: strehl: identical" in output
    assert "results/cases/good/telemetry.nc: axis_strehl: identical" in output


def test_verify_fails_naming_a_changed_or_missing_member(archive, tmp_path, capsys):
    members = read_members(archive)
    figure = next(name for name in members if name.startswith("figures/") and name.endswith(".nc"))
    tampered = bytearray(members[figure])
    tampered[-100] ^= 0xFF
    code, output = verify(capsys, rewritten(archive, tmp_path / "a.tar", {figure: bytes(tampered)}, False))
    assert code == 1 and f"{figure}: checksum differs" in output and "not rerun" in output
    members.pop("results/cases/bad/telemetry.nc")
    write_members(tmp_path / "b.tar", members)
    code, output = verify(capsys, tmp_path / "b.tar")
    assert code == 1 and "results/cases/bad/telemetry.nc: missing" in output


def test_verify_fails_naming_file_and_variable_when_a_result_differs(archive, verified, tmp_path, capsys):
    """An archived Strehl changed by 1e-5 (relative), its checksum updated: the checksums
    pass and the rerun comparison fails naming the file and the variable; ``--rtol 1e-4``
    accepts it."""
    _, _, workdir = verified
    member = "results/cases/good/lucky.nc"
    original = tmp_path / "lucky.nc"
    original.write_bytes(read_members(archive)[member])
    with xr.open_dataset(original) as ds:
        changed = ds.load()
    strehl = changed["strehl"].values
    strehl.flat[np.flatnonzero(np.isfinite(strehl) & (strehl > 0))[0]] *= 1 + 1e-5
    changed.to_netcdf(tmp_path / "changed.nc")
    path = rewritten(archive, tmp_path / "c.tar", {member: (tmp_path / "changed.nc").read_bytes()}, True)
    code, output = verify(capsys, path, "--case", "good", "--workdir", workdir)
    assert code == 1, output
    assert "checksums: all" in output
    assert f"FAILED: {member}: strehl: max abs diff" in output and "DIFFERS" in output
    assert f"{member}: fwhm_arcsec: identical" in output
    code, output = verify(capsys, path, "--case", "good", "--workdir", workdir, "--rtol", "1e-4")
    assert code == 0, output
    assert f"{member}: strehl: max abs diff" in output and "within rtol=0.0001" in output


def test_verify_warns_when_the_environment_differs(archive, tmp_path, capsys):
    lock = read_members(archive)["requirements.lock"].decode().replace(f"numpy=={np.__version__}", "numpy==1.0")
    path = rewritten(archive, tmp_path / "d.tar", {"requirements.lock": lock.encode()}, True)
    code, output = verify(capsys, path, "--no-rerun")
    assert code == 0, output
    assert f"warning: environment differs: numpy 1.0 archived, {np.__version__} here" in output


def test_archive_refuses_results_of_another_config(study, tmp_path, capsys):
    """Archiving with an overlay the study did not run with names the files it did not make."""
    overlay = tmp_path / "overlay.yaml"
    overlay.write_text("cases: {good: {atmosphere: {r0_500nm_m: 0.3}}}\n")
    code = main(["archive", "--study-dir", str(study), "--configfile", str(overlay), "--out", str(tmp_path / "x.tar")])
    assert code == 1
    assert "results/cases/good/lucky.nc: made from another config" in capsys.readouterr().err
    assert not (tmp_path / "x.tar").exists()


def test_requirements_lock_pins_every_runtime_dependency():
    """``requirements.lock`` (the whole .venv: test_setup.py) pins every package a study runs
    with, the workflow's, figures' and FITS export's among them (names; versions may move on);
    an archive's lock holds those alone."""
    pins = [line for line in (REPO / "requirements.lock").read_text().splitlines() if not line.startswith("#")]
    assert all(line.count("==") == 1 for line in pins)
    names = {line.split("==")[0] for line in pins}
    runtime = set(runtime_packages())
    assert runtime <= names and "luckyao" not in names
    assert {"numpy", "xarray", "snakemake", "matplotlib", "astropy"} <= runtime and "pytest" not in runtime


def test_compare_states_agreement_per_variable():
    archived = xr.Dataset(
        {"a": ("x", [1.0, np.nan]), "b": ("x", [1.0, 2.0]), "c": ("x", [1, 2]), "gone": ((), 0.0)},
        coords={"x": ["p", "q"]},
        attrs={"seed": 1},
    )
    fresh = xr.Dataset(
        {"a": ("x", [1.0, np.nan]), "b": ("x", [1.0, 2.002]), "c": ("x", [1, 3]), "new": ((), 0.0)},
        coords={"x": ["p", "r"]},
        attrs={"seed": 1},
    )
    rows = {name: (agrees, how) for name, agrees, how in compare_variables(fresh, archived, 1e-2, 0.0)}
    assert rows["a"] == (True, "identical") and rows["attribute seed"] == (True, "identical")
    assert rows["b"][0] and "max abs diff 0.002, max rel diff 0.001: within rtol=0.01" in rows["b"][1]
    assert rows["c"] == (False, "max abs diff 1, max rel diff 0.5: DIFFERS")
    assert rows["x"] == (False, "DIFFERS") and not rows["gone"][0] and rows["new"][0]
    exact = {name: agrees for name, agrees, _ in compare_variables(fresh, archived, 0.0, 0.0)}
    assert exact["a"] and not exact["b"]


def test_verify_names_a_changed_case_it_does_not_rerun_only_with_all_cases(archive, verified, tmp_path, capsys):
    """With ``SHA256SUMS`` rewritten, a changed ``lucky.nc`` of a case other than the one
    rerun passes (the checksums are no signature); ``--all-cases`` reruns it and fails."""
    _, _, workdir = verified
    member = "results/cases/bad/lucky.nc"
    original = tmp_path / "lucky.nc"
    original.write_bytes(read_members(archive)[member])
    with xr.open_dataset(original) as ds:
        changed = ds.load()
    changed["strehl"].values[...] *= 1 + 1e-5
    changed.to_netcdf(tmp_path / "changed.nc")
    path = rewritten(archive, tmp_path / "e.tar", {member: (tmp_path / "changed.nc").read_bytes()}, True)
    code, output = verify(capsys, path, "--case", "good", "--workdir", workdir)
    assert code == 0, output
    code, output = verify(capsys, path, "--all-cases", "--workdir", workdir)
    assert code == 1, output
    assert f"FAILED: {member}: strehl: max abs diff" in output
    assert "results/cases/good/lucky.nc: strehl: identical" in output


def test_a_corrupt_member_of_the_rerun_case_is_named_and_its_scratch_folder_removed(
    archive, verified, tmp_path, capsys, monkeypatch
):
    """The scratch folder is given a copy of the finished rerun (Snakemake reruns nothing)."""
    _, _, rerun = verified
    member = "results/cases/good/telemetry.nc"
    path = rewritten(archive, tmp_path / "f.tar", {member: b"not a netCDF file"}, True)
    scratch = tmp_path / "luckyao-verify-scratch"
    shutil.copytree(rerun, scratch, symlinks=True)
    monkeypatch.setattr(tempfile, "mkdtemp", lambda prefix: str(scratch))
    code, output = verify(capsys, path, "--case", "good")
    assert code == 1, output
    assert f"FAILED: {member}: unreadable" in output and "Traceback" not in output
    assert not scratch.exists()


class Zeros(io.RawIOBase):
    """``n`` zero bytes, never held."""

    def __init__(self, n: int):
        self.left = n

    def readable(self):
        return True

    def readinto(self, buffer):
        k = min(len(buffer), self.left)
        buffer[:k] = bytes(k)
        self.left -= k
        return k


def verify_in_a_process(archive: Path):
    """``luckyao verify ARCHIVE`` in a fresh process: its exit code, how far its peak memory grew
    during the verify [KiB] (the imports excluded), and the finished process (its output)."""
    script = (
        "import resource, sys; from luckyao.cli import main; import luckyao.archive.verify; "
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss; code = main(['verify', sys.argv[1]]); "
        "print(code, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before)"
    )
    result = subprocess.run([sys.executable, "-c", script, str(archive)], capture_output=True, text=True, timeout=600)
    code, growth_kib = map(int, result.stdout.split()[-2:])
    return code, growth_kib, result


def test_verify_reads_a_tar_bomb_in_bounded_memory(tmp_path):
    """A 1.5 MB ``.tar.gz`` holding a 320 MiB member: hashed as a stream (peak memory grows
    by less than 100 MB; reading it whole took 320 MB), refused as not in SHA256SUMS."""
    bomb, size = tmp_path / "bomb.tar.gz", 320 << 20
    with tarfile.open(bomb, "w:gz", compresslevel=1) as tar:
        tar.addfile(tarfile.TarInfo(f"bomb/{CHECKSUMS}"), io.BytesIO(b""))
        info = tarfile.TarInfo("bomb/results/cases/good/lucky.nc")
        info.size = size
        tar.addfile(info, io.BufferedReader(Zeros(size)))
    code, growth_kib, result = verify_in_a_process(bomb)
    assert code == 1 and "results/cases/good/lucky.nc: not in SHA256SUMS" in result.stdout, result.stdout
    assert growth_kib < 100_000, f"peak memory grew by {growth_kib / 1024:.0f} MiB"


def test_verify_refuses_unread_a_member_larger_than_any_archived_file(tmp_path, capsys):
    header = tarfile.TarInfo("big/results/cases/good/lucky.nc")
    header.size = MEMBER_LIMIT_BYTES + 1
    path = tmp_path / "big.tar.gz"
    path.write_bytes(gzip.compress(header.tobuf(format=tarfile.GNU_FORMAT) + bytes(4096)))
    code, output = verify(capsys, path)
    assert code == 1 and "member results/cases/good/lucky.nc claims 2,147,483,649 bytes" in output


def appended(archive: Path, path: Path, *infos: tuple[tarfile.TarInfo, bytes]) -> Path:
    """A copy of ``archive`` with members appended under its top folder, ``SHA256SUMS`` as archived."""
    shutil.copy(archive, path)
    top = archive.name.removesuffix(".tar")
    with tarfile.open(path, "a") as tar:
        for info, data in infos:
            info.name = f"{top}/{info.name}"
            tar.addfile(info, io.BytesIO(data) if data else None)
    return path


@pytest.mark.workflow
@pytest.mark.parametrize("kind", ["symlink", "hardlink", "fifo"])
def test_verify_refuses_a_link_or_other_non_regular_member(kind, archive, tmp_path, capsys):
    """A link to /etc/passwd added to the archive passed: verify skipped every non-file member."""
    info = tarfile.TarInfo("results/cases/good/extra.nc")
    info.type = {"symlink": tarfile.SYMTYPE, "hardlink": tarfile.LNKTYPE, "fifo": tarfile.FIFOTYPE}[kind]
    info.linkname = "/etc/passwd" if kind != "fifo" else ""
    code, output = verify(capsys, appended(archive, tmp_path / "a.tar", (info, b"")), "--no-rerun")
    assert code == 1, output
    expected = {
        "symlink": "is a symbolic link to '/etc/passwd'",
        "hardlink": "is a hard link to '/etc/passwd'",
        "fifo": "is a device or FIFO",
    }[kind]
    assert f"member results/cases/good/extra.nc {expected}" in output, output


@pytest.mark.workflow
def test_verify_refuses_a_member_archived_twice(archive, tmp_path, capsys):
    """Two copies of one name: checked on the last, extracted from the first. Refused."""
    data = read_members(archive)["results/cases/good/lucky.nc"]
    info = tarfile.TarInfo("results/cases/good/lucky.nc")
    info.size = len(data)
    code, output = verify(capsys, appended(archive, tmp_path / "a.tar", (info, data)), "--no-rerun")
    assert code == 1 and "member results/cases/good/lucky.nc is archived twice" in output, output


@pytest.mark.workflow
@pytest.mark.parametrize("folder", ["study", "other"])
def test_verify_refuses_a_workdir_that_is_a_study_or_not_empty_untouched(folder, study, archive, tmp_path, capsys):
    """--workdir at a study folder overwrote its config/config.yaml and reran jobs into its results/."""
    if folder == "other":
        workdir = tmp_path / "other"
        workdir.mkdir()
        (workdir / "notes.txt").write_text("mine")
    else:
        workdir = study
    before = sorted((p.relative_to(workdir), p.stat().st_mtime_ns) for p in workdir.rglob("*"))
    code, output = verify(capsys, archive, "--case", "good", "--workdir", workdir)
    assert code == 1, output
    assert f"--workdir '{workdir}' is {'a study folder' if folder == 'study' else 'not empty'}" in output, output
    assert sorted((p.relative_to(workdir), p.stat().st_mtime_ns) for p in workdir.rglob("*")) == before


def test_verify_reads_many_large_benchmark_members_in_bounded_memory(tmp_path):
    """100 benchmark members of 16 MiB each (an 85 MB file) peaked at 1.79 GB: each was held.
    A benchmark table is ~200 bytes: one over 64 KiB is refused unread."""
    bomb, size = tmp_path / "bench.tar.gz", 16 << 20
    with tarfile.open(bomb, "w:gz", compresslevel=1) as tar:
        tar.addfile(tarfile.TarInfo(f"bench/{CHECKSUMS}"), io.BytesIO(b""))
        for i in range(100):
            info = tarfile.TarInfo(f"bench/results/benchmarks/simulate/case{i}.tsv")
            info.size = size
            tar.addfile(info, io.BufferedReader(Zeros(size)))
    code, growth_kib, result = verify_in_a_process(bomb)
    assert code == 1 and "claims 16,777,216 bytes, more than verify reads (65,536)" in result.stderr, result.stderr
    assert growth_kib < 100_000, f"peak memory grew by {growth_kib / 1024:.0f} MiB"


def test_verify_bounds_the_members_it_holds_together_and_their_number(tmp_path, monkeypatch, capsys):
    from luckyao.archive import verify as verify_module

    path = tmp_path / "many.tar"
    with tarfile.open(path, "w") as tar:
        for i in range(12):
            info = tarfile.TarInfo(f"many/results/benchmarks/simulate/case{i}.tsv")
            info.size = 1000
            tar.addfile(info, io.BytesIO(bytes(1000)))
    monkeypatch.setattr(verify_module, "HELD_LIMIT_BYTES", 5000)
    code, output = verify(capsys, path)
    assert code == 1 and "benchmark members hold more than 5,000 bytes together" in output, output
    monkeypatch.setattr(verify_module, "HELD_LIMIT_BYTES", 1 << 20)
    monkeypatch.setattr(verify_module, "MEMBER_COUNT_LIMIT", 10)
    code, output = verify(capsys, path)
    assert code == 1 and "has more than 10 members" in output, output
