"""The shared turbulence product: one normalised strip screen per layer, along its wind.

Made once per turbulence spec (see ``studyspec.products.turbulence_spec``) and read by
every case that shares it, so those cases see the same turbulence (common
random numbers). Stored in rad at 500 nm for r0 = 1 m, as one flat float32
``.npy`` that cases memory-map (parallel jobs share its pages; paper-fidelity
screens are several GB), described by a small netCDF file with provenance.
"""

import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..atmosphere.screens import ScreenSet, StripSpec, strip_screen, strip_spec
from ..atmosphere.statistics import Layer
from ..io.datasets import atomic_path, open_dataset, require_finite, set_aside, write_dataset
from ..seeds import screen_rng
from ..units import ARCSEC_RAD

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TurbulenceSpec:
    """Everything the shared screens depend on: the seed, their duration and sampling, the
    telescope's reach into the field, the outer scale and each layer's height and wind."""

    seed: int
    duration_s: float
    time_step_s: float
    max_pixel_m: float
    diameter_m: float
    field_radius_arcsec: float
    min_along_m: float
    min_across_m: float
    outer_scale_m: float
    height_m: tuple[float, ...]
    wind_speed_m_s: tuple[float, ...]
    wind_direction_deg: tuple[float, ...]

    @classmethod
    def from_config(cls, spec: dict) -> "TurbulenceSpec":
        """From a ``studyspec.products.turbulence_spec`` dict."""
        return cls(
            spec["seed"],
            spec["duration_s"],
            spec["time_step_s"],
            spec["max_pixel_m"],
            spec["diameter_m"],
            spec["field_radius_arcsec"],
            spec["min_along_m"],
            spec["min_across_m"],
            spec["outer_scale_m"],
            tuple(spec["height_m"]),
            tuple(spec["wind_speed_m_s"]),
            tuple(spec["wind_direction_deg"]),
        )

    @property
    def n_steps(self) -> int:
        """Time steps the screens serve: the duration's, rounded up (robust to its rounding), and one more."""
        return int(np.ceil(self.duration_s / self.time_step_s - 1e-9)) + 1


def strip_specs(spec: TurbulenceSpec) -> list[StripSpec]:
    """Each layer's strip geometry for a turbulence spec."""
    specs = []
    for height, speed, direction in zip(spec.height_m, spec.wind_speed_m_s, spec.wind_direction_deg):
        layer = Layer(height, 1.0, speed, direction)
        # square pupil grids reach sqrt(2) D / 2 in their corners
        radius = 0.75 * spec.diameter_m + spec.field_radius_arcsec * ARCSEC_RAD * height
        specs.append(
            strip_spec(
                layer, spec.time_step_s, spec.n_steps, spec.max_pixel_m, radius, spec.min_along_m, spec.min_across_m
            )
        )
    return specs


def write_screens(spec_config: dict, screens_path, metadata_path, attrs: dict, threads: int = 1) -> None:
    """Generate every layer's strip of a ``studyspec.products.turbulence_spec`` dict into one flat float32
    ``.npy`` (memory-mappable) and describe it in a small netCDF file. Layer ``i`` draws from
    ``screen_rng(seed, i)`` (:mod:`luckyao.seeds`), so the layers are independent: ``threads``
    of them are made at once (largest first; numpy and scipy release the GIL), the same numbers
    for any ``threads``; memory ~12 bytes per sample of the layers in progress. Both
    files appear only when complete."""
    spec = TurbulenceSpec.from_config(spec_config)
    specs = strip_specs(spec)
    sizes = [s.n_major * s.n_minor for s in specs]
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    with atomic_path(screens_path) as tmp:
        flat = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float32, shape=(sum(sizes),))

        def generate(i: int, out: np.ndarray) -> None:
            begin = time.perf_counter()
            s = specs[i]
            screen = strip_screen(s, spec.outer_scale_m, screen_rng(spec.seed, i))
            out[starts[i] : starts[i] + sizes[i]] = screen.ravel()
            log.info(
                "layer %d/%d: %d x %d samples of %.4f m in %.1f s",
                i + 1,
                len(specs),
                s.n_major,
                s.n_minor,
                s.dx_m,
                time.perf_counter() - begin,
            )

        with ThreadPoolExecutor(max(1, threads)) as pool:
            list(pool.map(generate, sorted(range(len(specs)), key=lambda i: -sizes[i]), [flat] * len(specs)))
        flat.flush()
        del flat
    layer = xr.Variable(("layer",), np.arange(len(specs)), {"units": "1", "long_name": "layer index"})
    ds = xr.Dataset(
        {
            "dx_m": ("layer", [s.dx_m for s in specs], {"units": "m", "long_name": "screen sample spacing"}),
            "n_major": ("layer", [s.n_major for s in specs], {"units": "1", "long_name": "lines along the major axis"}),
            "n_minor": ("layer", [s.n_minor for s in specs], {"units": "1", "long_name": "samples per line"}),
            "major_axis": (
                "layer",
                [s.major_axis for s in specs],
                {"units": "1", "long_name": "sky axis of the strip's lines (0: x, 1: y)"},
            ),
            "skew": (
                "layer",
                [s.skew for s in specs],
                {"units": "1", "long_name": "minor offset of line i is floor(skew i / n_major) samples"},
            ),
            "origin_major_m": (
                "layer",
                [s.origin_m[0] for s in specs],
                {"units": "m", "long_name": "major-axis position of sample [0, 0] at t = 0"},
            ),
            "origin_minor_m": (
                "layer",
                [s.origin_m[1] for s in specs],
                {"units": "m", "long_name": "minor-axis position of sample [0, 0] at t = 0"},
            ),
            "step_major": (
                "layer",
                [s.step_samples[0] for s in specs],
                {"units": "1", "long_name": "frozen-flow shift per time step along the major axis, samples"},
            ),
            "step_minor": (
                "layer",
                [s.step_samples[1] for s in specs],
                {"units": "1", "long_name": "frozen-flow shift per time step along the minor axis, samples"},
            ),
            "start": ("layer", starts, {"units": "1", "long_name": "offset of the layer in the flat screen file"}),
        },
        coords={"layer": layer},
        attrs={**attrs, "screens_file": str(screens_path), "phase_units": "rad at 500 nm for r0 = 1 m"},
    )
    write_dataset(ds, metadata_path)


def read_screens(screens_path, metadata_path) -> ScreenSet:
    """The screens, memory-mapped read-only, with their geometry."""
    meta = open_dataset(metadata_path, "turbulence metadata", allow_nan=())
    specs = tuple(
        StripSpec(
            dx_m=float(meta.dx_m[i]),
            n_major=int(meta.n_major[i]),
            n_minor=int(meta.n_minor[i]),
            major_axis=int(meta.major_axis[i]),
            skew=int(meta.skew[i]),
            origin_m=(float(meta.origin_major_m[i]), float(meta.origin_minor_m[i])),
            step_samples=(float(meta.step_major[i]), float(meta.step_minor[i])),
        )
        for i in range(meta.sizes["layer"])
    )
    try:
        flat = np.load(screens_path, mmap_mode="r")
    except FileNotFoundError as err:
        raise OSError(f"turbulence file '{screens_path}' is missing ({err}); rerun its rule") from err
    except (OSError, ValueError) as err:
        raise OSError(set_aside(screens_path, f"turbulence file '{screens_path}' is corrupt ({err})")) from err
    expected = int(meta.start[-1]) + specs[-1].n_major * specs[-1].n_minor
    if flat.dtype != np.float32 or flat.shape != (expected,):
        raise OSError(
            set_aside(
                screens_path,
                f"turbulence file '{screens_path}' holds {flat.shape} {flat.dtype}, "
                f"its metadata expects ({expected},) float32",
            )
        )
    for begin in range(0, flat.size, 1 << 24):  # memory-mapped: check in 64 MB chunks
        try:
            require_finite(flat[begin : begin + (1 << 24)], f"turbulence file '{screens_path}'", "screens")
        except ValueError as err:
            raise ValueError(set_aside(screens_path, f"{err} (offset from {begin})")) from None
    return ScreenSet(specs, flat, meta.start.values.astype(np.int64))
