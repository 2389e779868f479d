"""Benchmark: the detector noise of the noise study's sweep (``lucky.detector.KeyedNoise``), per frame.

For each of the sweep's 18 noisy detectors (``bench_lucky.sweep``: 9 signal levels from 10 to
1e5 detected photons per frame, read noise 0.1 and 1 e-), the time to detect one 256 x 256
frame (``PreparedChunk.detect`` on chunks of 64, as the study draws them: the photons, the
read noise's Gaussian deviates and the frame's row and column sums and peak), the median of
``--repeats`` rounds taken in turn over the detectors (so that the machine's drift spreads over
all of them); then the sum over the sweep, which the lucky post-processing of a sweep case
spends per frame of the case on drawing the noise. Frames: ``bench_lucky``'s generated ones,
or with ``--frames-file`` a study's (e.g. ``results/cases/ltao_r0_13.5cm/frames.nc``).

Run: .venv/bin/python benchmarks/bench_detector.py [--repeats 7] [--frames-file FRAMES.nc]
"""

from luckyao.threads import pin_one_thread  # no numpy: before it is imported

pin_one_thread()

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from bench_lucky import BLOCK, GENERATED, cached_frames, study_frames, sweep  # noqa: E402

from luckyao.lucky.detector import KeyedNoise  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument(
        "--frames-file",
        default=None,
        help="a study's frames.nc: its first 256 frames (of target 0) instead of the generated ones",
    )
    args = parser.parse_args()
    frames = cached_frames(GENERATED) if args.frames_file is None else study_frames(args.frames_file)
    chunk = KeyedNoise(frames.shape[-1], BLOCK).prepare(frames[:BLOCK])
    out = np.empty((BLOCK, *frames.shape[1:]), np.float32)
    detectors = sweep()[1:]
    for detector in detectors:  # compiled, and the buffers touched
        chunk.detect(detector, 1, 0, out)
    times = {d.name: [] for d in detectors}
    for _ in range(args.repeats):
        for detector in detectors:
            t0 = time.perf_counter()
            chunk.detect(detector, 1, 0, out)
            times[detector.name].append((time.perf_counter() - t0) / BLOCK)
    for name, values in times.items():
        print(f"us_per_frame {name} {np.median(values) * 1e6:.0f}")
    print(f"us_per_frame_sweep {sum(np.median(v) for v in times.values()) * 1e6:.0f}")


if __name__ == "__main__":
    main()
