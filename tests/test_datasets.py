"""Files: atomic writes, provenance, and clear errors for missing or corrupt inputs."""

import numpy as np
import pytest
import xarray as xr

from luckyao.study.config import sha256
from luckyao.study.datasets import FrameWriter, iter_frame_blocks, open_dataset, provenance, write_dataset


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
