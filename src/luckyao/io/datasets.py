"""netCDF files of the study: provenance, atomic writes, checked reads.

Every file is written under a temporary name and renamed when complete, so a
file with the final name is never half-written; a failed write names the file
and what limits it (free disk, file size limit). A study file read by a job
of the workflow that is unreadable or holds NaN where it may not is set aside
as ``<name>.bad`` (``set_aside``), with an error naming it: the next run remakes
it with the job that made it (and reruns what depends on it). Only a workflow
job does that (``STUDY_JOB``, set by ``workflow/rules/common.smk``), and only to
a file in its study folder's ``results/``: a command run by hand (``luckyao
export``, ``open_case``, ``open_figure``, ``draw``) never moves, renames or
writes the files it reads, it names the problem. Conventions: CF-1.8 style,
``units`` and ``long_name`` on every variable; provenance in global attributes.
"""

import datetime
import json
import os
import platform
import resource
import shutil
import subprocess
from contextlib import contextmanager
from functools import cache
from importlib.metadata import version
from pathlib import Path

import netCDF4
import numpy as np
import xarray as xr

from ..threads import is_study_job
from ..version import __version__
from .hashing import canonical_json, sha256


@cache
def code_version() -> str:
    """The package version, with the git commit of its source tree and ``+dirty`` when
    that tree has uncommitted changes (``git`` absent or no checkout: the version alone)."""
    source = Path(__file__).resolve().parents[1]
    try:

        def git(*args):
            return subprocess.run(
                ["git", "-C", str(source), *args], capture_output=True, text=True, timeout=10, check=True
            ).stdout.strip()

        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no", "--", "."))
    except (OSError, subprocess.SubprocessError):
        return __version__
    return f"{__version__} git {commit}{' +dirty' if dirty else ''}"


def provenance(title: str, config: dict, seed: int) -> dict:
    """Global attributes: the config as JSON, its sha256, code version, seed, and the
    versions of every library that shapes the numbers."""
    libraries = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": version("scipy"),
        "numba": version("numba"),
        "pyfftw": version("pyFFTW"),
        "xarray": xr.__version__,
        "netCDF4": netCDF4.__version__,
        "netcdf_library": netCDF4.__netcdf4libversion__,
        "hdf5_library": netCDF4.__hdf5libversion__,
        "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE", "auto"),
    }
    return {
        "Conventions": "CF-1.8",
        "title": title,
        "source": f"luckyao {__version__}",
        "history": f"{datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')} created by luckyao",
        "config_json": canonical_json(config),
        "config_sha256": sha256(config),
        "code_version": code_version(),
        "seed": int(seed),
        "library_versions": json.dumps(libraries),
    }


def require_finite(values, what: str, variable: str, index_names=()) -> None:
    """Raise ``ValueError`` naming ``what`` (a file or a stage), the variable and the first
    non-finite element's index, if ``values`` holds NaN or an infinity: nothing wrong is
    ever taken as a result."""
    finite = np.isfinite(values)
    if not finite.all():
        index = np.unravel_index(np.argmin(finite), np.shape(values))
        where = (
            ", ".join(f"{n}={i}" for n, i in zip(index_names, index)) if index_names else str(tuple(map(int, index)))
        )
        raise ValueError(f"{what}: variable '{variable}' is not finite at {where}")


def may_set_aside(path) -> bool:
    """Whether ``path`` may be set aside here: only by a job of the workflow, and only a
    file in its study folder's ``results/`` (the working folder's), after links resolved;
    never a file a user handed to a command (``luckyao export README.md``)."""
    if not is_study_job():
        return False
    results = (Path.cwd() / "results").resolve()
    try:
        resolved = Path(path).resolve()
    except (OSError, RuntimeError):
        return False
    return resolved.is_relative_to(results) and resolved != results


def require_finite_lucky(ds: xr.Dataset, what: str) -> None:
    """Raise ``ValueError`` naming ``what``, the variable and the first bad element's index
    (with its label: ``detector=1 ('emccd')``) if a case's lucky results ``ds`` hold NaN or
    an infinity where they may not: the rule ``lucky.nc`` is written with, and that every
    reader of it checks again (figures, FITS export, archive). A noisy image can have no
    positive flux (a few photons under read noise): its metrics are undefined (NaN), per
    frame (``frame_*``) or integrated. Nothing else may be NaN: every value of the
    noiseless detectors and every variable without a detector."""
    noisy = (
        np.isfinite(ds["photons_per_frame"].values)
        if "photons_per_frame" in ds.coords
        else np.zeros(ds.sizes.get("detector", 0), bool)
    )
    for name, var in ds.data_vars.items():
        if var.dtype.kind != "f" or name.startswith("frame_"):
            continue
        bad = ~np.isfinite(var.values)
        if "detector" in var.dims and noisy.any():
            shape = [1] * var.ndim
            shape[var.dims.index("detector")] = -1
            bad &= ~noisy.reshape(shape)
        if bad.any():
            index = np.unravel_index(np.argmax(bad), bad.shape)
            where = []
            for dim, i in zip(var.dims, index):
                label = ds[dim].values[i] if dim in ds.coords and ds[dim].ndim == 1 else None
                where.append(f"{dim}={int(i)}" + (f" ('{label}')" if isinstance(label, str) else ""))
            raise ValueError(f"{what}: variable '{name}' is not finite at {', '.join(where) or '()'}")


def set_aside(path, problem: str) -> str:
    """Rename the bad study file ``path`` to ``<name>.bad`` (replacing an older one), so
    that the next run remakes it, when this process may (``may_set_aside``); returns
    ``problem`` saying what was done. A file it may not set aside is left where it is."""
    path = Path(path)
    if not may_set_aside(path):
        return problem
    bad = path.with_name(path.name + ".bad")
    try:
        os.replace(path, bad)
    except OSError as err:
        return f"{problem}; delete it and rerun (it could not be set aside: {err})"
    return f"{problem}; set aside as '{bad}': the next run remakes it"


def write_failure(path, partial: Path, err: Exception) -> OSError:
    """The error of a failed write, naming the file, how far it got and what limits it."""
    path = Path(path)
    written = partial.stat().st_size if partial.exists() else 0
    limits = [f"{shutil.disk_usage(path.parent).free / 1e9:,.1f} GB free on its disk"]
    file_limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if file_limit != resource.RLIM_INFINITY:
        limits.append(f"file size limit (ulimit -f) {file_limit:,} bytes")
    return OSError(f"writing '{path}' failed after {written:,} bytes: {err} ({'; '.join(limits)})")


@contextmanager
def atomic_path(path):
    """Yields a temporary path next to ``path``; renamed to ``path`` on success only."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    try:
        yield partial
        os.replace(partial, path)
    finally:
        if partial.exists():
            partial.unlink()


def write_dataset(ds: xr.Dataset, path, compress: bool = True, allow_nan=()) -> None:
    """Write ``ds`` to netCDF4 atomically; floats compressed with zlib + shuffle. Every
    float variable must be finite, except those in ``allow_nan`` (NaN meaning "none")."""
    for name, var in ds.data_vars.items():
        if var.dtype.kind == "f" and name not in allow_nan:
            require_finite(var.values, f"file '{path}'", name, var.dims)
    encoding = {}
    if compress:
        for name, var in ds.data_vars.items():
            if var.dtype.kind == "f" and var.size > 1:
                encoding[name] = {"zlib": True, "complevel": 4, "shuffle": True}
    with atomic_path(path) as tmp:
        try:
            ds.to_netcdf(tmp, engine="netcdf4", encoding=encoding)
        except (OSError, RuntimeError) as err:
            raise write_failure(path, tmp, err) from err


def open_dataset(path, what: str, allow_nan=None, remake: bool = True) -> xr.Dataset:
    """Open a study file fully into memory with a clear error if missing or corrupt. With
    ``allow_nan`` (a set), every float variable but those must be finite. A corrupt or
    non-finite file is set aside for the next run to remake (``remake``) when this is a
    workflow job and the file its study's (``may_set_aside``); otherwise left as it is."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{what} file '{path}' is missing; rerun the step that makes it")
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
    except (OSError, ValueError, RuntimeError) as err:
        problem = f"{what} file '{path}' is unreadable or corrupt ({err})"
        raise OSError(set_aside(path, problem) if remake else problem) from err
    for name, var in ds.data_vars.items() if allow_nan is not None else ():
        if var.dtype.kind == "f" and name not in allow_nan:
            try:
                require_finite(var.values, f"{what} file '{path}'", name, var.dims)
            except ValueError as err:
                raise ValueError(set_aside(path, str(err)) if remake else str(err)) from None
    return ds


class FrameWriter:
    """Writes a (target, frame, y, x) float32 cube frame block by frame block.

    One frame per chunk, uncompressed: zlib (level 1, shuffle) saved only 18 % on
    these noise-like float32 frames and cost 5-6 ms per 256 x 256 frame, more
    than simulating it. Opened as a context manager; the file gets its final
    name only when the block closes without error.
    """

    def __init__(self, path, targets, n_frames: int, n_pixels: int, pixel_scale_arcsec: float, attrs: dict):
        self._atomic = atomic_path(path)
        self._atomic_target = path
        self._targets = list(targets)  # the case's indices of the targets stored
        self._shape = (len(self._targets), n_frames, n_pixels)
        self._pixel_scale = pixel_scale_arcsec
        self._attrs = attrs

    def __enter__(self):
        tmp = self._partial = self._atomic.__enter__()
        n_targets, n_frames, n = self._shape
        self._nc = netCDF4.Dataset(tmp, "w", format="NETCDF4")
        self._nc.setncatts(self._attrs)
        for dim, size in (("target", n_targets), ("frame", n_frames), ("y", n), ("x", n)):
            self._nc.createDimension(dim, size)
        target = self._nc.createVariable("target", "i4", ("target",))
        target[:] = self._targets
        target.units = "1"
        target.long_name = "index of the target in the case's targets_arcsec"
        for axis in ("y", "x"):
            coord = self._nc.createVariable(axis, "f8", (axis,))
            coord[:] = (np.arange(n) - n // 2) * self._pixel_scale
            coord.units = "arcsec"
            coord.long_name = f"{axis} position on the sky relative to the optical axis"
        self.frames = self._nc.createVariable("frames", "f4", ("target", "frame", "y", "x"), chunksizes=(1, 1, n, n))
        self.frames.units = "1"
        self.frames.long_name = "noiseless lucky-camera frame, unit total flux"
        return self

    def write(self, start: int, block: np.ndarray) -> None:
        """Frames ``start:start+k`` for every target from ``block`` (target, k, y, x)."""
        try:
            require_finite(block, f"frames file '{self._atomic_target}'", "frames", ("target", "frame", "y", "x"))
        except ValueError as err:
            raise ValueError(f"{err} (block from frame {start})") from None
        try:
            self.frames[:, start : start + block.shape[1]] = block
        except (OSError, RuntimeError) as err:
            raise write_failure(self._atomic_target, self._partial, err) from err

    def __exit__(self, exc_type, exc, tb):
        try:
            self._nc.close()
        except (OSError, RuntimeError) as err:
            failure = write_failure(self._atomic_target, self._partial, err)
            self._atomic.__exit__(type(failure), failure, None)
            raise failure from err
        return self._atomic.__exit__(exc_type, exc, tb)


def iter_frame_blocks(path, target: int, block: int = 64):
    """Callable returning an iterator of (start, frames (k, y, x) float32) for one target
    (its index in the case's targets)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"frames file '{path}' is missing; rerun the simulate step")

    def iterate():
        try:
            nc = netCDF4.Dataset(path, "r")
        except OSError as err:
            raise OSError(set_aside(path, f"frames file '{path}' is unreadable or corrupt ({err})")) from err
        with nc:
            frames = nc.variables["frames"]
            stored = [int(t) for t in nc.variables["target"][:]]
            if target not in stored:
                raise ValueError(f"frames file '{path}' holds targets {stored}, not target {target}")
            row = stored.index(target)
            for start in range(0, frames.shape[1], block):
                try:
                    frames_block = np.asarray(frames[row, start : start + block], dtype=np.float32)
                except (OSError, RuntimeError, IndexError) as err:
                    raise OSError(
                        set_aside(path, f"frames file '{path}' is unreadable from frame {start} ({err})")
                    ) from err
                try:
                    require_finite(frames_block, f"frames file '{path}'", "frames", ("frame", "y", "x"))
                except ValueError as err:
                    raise ValueError(set_aside(path, f"{err} (block from frame {start}, target {target})")) from None
                yield start, frames_block

    return iterate
