"""What each job of a study needs, from its config alone: memory and disk, before any job.

Estimates (bytes) of the large arrays each step holds or writes, calibrated on the
paper-fidelity run (README, Paper fidelity):

* turbulence: the screens file, 4 bytes per sample of every layer (``.npy``,
  float32); while made, ~12 bytes per sample of the layers in progress (the rule's
  2 threads: the two largest) plus the interpreter and libraries (``BASE_BYTES``):
  11.8 GB at paper fidelity;
* reconstructor / commands: the slope covariance and its Cholesky factor
  (2 x 8 n_slopes^2), the cross covariances and results (24 bytes per point and
  slope; the command matrix's points a quarter of the DM pitch apart) and the file,
  with n_slopes = 2 x beacons x the sub-apertures in the pupil's disk;
* WFS calibration: 1.5 GB, or a draw's screen (56 bytes per sample) and the sub-apertures'
  spectra where more (:func:`calibration_memory_bytes`: 6.4 GB for the 39 m case's 12" field);
* slopes: ``SIMULATE_BYTES`` (the sensor's screens memory-mapped) plus the slopes it
  holds and writes, 4 bytes per slope of every WFS exposure;
* simulate: ``SIMULATE_BYTES`` measured (the screens are memory-mapped) plus the
  matrices and slopes it loads (with the iterative tomography, its layer grids, preconditioner
  and sparse projections instead: :func:`iterative_tomography_bytes`) and a block of frames; the
  frame cube it writes, 4 bytes per pixel of every imaged target's frames;
* lucky: 1.5 GB and its partial sums, from their layout (the sweep's 19 detectors at paper
  fidelity, ``cog`` alone: 4.7 GB measured, 4.74 estimated); a sub-pixel registration method's
  ~1/8 of a whole frame's more; replaying the frames, their block and the DM commands (the
  screens memory-mapped, as in every job: file cache, not counted).

Each rule declares ``mem_mb`` from the same estimate (``mem_mb``: x ``MARGIN``, at
least the rule's measured paper-fidelity need; lucky's estimate is its measured
need, declared as is), and ``preflight`` refuses a study
whose job would need more than this machine's memory, or whose files not yet made would
together exceed the free disk of the study folder, naming the case, the job and the numbers.
``checked_study`` is the one pre-flight, validation then this, that ``luckyao check`` and the
workflow (its dry run and every run) share.
"""

import math
import os
import shutil
from pathlib import Path
from typing import NamedTuple

from ..clock import FrameClock, frame_count
from ..steps.screens import TurbulenceSpec, strip_specs
from ..studyspec.lucky import registrations
from ..studyspec.products import commands_spec, geometric_wfs, iterative, reconstructor_spec
from ..studyspec.resolved import criteria_of, imaged_targets
from ..studyspec.schema import ConfigError, case_defaults
from ..studyspec.study import validate_study
from ..studyspec.sweeps import expand_study
from ..studyspec.view import ResolvedStudy, resolve_study
from ..units import ARCSEC_RAD
from ..wfs.sampling import calibration_screen_size, samples_per_subaperture

BASE_BYTES = 0.4e9
"""Python with numpy, scipy, numba and pyFFTW loaded."""
SIMULATE_BYTES = 2.5e9
"""A simulation's own memory at paper fidelity, measured (2-3 GB), screens memory-mapped."""
MARGIN = 1.3
"""Declared memory over the estimate."""
TURBULENCE_THREADS = 2
"""Layers a screens job makes at once when it is its study's only one and two fit the machine's
memory (the turbulence rule's ``threads``: else one)."""
FRAME_BLOCK = 64
"""Frames a simulation or post-processing holds at once."""


def screens_samples(spec: dict) -> list[int]:
    """Samples of each layer's strip of a ``studyspec.products.turbulence_spec``."""
    return [s.n_major * s.n_minor for s in strip_specs(TurbulenceSpec.from_config(spec))]


def screens_bytes(spec: dict) -> float:
    """The screens file (float32 samples)."""
    return 4.0 * sum(screens_samples(spec))


def turbulence_memory_bytes(spec: dict, threads: int = TURBULENCE_THREADS) -> float:
    """The turbulence job: 12 bytes per sample of the layers made at once (``threads``: the largest)."""
    largest = sorted(screens_samples(spec), reverse=True)[:threads]
    return BASE_BYTES + 12.0 * sum(largest)


def _slopes_and_points(spec: dict) -> tuple[float, float]:
    """Slopes of every LGS WFS and pupil points of a reconstructor or command-matrix spec:
    the sub-apertures and points of the pupil's disk (pi/4 of the square, obscuration
    ignored)."""
    n_sub = spec["wfs"]["n_subapertures"]
    n_slopes = 2 * spec["lgs"]["n_beacons"] * math.pi / 4 * n_sub**2
    n_points = math.pi / 4 * (n_sub * spec["tomography"]["points_per_subaperture"] + 2) ** 2
    return n_slopes, n_points


def reconstructor_bytes(spec: dict) -> float:
    """The reconstructor file: one float32 matrix (points, slopes) per target."""
    n_slopes, n_points = _slopes_and_points(spec)
    return 4.0 * len(spec["targets_arcsec"]) * n_points * n_slopes


def reconstructor_memory_bytes(spec: dict) -> float:
    n_slopes, n_points = _slopes_and_points(spec)
    return BASE_BYTES + 16.0 * n_slopes**2 + 24.0 * n_points * n_slopes + reconstructor_bytes(spec)


def commands_bytes(spec: dict) -> float:
    """The command-matrix file: the command matrix and the DM slopes (float64)."""
    n_slopes, _ = _slopes_and_points(spec)
    return 16.0 * spec["ao"]["n_actuators"] ** 2 * n_slopes


def commands_memory_bytes(spec: dict) -> float:
    """Its points are a quarter of the DM pitch apart (``ao.control.command_matrix``)."""
    n_slopes, _ = _slopes_and_points(spec)
    n_points = math.pi / 4 * (4 * (spec["ao"]["n_actuators"] - 1) + 2) ** 2
    return BASE_BYTES + 16.0 * n_slopes**2 + 24.0 * n_points * n_slopes + commands_bytes(spec)


def slopes_bytes(case: dict) -> float:
    """An AO case's LGS slopes product (float32, every WFS exposure's slopes)."""
    n_slopes, _ = _slopes_and_points(case)
    return 4.0 * n_slopes * FrameClock.from_config(case).n_exposures


def sensor_bytes(case: dict) -> float:
    """The LGS sensor's own arrays: its exposure's downlink phases (float32, every beacon's pupil grid
    and step) and, while its elongation OTF is built, four complex128 arrays of every valid
    sub-aperture's OTF samples (``M (M/2 + 1)``: 1.4 GB at 39 m with the 12" field); the geometric
    sensor's, its downlink phases on the nodes and their float64 mean (a few MB at 39 m)."""
    if geometric_wfs(case):
        nodes = (2 * case["wfs"]["n_subapertures"] + 1) ** 2
        return (4.0 * case["wfs"]["exposure_steps"] + 8.0 * 4) * case["lgs"]["n_beacons"] * nodes
    n = wfs_pupil_samples(case)
    m = 2 * n // case["wfs"]["n_subapertures"]
    downlink = 4.0 * case["wfs"]["exposure_steps"] * case["lgs"]["n_beacons"] * n * n
    return downlink + 4 * 16.0 * valid_subapertures(case) * m * (m // 2 + 1)


def slopes_memory_bytes(case: dict) -> float:
    """An LGS slopes product: the simulation's measured own memory, its sensor's arrays
    (:func:`sensor_bytes`) and the slopes it writes."""
    return SIMULATE_BYTES + sensor_bytes(case) + slopes_bytes(case)


def frames_bytes(case: dict) -> float:
    """A case's frame cube (float32, its imaged targets)."""
    return 4.0 * len(imaged_targets(case)) * frame_count(case) * case["camera"]["n_pixels"] ** 2


def telemetry_bytes(case: dict) -> float:
    """A case's telemetry file: with AO every WFS exposure's DM commands (float32), and a few
    float32 values per target and frame."""
    commands = 0.0
    if case["ao"]["mode"] != "none":
        commands = 4.0 * case["ao"]["n_actuators"] ** 2 * FrameClock.from_config(case).n_exposures
    return commands + 4.0 * 8 * len(case["targets_arcsec"]) * frame_count(case)


def layer_grid_samples(case: dict) -> tuple[int, int]:
    """The iterative tomography's layers and samples across each layer's grid
    (:meth:`luckyao.layer_tomography.grids.LayerGrids.covering`, as the simulation builds them)."""
    from ..layer_tomography.grids import LayerGrids  # imported only for an iterative case
    from ..studyspec.case import lgs_from

    lgs, n_sub = lgs_from(case["lgs"]), case["wfs"]["n_subapertures"]
    subaperture_m = case["telescope"]["diameter_m"] / n_sub
    directions = [*case["targets_arcsec"], case["ao"]["correction_direction_arcsec"]]
    grids = LayerGrids.covering(
        case["tomography"]["layer_heights_m"],
        lgs.height_m,
        subaperture_m / 2,
        n_sub * subaperture_m / 2,
        lgs.directions_rad,
        [(x * ARCSEC_RAD, y * ARCSEC_RAD) for x, y in directions],
    )
    return grids.n_layers, grids.n


ITERATIVE_VECTORS = 16
"""Layer-sized float32 arrays the iterative tomography holds at once (PCG's six, the warm start,
the frame's estimates, the FFTs' work arrays)."""


def iterative_tomography_bytes(case: dict) -> float:
    """The iterative tomography: :data:`ITERATIVE_VECTORS` float32 layer arrays, the FDPCG's
    per-frequency inverse (complex128, built beside its system) and the sparse lines of sight
    (four samples per layer and point, 12 bytes each) of every target and the DM fit's points
    (a quarter of its pitch apart, with its influence functions)."""
    n_layers, n = layer_grid_samples(case)
    layer_bytes = ITERATIVE_VECTORS * 4.0 * n_layers * n * n
    preconditioner = 2 * 16.0 * n * (n // 2 + 1) * n_layers**2
    n_sub = case["wfs"]["n_subapertures"]
    points = math.pi / 4 * (n_sub * case["tomography"]["points_per_subaperture"] + 2) ** 2
    fit_points = math.pi / 4 * (4 * (case["ao"]["n_actuators"] - 1) + 2) ** 2
    traces = 48.0 * n_layers * (points * len(case["targets_arcsec"]) + fit_points) + 12.0 * 25 * fit_points
    return layer_bytes + preconditioner + traces


def runs_layer_tomography(case: dict, lgs_twin: str | None = None) -> bool:
    """Whether a case's simulation builds and runs the iterative tomography: with LGS and
    ``tomography.method: iterative``, unless a no-AO case's ``lgs_rms`` comes from its
    ``lgs_twin`` (``studyspec.products.lgs_twin``)."""
    return case["lgs"]["enabled"] and iterative(case) and lgs_twin is None


def simulate_memory_bytes(case: dict, lgs_twin: str | None = None) -> float:
    """A simulation: its measured own memory, the matrices and slopes it loads (or the iterative
    tomography it builds: :func:`runs_layer_tomography`), a block of frames."""
    matrices = 0.0
    if (spec := reconstructor_spec(case)) is not None:
        matrices += reconstructor_bytes(spec)
    if (spec := commands_spec(case)) is not None:
        matrices += commands_bytes(spec) + slopes_bytes(case)
    if runs_layer_tomography(case, lgs_twin):
        matrices += iterative_tomography_bytes(case) + (slopes_bytes(case) if case["ao"]["mode"] != "none" else 0.0)
    block = 3 * 4.0 * len(case["targets_arcsec"]) * FRAME_BLOCK * case["camera"]["n_pixels"] ** 2
    return SIMULATE_BYTES + matrices + block


SUBPIXEL_SUMS_FRACTION = (64**2 + 4357 + 1) / 256**2
"""A sub-pixel method's partial sums over a whole frame's (:mod:`luckyao.lucky.cropped`: a 1.25"
crop, the encircled energy's 4,357 radial sums and the flux per frame, for the 4.2 m camera's
5"; at 8.2 m the radial sums are a smaller part). Written out, so that parsing the workflow loads
no FFT code; tests/test_registration.py checks it against the layout."""


LUCKY_BASE_BYTES = 1.5e9
"""A lucky job's memory besides its partial sums: the interpreter, the per-frame values and
bins, a chunk of frames and their spectra (4.7 GB measured at paper fidelity with the sweep's 19
detectors and ``cog``, of which the sums are 3.2 GB)."""


def partial_sums_bytes(settings: dict) -> float:
    """The partial sums a lucky job holds (:class:`.lucky.accumulation.PartialSums`, float64 rows of
    an item + 8 values, per detector and registration method, all held at once: the methods share
    the passes over the frames): the run's (criterion, fraction) rows, twice (detected and the
    noiseless twin's), the long exposure, and the time blocks' rows: a set of rows per criterion
    for the blocks a chunk of :data:`FRAME_BLOCK` frames spans, or, with a noisy detector, the
    image criteria (Strehl, d50: their guessed bins corrected until the last chunk) a set for
    every block. An item is a whole frame for ``cog``, :data:`SUBPIXEL_SUMS_FRACTION` of it for a
    sub-pixel method's vector."""
    from ..lucky.ranking import fraction_counts  # numpy only

    case, fractions = settings["case_config"], settings["fractions"]
    n_frames, n_blocks = frame_count(case), settings.get("error_blocks", 0)
    n_crit, n_bins = len(criteria_of(case)), len(set(fraction_counts(n_frames, fractions).tolist()))
    noisy = any(d["photons_per_frame"] is not None for d in settings["detectors"].values())
    n_resident = 2 if noisy else 0
    block_rows = 0
    if n_blocks:
        block_frames = n_frames // n_blocks
        n_sets = min(n_blocks, -(-FRAME_BLOCK // block_frames) + 1)
        block_bins = len(set(fraction_counts(max(block_frames, 1), fractions).tolist()))
        block_rows = (n_sets * (n_crit - n_resident) + n_blocks * n_resident) * block_bins
    rows = 2 * n_crit * n_bins + 1 + block_rows
    pixels = case["camera"]["n_pixels"] ** 2
    items = sum(pixels if name == "cog" else SUBPIXEL_SUMS_FRACTION * pixels for name in registrations(settings))
    return 8.0 * len(settings["detectors"]) * rows * (items + 8 * len(registrations(settings)))


def replay_memory_bytes(case: dict) -> float:
    """A lucky job's replay of the frames (``replay_frames``) besides its memory-mapped screens:
    the simulation's block of frames (float32, three arrays of every target's) and the recorded
    DM commands (float32, every WFS exposure's)."""
    block = 3 * 4.0 * len(case["targets_arcsec"]) * FRAME_BLOCK * case["camera"]["n_pixels"] ** 2
    commands = 0.0
    if case["ao"]["mode"] != "none":
        commands = 4.0 * case["ao"]["n_actuators"] ** 2 * FrameClock.from_config(case).n_exposures
    return block + commands


def lucky_memory_bytes(settings: dict) -> float:
    """A case's post-processing (``studyspec.lucky.lucky_settings``): :data:`LUCKY_BASE_BYTES`, its
    partial sums (:func:`partial_sums_bytes`), replaying the frames (``replay_frames``) their block
    and the DM commands (:func:`replay_memory_bytes`: the screens are memory-mapped, pages of the
    file cache the kernel may drop and read again), Fourier lucky imaging's amplitudes
    (:func:`fourier_memory_bytes`). The 16 m detector sweep: 10.2 GB, 9.93 GB of its own measured at
    its peak (15.0 GB by the scaled estimate this replaced); the 8.2 m one 3.8 GB, 3.0 measured."""
    case = settings["case_config"]
    replay = replay_memory_bytes(case) if settings.get("replay_frames", False) else 0.0
    return LUCKY_BASE_BYTES + partial_sums_bytes(settings) + replay + fourier_memory_bytes(settings)


def fourier_memory_bytes(settings: dict) -> float:
    """Fourier lucky imaging's amplitudes (``fourier_fractions``, :mod:`luckyao.lucky.fourier`): per
    detector and registration method, for the whole run and each of its ``error_blocks`` time blocks
    (:class:`.lucky.fourier.FourierRun`), 1.25 x the largest count kept below all its frames (at least
    a chunk of 64), float32, at each frequency of the crop's half plane (``image_crop_px``, 64: 2,112);
    0 without it. Measured at paper fidelity (19 detectors, 4 methods, 10 blocks, 10 % kept): 3.7 GB
    more than without it, against 4.0 GB estimated."""
    fractions = settings.get("fourier_fractions")
    if not fractions:
        return 0.0
    n_frames, n_blocks = frame_count(settings["case_config"]), settings.get("error_blocks", 0)

    def kept(n: int) -> int:
        return max(max([round(f * n) for f in fractions if round(f * n) < n] or [0]), 64)

    runs = kept(n_frames) + (n_blocks * kept(n_frames // n_blocks) if n_blocks else 0)
    n_pixels = settings["case_config"]["camera"]["n_pixels"]
    crop = min(settings.get("image_crop_px", 64) or n_pixels, n_pixels)
    return 1.25 * runs * crop * (crop // 2 + 1) * 4.0 * len(settings["detectors"]) * len(registrations(settings))


# Time estimates [s] of one job's work on one core of the measuring machine (docs/performance.md;
# Python's start-up, 2-5 s a job, left out). The rules declare wall times from them.

STEP_MS_8M, STEP_EXPONENT = 5.4, 2.8
"""One core's whole-loop ms per 2.5 ms step of LTAO at 8.2 m, and its power of the diameter
(1.24 ms at 4.2 m, 5.36 at 8.2, 35-75 at 16 m measured: docs/performance.md)."""
IMAGING_SHARE = 0.45
"""The science path's share of a step (propagation, DM surface, image; 8.2 m): what a replay redoes."""
BUDGET_SHARE = 1.0
"""The residual budget's share of a step (``ao.residual_budget``: a noiseless twin of the LGS chain,
the DM fits of the science and beacon phases and the parts' surfaces): +2.1 ms on the default AO
case's 2.09 at 4.2 m, measured on a loaded machine (docs/performance.md)."""
ITERATIVE_NS_PER_SAMPLE, ITERATIVE_ITERATIONS = 25.0, 30
"""The iterative tomography's time per PCG iteration and layer sample, and its iterations per
exposure (warm-started to 10^-3): with the compiled kernels 14-23 ns per sample (1.1-1.3 ms per
iteration on 9 layers of 96² at 4.2 m, 6.5-7.6 ms on 9 x 192² at 39 m, a loaded machine) and
16-24 warm iterations (the first, cold solve ~70-140): docs/performance.md."""
SCREENS_NS_PER_SAMPLE = 141.0
"""One core's time per screen sample (the paper's 2.3e9 samples: 5.4 minutes of CPU)."""
RECONSTRUCTOR_S_16, RECONSTRUCTOR_EXPONENT = 1.7, 1.33
"""A reconstructor's build [s] for one target with 16x16 sub-apertures (8.2 m), and its power of
the sub-apertures across (0.4 s at 4.2 m and 2.5 m measured; the pitch fixed)."""
COMMANDS_S_17, COMMANDS_EXPONENT = 3.9, 2.94
"""A command matrix's build [s] with 17x17 actuators (8.2 m), and its power of the actuators
across (0.4 s with 9x9, 0.1 with 6x6 measured)."""
CALIBRATION_S = 13.0
"""A WFS calibration [s]: the default study's six took 77 s, mostly numba compiling the WFS
kernels of each size the first time (cached later)."""
LGS_PROPAGATION_NS = 10.6
"""The LGS propagation's time per beacon, pupil sample of its valid sub-apertures and step: the
default AO case's 0.52 ms per step for 4 beacons x 48 sub-apertures x 16^2 samples (8.1 ms
measured, 8.3 from this, for 6 x 48 x 52^2: the 12" WFS field at 4.2 m)."""
WFS_SUBAPERTURE_NS, WFS_SAMPLES_EXPONENT, MEASURED_WFS_SAMPLES = 1406.0, 4.6, 16
"""The WFS's time per beacon, valid sub-aperture and step with :data:`MEASURED_WFS_SAMPLES` pupil
samples across a sub-aperture (the default AO case's 0.27 ms per step for 4 x 48), and its power of
those samples: 0.19, 3.0, 13.0 and 79 ms per step measured at 4.2 m for 6 sodium beacons x 48
sub-apertures with 14, 26, 34 and 52 samples (WFS fields of 3.36, 6, 8 and 12"; a loaded machine)."""
GEOMETRIC_NODES = 4.1
"""The geometric sensor's pupil samples per valid sub-aperture: the nodes at half its pitch
(corners, edge mid-points, centre; 16,264 for the 39 m case's 3,972 sub-apertures)."""
GEOMETRIC_NODE_NS = 101.0
"""The geometric sensor's propagation: time per beacon, node and step through the layers (9.84 ms
per step for 6 x 16,264 nodes measured at 39 m, bench_step --system elt; scattered nodes, not the
physical sensor's rows of :data:`LGS_PROPAGATION_NS`)."""
GEOMETRIC_WFS_NS = 29.0
"""The geometric sensor's time per beacon, valid sub-aperture and step besides the propagation:
the exposure's mean phase, the mean gradients, the NEA noise and the tilt removal (0.69 ms per
step for 6 x 3,972 sub-apertures measured at 39 m, bench_step --system elt). With the
propagation: 10.6 ms per step estimated, the 39 m slopes job's 9.2 measured."""
CALIBRATION_SCREEN_NS = 70.0
"""A calibration draw's time per screen sample (normal deviates, product, complex FFT): 0.29 s per
2048^2 draw measured (4.2 m, the 12" WFS field; a loaded machine)."""
ELONGATION_OTF_NS = 14000.0
"""The sensor's set-up, its LGS elongation OTF: time per valid sub-aperture and OTF sample
(``M (M/2 + 1)``, ``M`` twice the sub-aperture's pupil samples), with the sodium profile: 3.7 s
measured for 48 sub-apertures with ``M`` = 104 (4.2 m, the 12" WFS field)."""
LUCKY_FRAME_MS = 0.9
"""A lucky job's ms per frame and target with the noiseless detector and ``cog`` alone, 256
pixels (22.8 s for 25,000 frames and 10 blocks)."""
NOISY_FRAME_MS = 1.24
"""More per frame and noisy detector, ``cog`` (the detector-sweep case: 579 s for 18 noisy
detectors and 25,000 frames)."""
SUBPIXEL_FRAME_MS = 0.42
"""More per frame, detector and sub-pixel registration method (the sweep case's three: 10.05
minutes of its 19.7 for 19 detectors)."""
FOURIER_FRAME_MS, FOURIER_REDRAW_MS = 0.25, 0.4
"""More per frame with Fourier lucky imaging: per detector and registration method (both passes'
crop transforms and selection: 0.03-0.30 ms measured with ``cog`` and the noiseless detector), and
per noisy detector (its noise drawn again in pass 2: 1.4 ms for the noiseless and 2 noisy
detectors with ``cog``; docs/performance.md)."""
RUNTIME_MARGIN = 3.0
"""Wall time declared over the estimate: a loaded node, a slower core."""


def step_ms(case: dict) -> float:
    """One core's whole-loop ms per time step at the case's diameter: :data:`STEP_MS_8M` (D / 8.2 m)^b."""
    return STEP_MS_8M * (case["telescope"]["diameter_m"] / 8.2) ** STEP_EXPONENT


def screens_seconds(spec: dict, threads: int = TURBULENCE_THREADS) -> float:
    """Making the screens: :data:`SCREENS_NS_PER_SAMPLE` per sample, on ``threads`` (a layer each)."""
    return SCREENS_NS_PER_SAMPLE * 1e-9 * sum(screens_samples(spec)) / threads


def screens_job_threads(spec: dict, n_screens_jobs: int) -> int:
    """A screens job's threads: two layers at once (:data:`TURBULENCE_THREADS`) when it is the
    study's only screens job and two layers fit this machine's memory; else one, so that several
    run side by side and none waits for both cores while one-core jobs hold one (the same screens
    for any number)."""
    fits = mem_mb(turbulence_memory_bytes(spec, TURBULENCE_THREADS)) * 1e6 <= machine_memory_bytes()
    return TURBULENCE_THREADS if n_screens_jobs == 1 and fits else 1


def screens_minutes(spec: dict, threads: int) -> int:
    """A screens job's wall time to declare [min]: at least 15, else :data:`RUNTIME_MARGIN` x
    :func:`screens_seconds` (39 m at 100 s: 40 GB of screens, ~12 minutes of one core)."""
    return max(15, math.ceil(RUNTIME_MARGIN * screens_seconds(spec, threads) / 60))


def reconstructor_seconds(spec: dict) -> float:
    """A reconstructor's build: :data:`RECONSTRUCTOR_S_16` per target, (sub-apertures / 16)^b."""
    n_sub = spec["wfs"]["n_subapertures"]
    return RECONSTRUCTOR_S_16 * len(spec["targets_arcsec"]) * (n_sub / 16) ** RECONSTRUCTOR_EXPONENT


def commands_seconds(spec: dict) -> float:
    """A command matrix's build: :data:`COMMANDS_S_17` (actuators / 17)^b."""
    return COMMANDS_S_17 * (spec["ao"]["n_actuators"] / 17) ** COMMANDS_EXPONENT


def valid_subapertures(case: dict) -> float:
    """About the LGS WFS's valid sub-apertures: those of the annulus' area."""
    telescope, n_sub = case["telescope"], case["wfs"]["n_subapertures"]
    return math.pi / 4 * n_sub**2 * (1 - (telescope["obscuration_m"] / telescope["diameter_m"]) ** 2)


def wfs_step_ns(case: dict) -> float:
    """The WFS's time per beacon and valid sub-aperture [ns] of a step (or of a one-step exposure):
    :data:`WFS_SUBAPERTURE_NS` at its pupil samples across a sub-aperture, their power
    :data:`WFS_SAMPLES_EXPONENT`."""
    n_s = wfs_pupil_samples(case) / case["wfs"]["n_subapertures"]
    return WFS_SUBAPERTURE_NS * (n_s / MEASURED_WFS_SAMPLES) ** WFS_SAMPLES_EXPONENT


def lgs_chain_ms(case: dict) -> float:
    """One core's ms per step of the LGS chain: every beacon's propagation to its valid
    sub-apertures' pupil samples (:data:`LGS_PROPAGATION_NS`) and its WFS (:func:`wfs_step_ns`);
    geometric (``wfs.model``), :data:`GEOMETRIC_NODES` nodes per sub-aperture at
    :data:`GEOMETRIC_NODE_NS` and :data:`GEOMETRIC_WFS_NS`."""
    if geometric_wfs(case):
        per_subaperture_ns = GEOMETRIC_NODE_NS * GEOMETRIC_NODES + GEOMETRIC_WFS_NS
        return case["lgs"]["n_beacons"] * valid_subapertures(case) * per_subaperture_ns / 1e6
    n_s = wfs_pupil_samples(case) / case["wfs"]["n_subapertures"]
    per_subaperture_ns = LGS_PROPAGATION_NS * n_s**2 + wfs_step_ns(case)
    return case["lgs"]["n_beacons"] * valid_subapertures(case) * per_subaperture_ns / 1e6


def elongation_otf_seconds(spec: dict) -> float:
    """The sensor's set-up: its LGS elongation OTF (:data:`ELONGATION_OTF_NS`), of a case or
    calibration spec."""
    m = 2 * wfs_pupil_samples(spec) // spec["wfs"]["n_subapertures"]
    return valid_subapertures(spec) * m * (m // 2 + 1) * ELONGATION_OTF_NS * 1e-9


def slopes_seconds(case: dict) -> float:
    """An LGS slopes product: the sensor's set-up (:func:`elongation_otf_seconds`) and the LGS chain
    (:func:`lgs_chain_ms`) at every step (the geometric sensor has no elongation OTF)."""
    setup = 0.0 if geometric_wfs(case) else elongation_otf_seconds(case)
    return setup + FrameClock.from_config(case).n_steps * lgs_chain_ms(case) / 1e3


def slopes_minutes(case: dict) -> int:
    """An LGS slopes product's wall time to declare [min]: at least the 60 of paper fidelity
    (about half an LTAO simulation), else :data:`RUNTIME_MARGIN` x :func:`slopes_seconds`."""
    return max(60, math.ceil(RUNTIME_MARGIN * slopes_seconds(case) / 60))


def wfs_pupil_samples(spec: dict) -> int:
    """Samples across the LGS WFS's pupil grid of a case or calibration spec (sub-apertures x
    ``wfs.sampling.samples_per_subaperture``)."""
    n_sub, wfs = spec["wfs"]["n_subapertures"], spec["wfs"]
    subaperture_m = spec["telescope"]["diameter_m"] / n_sub
    pixel_scale_rad = wfs["pixel_scale_arcsec"] * ARCSEC_RAD
    return n_sub * samples_per_subaperture(subaperture_m, wfs["n_pixels"], pixel_scale_rad, spec["lgs"]["wavelength_m"])


def calibration_memory_bytes(spec: dict) -> float:
    """A WFS calibration: :data:`CALIBRATION_BYTES` (what small sensors declare), or more: the
    libraries, a draw's screen (its amplitudes, normal deviates, spectrum and transform: 56 bytes
    per sample) and an exposure's sub-aperture spectra (complex64, 3 arrays, up to 4 beacons)."""
    n, n_sub = wfs_pupil_samples(spec), spec["wfs"]["n_subapertures"]
    screen = calibration_screen_size(n) ** 2
    m = 2 * n // n_sub  # FFT samples per sub-aperture (the sensor's fft_size, the launch aside)
    spectra = 3 * 8.0 * min(spec["lgs"]["n_beacons"], 4) * math.pi / 4 * n_sub**2 * m * (m // 2 + 1)
    return max(CALIBRATION_BYTES, BASE_BYTES + 56.0 * screen + spectra)


def calibration_seconds(spec: dict) -> float:
    """A WFS calibration: :data:`CALIBRATION_S` (compiling, small sensors), the sensor's set-up
    (:func:`elongation_otf_seconds`) and each draw's screen (:data:`CALIBRATION_SCREEN_NS` per
    sample) and its 4 one-step exposures of up to 4 beacons (:func:`wfs_step_ns` per sub-aperture)."""
    screen = calibration_screen_size(wfs_pupil_samples(spec)) ** 2
    sensor = 4 * min(spec["lgs"]["n_beacons"], 4) * valid_subapertures(spec) * wfs_step_ns(spec)
    draws = spec["wfs"].get("calibration_draws", case_defaults("wfs")["calibration_draws"])
    return CALIBRATION_S + elongation_otf_seconds(spec) + draws * (CALIBRATION_SCREEN_NS * screen + sensor) * 1e-9


def calibration_minutes(spec: dict) -> int:
    """A WFS calibration's wall time to declare [min]: at least 5, else :data:`RUNTIME_MARGIN` x
    :func:`calibration_seconds`."""
    return max(5, math.ceil(RUNTIME_MARGIN * calibration_seconds(spec) / 60))


def iterative_seconds(case: dict, lgs_twin: str | None = None) -> float:
    """The iterative tomography's solves (0 unless :func:`runs_layer_tomography`): every WFS
    exposure's :data:`ITERATIVE_ITERATIONS` iterations at :data:`ITERATIVE_NS_PER_SAMPLE` per layer
    sample."""
    if not runs_layer_tomography(case, lgs_twin):
        return 0.0
    n_layers, n = layer_grid_samples(case)
    exposure_s = ITERATIVE_ITERATIONS * ITERATIVE_NS_PER_SAMPLE * 1e-9 * n_layers * n * n
    return FrameClock.from_config(case).n_exposures * exposure_s


def simulate_seconds(case: dict, lgs_twin: str | None = None) -> float:
    """A simulation: its steps at :func:`step_ms` (the whole loop: an AO case replaying its LGS
    chain's slopes takes less), :data:`BUDGET_SHARE` more with the residual budget, and the
    iterative tomography's solves (:func:`iterative_seconds`)."""
    budget = BUDGET_SHARE if case.get("ao", {}).get("residual_budget", False) else 0.0
    steps_s = FrameClock.from_config(case).n_steps * (1 + budget) * step_ms(case) / 1e3
    return steps_s + iterative_seconds(case, lgs_twin)


def simulate_minutes(case: dict, lgs_twin: str | None = None) -> int:
    """A simulation's wall time to declare [min]: at least the 60 measured at paper fidelity
    on 4.2 m, else :data:`RUNTIME_MARGIN` x :func:`simulate_seconds`."""
    return max(60, math.ceil(RUNTIME_MARGIN * simulate_seconds(case, lgs_twin) / 60))


def lucky_seconds(settings: dict) -> float:
    """A lucky job: every target's frames through its detectors and registration methods
    (:data:`LUCKY_FRAME_MS`, :data:`NOISY_FRAME_MS`, :data:`SUBPIXEL_FRAME_MS`,
    :data:`FOURIER_FRAME_MS`, :data:`FOURIER_REDRAW_MS`, as the camera's pixels), and each target the
    simulation did not image (all with ``replay_frames``) made again: its science path
    (:data:`IMAGING_SHARE` of a step) once per pass over the frames, 3 with noisy detectors, else 2.
    A case's ``stars`` count as that many more targets, made again: a pass over each star's frames,
    one over the science target's, and its run per count above one (``steps.stars``; an
    over-estimate)."""
    case, detectors = settings["case_config"], settings["detectors"]
    noisy = sum(d["photons_per_frame"] is not None for d in detectors.values())
    subpixel = sum(name != "cog" for name in registrations(settings))
    frame_ms = LUCKY_FRAME_MS + NOISY_FRAME_MS * noisy + SUBPIXEL_FRAME_MS * subpixel * len(detectors)
    if settings.get("fourier_fractions"):
        frame_ms += FOURIER_FRAME_MS * len(detectors) * len(registrations(settings)) + FOURIER_REDRAW_MS * noisy
    stars = case.get("stars")
    extra = 0 if stars is None else len(stars["targets"]) + 1 + sum(n > 1 for n in stars["counts"])
    targets = len(case["targets_arcsec"]) + extra
    frames_s = frame_count(case) * targets * (case["camera"]["n_pixels"] / 256) ** 2 * frame_ms / 1e3
    replayed = targets if settings.get("replay_frames", False) else targets - len(imaged_targets(case))
    steps = FrameClock.from_config(case).n_steps * replayed * (3 if noisy else 2)
    return frames_s + steps * IMAGING_SHARE * step_ms(case) / 1e3


def lucky_minutes(settings: dict) -> int:
    """A lucky job's wall time to declare [min]: at least the 30 measured at paper fidelity on
    4.2 m, else :data:`RUNTIME_MARGIN` x :func:`lucky_seconds`."""
    return max(30, math.ceil(RUNTIME_MARGIN * lucky_seconds(settings) / 60))


def mem_mb(estimate_bytes: float, measured_mb: int = 0, margin: float = MARGIN) -> int:
    """A rule's declared memory [MB]: the estimate x ``margin``, at least ``measured_mb``
    (the rule's measured need at paper fidelity), rounded up to 100 MB."""
    return max(measured_mb, 100 * math.ceil(margin * estimate_bytes / 1e8))


class Job(NamedTuple):
    """One job of a study, from its config: what :func:`preflight` checks and ``luckyao show`` prints."""

    name: str
    """``<step> <key or case>``, e.g. ``simulate ltao_r0_13.5cm``."""
    case: str
    """The first case it serves."""
    memory_bytes: float
    output: str | None
    """The file it writes that the pre-flight counts, or None."""
    output_bytes: float
    seconds: float
    """Its estimated time on one core (the ``*_seconds`` functions)."""


CALIBRATION_BYTES = 1.5e9
"""A WFS calibration's memory: what its rule declares (small sensors; not measured apart)."""


def study_jobs(view: ResolvedStudy) -> list[Job]:
    """Every job of a resolved study, once (a product shared by cases: its first case)."""
    jobs = {}

    def add(name, *values):
        jobs.setdefault(name, Job(name, *values))

    n_screens_jobs = len({resolved.screens.key for resolved in view.cases.values()})
    for name, resolved in view.cases.items():
        case, screens = resolved.config, resolved.screens
        threads = screens_job_threads(screens.spec, n_screens_jobs)
        add(
            f"turbulence {screens.key}",
            name,
            turbulence_memory_bytes(screens.spec, threads),
            screens.samples_path,
            screens_bytes(screens.spec),
            screens_seconds(screens.spec, threads),
        )
        if (product := resolved.calibration) is not None:
            spec = product.spec
            add(
                f"calibration {product.key}", name, calibration_memory_bytes(spec), None, 0.0, calibration_seconds(spec)
            )
        if (product := resolved.reconstructor) is not None:
            add(
                f"reconstructor {product.key}",
                name,
                reconstructor_memory_bytes(product.spec),
                product.path,
                reconstructor_bytes(product.spec),
                reconstructor_seconds(product.spec),
            )
        if (product := resolved.commands) is not None:
            add(
                f"commands {product.key}",
                name,
                commands_memory_bytes(product.spec),
                product.path,
                commands_bytes(product.spec),
                commands_seconds(product.spec),
            )
        if (product := resolved.slopes) is not None:
            add(
                f"slopes {product.key}",
                name,
                slopes_memory_bytes(case),
                product.path,
                slopes_bytes(case),
                slopes_seconds(case),
            )
        if view.config.get("replay_frames", False):  # no cube: the telemetry is the simulation's file
            output, size = f"results/cases/{name}/telemetry.nc", telemetry_bytes(case)
        else:
            output, size = f"results/cases/{name}/frames.nc", frames_bytes(case)
        twin = resolved.lgs_twin
        add(f"simulate {name}", name, simulate_memory_bytes(case, twin), output, size, simulate_seconds(case, twin))
        settings = resolved.lucky_settings
        add(f"lucky {name}", name, lucky_memory_bytes(settings), None, 0.0, lucky_seconds(settings))
    return list(jobs.values())


def machine_memory_bytes() -> float:
    return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


FILE_KINDS = {
    "turbulence": "phase screens",
    "reconstructor": "reconstructors",
    "commands": "command matrices",
    "slopes": "LGS slopes",
    "simulate": "frame cubes (telemetry with replay_frames)",
}


def preflight(view: ResolvedStudy, folder=".", memory_bytes: float | None = None, parallel_jobs: int = 1) -> list[str]:
    """One problem per job whose memory estimate exceeds ``memory_bytes`` (default: this
    machine's), and one when the files of the study not yet made would together exceed the
    free disk of ``folder``: every product and, with ``keep_frames``, every frame cube, or
    without it the ``parallel_jobs`` largest (each is deleted once post-processed)."""
    memory_bytes = memory_bytes or machine_memory_bytes()
    free_bytes = shutil.disk_usage(folder).free
    problems, pending = [], []
    for job, case, memory, output, size, _ in study_jobs(view):
        if memory > memory_bytes:
            key = "turbulence" if job.startswith("turbulence ") else f"cases.{case}"  # screens: of every case
            dense = job.split()[0] in ("reconstructor", "commands")
            problems.append(
                f"config key '{key}': job {job} needs about {_gb(memory)} of memory, more than "
                f"the {_gb(memory_bytes)} available (this machine's memory, or --resources mem_mb=N if "
                "larger)"
                + (
                    "; tomography.method: iterative builds no dense reconstructor or command matrix "
                    "(docs: methods/layer-tomography)"
                    if dense
                    else ""
                )
            )
        if output is not None and not (Path(folder) / output).exists():
            pending.append((job, case, output, size))
    keep_frames, replay = view.config.get("keep_frames", False), view.config.get("replay_frames", False)
    kept = [p for p in pending if keep_frames or replay or not p[0].startswith("simulate ")]
    passing = sorted((p for p in pending if p not in kept), key=lambda p: p[3], reverse=True)[: max(1, parallel_jobs)]
    needed = sum(p[3] for p in kept + passing)
    if needed > free_bytes:
        totals = {}
        for job, *_, size in kept + passing:
            totals[FILE_KINDS[job.split()[0]]] = totals.get(FILE_KINDS[job.split()[0]], 0.0) + size
        parts = ", ".join(f"{kind} {_gb(size)}" for kind, size in sorted(totals.items(), key=lambda t: -t[1]))
        frames = (
            "every frame cube kept (keep_frames: true)"
            if keep_frames
            else "no frame cube (replay_frames: true)"
            if replay
            else f"the {len(passing)} largest frame cubes at once (each deleted once post-processed)"
        )
        largest = max(kept + passing, key=lambda p: p[3])
        problems.append(
            f"config key '{'keep_frames' if keep_frames else 'cases'}': the study's files not yet made "
            f"need about {_gb(needed)} together ({parts}; {frames}), more than the {_gb(free_bytes)} "
            f"free on the study folder's disk (the largest: {largest[2]} of case '{largest[1]}', "
            f"{_gb(largest[3])})"
        )
    return problems


class StudyTooLarge(ConfigError):
    """A valid study whose jobs do not fit this machine's memory or the study folder's disk."""


def checked_study(
    config: dict, folder=".", memory_bytes: float | None = None, parallel_jobs: int | None = None
) -> ResolvedStudy:
    """The one pre-flight of a study config, shared by ``luckyao check`` and the workflow (its
    dry run and every run), before any job: the config validated (``ConfigError``, one line per
    problem naming its key), then :func:`preflight` in ``folder`` (``StudyTooLarge``, one line
    per problem); returns the study resolved (``studyspec.view``).
    ``parallel_jobs``: jobs run at once (default: this machine's cores)."""
    study = expand_study(config)
    view = resolve_study(study, validate_study(study))
    problems = preflight(view, folder, memory_bytes, parallel_jobs or os.cpu_count() or 1)
    if problems:
        raise StudyTooLarge("\n".join(problems))
    return view


def _gb(n_bytes: float) -> str:
    return f"{n_bytes / 1e9:,.1f} GB"
