"""Benchmark: lucky post-processing (``lucky.run_lucky``) of one target for the noise study's sweep.

The detectors are those of the study's sweep (``study.config.sweep_detectors``: 9 signal
levels from 10 to 1e5 detected photons per frame, log-spaced, x read noise 0.1 and 1 e-)
plus the noiseless one: 19 in all, as a case shown by a noise figure gets them. Frames:
256 x 256 unit-flux images (800 nm, 4.2 m telescope, 5" field) of random von Karman phases
(r0 = 13.5 cm at 500 nm), every other frame with the low orders below the DM cutoff damped
(an AO-like core, Strehl ~0.3) and the others seeing-limited (d50 ~0.6"), each tilted to a
centre wandering by ~0.25" rms. Criteria: strehl, d50 and three external ones (as
``lgs_rms``, ``lgs_residual_rms``, ``true_rms``), the study's 9 fractions.

Runs a ``--frames`` cube (default 512: 256 frames generated once, cached in the temporary
directory, and tiled) and a quarter of it: their difference gives the per-frame cost, the
rest is the fixed cost (scoring the integrated images). Prints ``seconds_<frames>``,
``scoring_s_<frames>`` (time in ``scoring.score_partial_sums``: the integrated images' Strehl, d50, FWHM,
of the run and, with ``--blocks``, of each time block), ``fixed_s``,
``frames_per_s``, ``detector_frames_per_s`` (per-frame part only) and
``extrapolated_s_25000`` (fixed + 25,000 frames). With ``--cube N``, also a real run over an N-frame cube
(the generated frames tiled, yielded in blocks of 64 as the study reads them, nothing on
disk), with its elapsed time and the process's peak resident memory.

With ``--frames-file results/cases/ltao_r0_13.5cm/frames.nc`` (after the default study) the frames
are that case's first 256 instead (real AO-corrected frames).

With ``--registrations NAME ...`` the frames are registered by those methods (``lucky.registration``;
default all four, as the paper's sweep cases), in one run (``lucky.run_lucky_methods``: the methods
share the passes over the frames, as the study runs them); ``--registrations cog`` times ``cog`` alone.
With ``--fourier F ...``, Fourier lucky imaging too at those fractions (``lucky.fourier``).

Run: .venv/bin/python benchmarks/bench_lucky.py [--frames 256] [--cube 25000] [--repeats 1] [--blocks 10]
     [--frames-file FRAMES.nc] [--registrations cog windowed_cog peak xcorr] [--fourier 0.01 0.1 1]
"""

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import argparse  # noqa: E402
import resource  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from luckyao.atmosphere.statistics import von_karman_psd  # noqa: E402
from luckyao.lucky import method_run  # noqa: E402
from luckyao.lucky.detector import Detector  # noqa: E402
from luckyao.lucky.pipeline import run_lucky_methods  # noqa: E402
from luckyao.lucky.ranking import ExternalCriterion  # noqa: E402
from luckyao.lucky.registration import REGISTRATIONS, Registration, search_px  # noqa: E402
from luckyao.optics.imaging import Camera, Imager  # noqa: E402
from luckyao.optics.pupil import Telescope  # noqa: E402

FRACTIONS = [0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.75, 1.0]
BLOCK = 64  # frames per chunk, as study.datasets.iter_frame_blocks
TARGET_FRAMES = 25_000
GENERATED = 256


def sweep() -> list[Detector]:
    """The noiseless detector and the study's sweep (names as ``study.config.sweep_name``)."""
    photons = np.geomspace(10, 1e5, 9)
    return [Detector("noiseless")] + [
        Detector(f"rn{rn:g}_{n:.3g}ph", float(n), rn) for rn in (0.1, 1.0) for n in photons
    ]


def imager() -> Imager:
    return Imager(Telescope(4.2, 1.2), Camera(800e-9, 256, 5 / 256))


def make_frames(n_frames: int, seed: int = 0) -> np.ndarray:
    """Unit-flux frames (n_frames, 256, 256) float32 (module docstring)."""
    im = imager()
    grid, mask = im.grid, im.mask
    m = 2 * grid.n_pix
    fy, fx = np.meshgrid(np.fft.fftfreq(m, grid.dx_m), np.fft.fftfreq(m, grid.dx_m), indexing="ij")
    f = np.hypot(fy, fx)
    r0_m = 0.135 * (800 / 500) ** 1.2
    amplitude = np.sqrt(von_karman_psd(f, r0_m, 25.0)) / (m * grid.dx_m)
    amplitude[0, 0] = 0.0
    corrected = amplitude * np.where(f < 1 / (2 * 4.2 / 9), 0.08, 1.0)
    rng = np.random.default_rng(seed)
    x, y = (c[mask] for c in grid.xy_m)
    frames = np.empty((n_frames, 256, 256), np.float32)
    for i in range(n_frames):
        z = rng.standard_normal((m, m)) + 1j * rng.standard_normal((m, m))
        screen = np.fft.fft2(z * (corrected if i % 2 == 0 else amplitude)).real
        phase = screen[: grid.n_pix, : grid.n_pix][mask]
        tilt_rad = rng.normal(0.0, 0.25, 2) * np.pi / 180 / 3600
        phase = phase - phase.mean() + 2 * np.pi * (tilt_rad[0] * y + tilt_rad[1] * x) / 800e-9
        frames[i] = im.image(phase[None].astype(np.float32))[0]
    return frames


def cached_frames(n_frames: int) -> np.ndarray:
    path = Path(tempfile.gettempdir()) / f"luckyao_bench_lucky_{n_frames}.npy"
    if not path.exists():
        np.save(path, make_frames(n_frames))
    return np.load(path)


def study_frames(path: str) -> np.ndarray:
    """The first ``GENERATED`` frames of target 0 of a study's ``frames.nc`` (e.g. an LTAO
    case's: real AO-corrected frames, dearer to detect than the generated ones, whose
    seeing-limited half has fewer bright pixels)."""
    import xarray as xr

    with xr.open_dataset(path) as ds:
        return ds.frames[0, :GENERATED].values.astype(np.float32)


def externals(n_frames: int) -> list[ExternalCriterion]:
    rng = np.random.default_rng(1)
    return [
        ExternalCriterion(name, rng.uniform(50, 300, n_frames), False, "nm")
        for name in ("lgs_rms", "lgs_residual_rms", "true_rms")
    ]


def tiled(frames: np.ndarray, n_frames: int):
    """Chunks of ``BLOCK`` frames of an ``n_frames`` cube tiling ``frames``, none stored."""

    def iterate():
        for start in range(0, n_frames, BLOCK):
            index = np.arange(start, min(start + BLOCK, n_frames)) % len(frames)
            yield start, frames[index]

    return iterate


SCORING = {"s": 0.0, "images": 0}
_score = method_run.score_partial_sums


def _timed_score(partial, *args, **kwargs):
    """``scoring.score_partial_sums`` (integrated images of the whole run and of each time block), timed."""
    t0 = time.perf_counter()
    out = _score(partial, *args, **kwargs)
    SCORING["s"] += time.perf_counter() - t0
    SCORING["images"] += out[1].size
    return out


method_run.score_partial_sums = _timed_score


def registration(name: str) -> Registration:
    """The registration method ``name`` for the benchmark's camera (as ``LuckySettings.registration_methods``)."""
    im = imager()
    return Registration(
        name,
        im.diffraction_limited,
        800e-9 / 4.2 / im.camera.pixel_scale_rad,
        search_px(im.camera.n_pixels, im.camera.pixel_scale_arcsec),
    )


def run(frames: np.ndarray, n_frames: int, n_blocks: int = 0, methods=("cog",), fourier=None) -> float:
    im = imager()
    SCORING.update(s=0.0, images=0)
    t0 = time.perf_counter()
    run_lucky_methods(
        tiled(frames, n_frames),
        n_frames,
        sweep(),
        FRACTIONS,
        im.diffraction_limited_peak,
        im.camera.pixel_scale_arcsec,
        1,
        criteria_external=externals(n_frames),
        n_blocks=n_blocks,
        progress_interval_s=60,
        registrations=[registration(name) for name in methods],
        fourier_fractions=fourier,
    )
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=512)
    parser.add_argument("--cube", type=int, default=0, help="frames of a real run too (0: none)")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--blocks", type=int, default=0, help="time blocks (n_blocks of run_lucky; 0: none)")
    parser.add_argument(
        "--registrations",
        nargs="+",
        default=list(REGISTRATIONS),
        choices=REGISTRATIONS,
        help="registration methods, in one run (lucky.registration; default all four)",
    )
    parser.add_argument("--fourier", nargs="+", type=float, default=None, help="Fourier lucky imaging's fractions")
    parser.add_argument(
        "--frames-file",
        default=None,
        help="a study's frames.nc: its first 256 frames (of target 0) instead of the generated ones",
    )
    args = parser.parse_args()
    frames = cached_frames(GENERATED) if args.frames_file is None else study_frames(args.frames_file)
    n_det = len(sweep())
    half = args.frames // 4
    print(f"registrations {' '.join(args.registrations)}")
    for _ in range(args.repeats):
        t_half = run(frames, half, args.blocks, args.registrations, args.fourier)
        t_full = run(frames, args.frames, args.blocks, args.registrations, args.fourier)
        print(
            f"scoring_s_{args.frames} {SCORING['s']:.2f} ({SCORING['images']} images, "
            f"{SCORING['s'] / max(SCORING['images'], 1) * 1e3:.2f} ms each)"
        )
        per_frame = (t_full - t_half) / (args.frames - half)
        fixed = t_full - args.frames * per_frame
        print(f"seconds_{half} {t_half:.2f}")
        print(f"seconds_{args.frames} {t_full:.2f}")
        print(f"fixed_s {fixed:.2f}")
        print(f"frames_per_s {1 / per_frame:.2f}")
        print(f"detector_frames_per_s {n_det / per_frame:.1f}")
        print(f"extrapolated_s_{TARGET_FRAMES} {fixed + TARGET_FRAMES * per_frame:.0f}")
    if args.cube:
        elapsed = run(frames, args.cube, args.blocks, args.registrations, args.fourier)
        print(f"cube_frames {args.cube}")
        print(f"cube_seconds {elapsed:.1f}")
        print(f"peak_rss_mb {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f}")


if __name__ == "__main__":
    main()
