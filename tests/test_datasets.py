"""Files: atomic writes, provenance, and clear errors for missing or corrupt inputs."""

import subprocess
import sys

import netCDF4
import numpy as np
import pytest
import xarray as xr

from luckyao.io.datasets import FrameWriter, iter_frame_blocks, open_dataset, provenance, write_dataset
from luckyao.io.hashing import sha256
from luckyao.threads import STUDY_JOB


def test_provenance_carries_config_hash_version_and_seed():
    config = {"a": 1, "b": [1.5, 2]}
    attrs = provenance("t", config, 42)
    assert attrs["config_sha256"] == sha256(config) and attrs["seed"] == 42 and attrs["code_version"]
    assert all(not isinstance(v, (bool, dict, type(None))) for v in attrs.values())


def test_missing_and_corrupt_files_say_which_and_why(tmp_path):
    with pytest.raises(FileNotFoundError, match="telemetry file .*missing.nc"):
        open_dataset(tmp_path / "missing.nc", "telemetry")
    corrupt = tmp_path / "corrupt.nc"
    corrupt.write_bytes(b"not a netCDF file")
    with pytest.raises(OSError, match="corrupt"):
        open_dataset(corrupt, "lucky")
    with pytest.raises(FileNotFoundError, match="frames file"):
        iter_frame_blocks(tmp_path / "frames.nc", 0)


def test_a_failed_write_leaves_no_result(tmp_path):
    path = tmp_path / "frames.nc"
    with pytest.raises(RuntimeError):
        with FrameWriter(path, [0], 4, 8, 0.1, {"title": "t"}) as writer:
            writer.write(0, np.ones((1, 2, 8, 8), np.float32))
            raise RuntimeError("simulation failed half way")
    assert list(tmp_path.iterdir()) == []


def test_frames_round_trip(tmp_path):
    path = tmp_path / "frames.nc"
    frames = np.random.default_rng(0).random((2, 5, 8, 8)).astype(np.float32)
    with FrameWriter(path, [0, 1], 5, 8, 0.1, {"title": "t"}) as writer:
        writer.write(0, frames[:, :3])
        writer.write(3, frames[:, 3:])
    blocks = list(iter_frame_blocks(path, 1, block=2)())
    assert [start for start, _ in blocks] == [0, 2, 4]
    np.testing.assert_array_equal(np.concatenate([b for _, b in blocks]), frames[1])
    star_only = tmp_path / "star.nc"  # a field case stores its star (here target 3) only
    with FrameWriter(star_only, [3], 5, 8, 0.1, {"title": "t"}) as writer:
        writer.write(0, frames[1:])
    np.testing.assert_array_equal(next(iter_frame_blocks(star_only, 3, block=5)())[1], frames[1])
    with pytest.raises(ValueError, match=r"holds targets \[3\], not target 0"):
        next(iter_frame_blocks(star_only, 0)())
    ds = xr.Dataset({"v": ("x", np.arange(3.0), {"units": "1", "long_name": "v"})})
    write_dataset(ds, tmp_path / "v.nc")
    assert open_dataset(tmp_path / "v.nc", "v").v.values.tolist() == [0.0, 1.0, 2.0]


@pytest.fixture
def study_job(tmp_path, monkeypatch):
    """This process as a job of the workflow (``STUDY_JOB``) in the study folder ``tmp_path``:
    the folder of its results, where a bad input is set aside."""
    monkeypatch.setenv(STUDY_JOB, "1")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results").mkdir()
    return tmp_path / "results"


def test_nan_in_a_frame_cube_is_named_against_it_and_the_cube_set_aside_for_the_next_run(study_job):
    path = study_job / "frames.nc"
    with FrameWriter(path, [0], 70, 8, 0.1, {"title": "t"}) as writer:
        writer.write(0, np.ones((1, 70, 8, 8), np.float32))
    with netCDF4.Dataset(path, "r+") as nc:
        nc["frames"][0, 66, 2, 3] = np.nan
    with pytest.raises(
        ValueError,
        match=r"frames file '.*frames\.nc': variable 'frames' is not finite at "
        r"frame=2, y=2, x=3 \(block from frame 64.*set aside as '.*frames\.nc\.bad'",
    ):
        list(iter_frame_blocks(path, 0)())
    assert not path.exists() and path.with_name("frames.nc.bad").exists()


def test_nan_in_a_telemetry_file_is_named_against_it_and_the_file_set_aside(study_job):
    path = study_job / "telemetry.nc"
    write_dataset(
        xr.Dataset(
            {
                "true_rms_m": (("target", "frame"), np.ones((1, 5))),
                "axis_strehl": (("target", "frame"), np.full((1, 5), np.nan)),
            }
        ),
        path,
        allow_nan={"axis_strehl"},
    )
    assert open_dataset(path, "telemetry", allow_nan={"axis_strehl"}).sizes["frame"] == 5
    with netCDF4.Dataset(path, "r+") as nc:
        nc["true_rms_m"][0, 3] = np.nan
    with pytest.raises(
        ValueError,
        match=r"telemetry file '.*telemetry\.nc': variable 'true_rms_m' is not finite "
        r"at target=0, frame=3.*the next run remakes it",
    ):
        open_dataset(path, "telemetry", allow_nan={"axis_strehl"})
    assert not path.exists() and path.with_name("telemetry.nc.bad").exists()


def test_a_truncated_input_is_set_aside_for_the_next_run(study_job):
    path = study_job / "reconstructor.nc"
    write_dataset(xr.Dataset({"r": ("x", np.arange(1000.0))}), path, compress=False)
    path.write_bytes(path.read_bytes()[:2000])
    with pytest.raises(OSError, match=r"reconstructor file '.*' is unreadable or corrupt.*set aside"):
        open_dataset(path, "reconstructor", allow_nan=())
    assert not path.exists() and path.with_name("reconstructor.nc.bad").exists()


def test_a_failed_write_names_the_file_and_what_limits_it(tmp_path):
    """A file over the size limit (``ulimit -f``): the error names the file, the bytes written
    and the limit, not only netCDF's "HDF error"; nothing is left."""
    script = (
        "import resource, signal, sys, numpy as np, xarray as xr\n"
        "from luckyao.io.datasets import write_dataset\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, resource.RLIM_INFINITY))\n"
        "try:\n"
        "    write_dataset(xr.Dataset({'v': ('x', np.arange(100_000.0))}), sys.argv[1], compress=False)\n"
        "except OSError as err:\n"
        "    print(err)\n"
    )
    path = tmp_path / "big.nc"
    result = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=120)
    assert f"writing '{path}' failed after" in result.stdout, result.stdout + result.stderr
    assert "GB free on its disk" in result.stdout and "file size limit (ulimit -f) 200,000 bytes" in result.stdout
    assert list(tmp_path.iterdir()) == []
