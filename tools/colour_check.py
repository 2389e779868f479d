"""The colour-blind check of the published figures: which of the palette's colours each PNG
draws with, and how far apart they stay to normal, deuteranope and protanope eyes
(Machado et al. 2009 simulation, CIEDE2000: src/luckyao/figures/colour_vision.py).

A pair closer than ``DISTINCT_DE00`` is reported: the figure must tell those series apart by
marker or line style as well (tests/test_figure_style.py checks that on the drawings, from
their datasets). With ``--simulate DIR`` each PNG is also written as a dichromat sees it,
``DIR/<name>.<vision>.png``, to look at.

Usage (from the checkout): .venv/bin/python tools/colour_check.py [--simulate DIR] [PNG ...]
(default: figures/paper/*.png figures/telescopes/*.png figures/stars/*.png figures/*.png)."""

import argparse
import glob
import sys
from itertools import combinations
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np

from luckyao.figures.colour_vision import DISTINCT_DE00, MACHADO_2009, VISIONS, closest_pair, simulate
from luckyao.figures.style import PALETTE

MIN_PIXELS = 100
"""A palette colour counts as drawn when at least this many pixels have it exactly (black,
the palette's third colour, always does: the text is black)."""


def palette_colours(image: np.ndarray) -> list[str]:
    """The palette's colours drawn in an RGB(A) image (8-bit exact matches)."""
    rgb = np.round(image[..., :3] * 255).astype(np.int32).reshape(-1, 3)
    codes = rgb[:, 0] << 16 | rgb[:, 1] << 8 | rgb[:, 2]
    values, counts = np.unique(codes, return_counts=True)
    found = dict(zip(values.tolist(), counts.tolist()))
    return [c for c in PALETTE if found.get(int(c[1:], 16), 0) >= MIN_PIXELS]


def check(path: Path, simulate_to: Path | None) -> list[str]:
    """One report line per vision; the pairs below the threshold named."""
    image = mpimg.imread(path)
    colours = palette_colours(image)
    if simulate_to is not None:
        simulate_to.mkdir(parents=True, exist_ok=True)
        for vision in MACHADO_2009:
            mpimg.imsave(simulate_to / f"{path.stem}.{vision}.png", simulate(image[..., :3], vision))
    if len(colours) < 2:
        return [f"{path}: {len(colours)} palette colour(s) drawn: nothing to tell apart"]
    lines = []
    for vision in VISIONS:
        distance, a, b = closest_pair(colours, vision)
        close = [(x, y) for x, y in combinations(colours, 2) if closest_pair([x, y], vision)[0] < DISTINCT_DE00]
        note = f"; below {DISTINCT_DE00:g}: " + ", ".join(f"{x}/{y}" for x, y in close) if close else ""
        lines.append(f"{path}: {vision:12s} {len(colours)} colours, closest {a}/{b} {distance:5.1f}{note}")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pngs", nargs="*", type=Path)
    parser.add_argument("--simulate", type=Path, default=None, help="write each PNG as dichromats see it here")
    args = parser.parse_args(argv)
    pngs = args.pngs or [
        Path(p)
        for pattern in ("figures/paper/*.png", "figures/telescopes/*.png", "figures/stars/*.png", "figures/*.png")
        for p in sorted(glob.glob(pattern))
    ]
    if not pngs:
        print("colour_check: no PNG found", file=sys.stderr)
        return 1
    below = 0
    for path in pngs:
        lines = check(path, args.simulate)
        below += any("below" in line for line in lines)
        print("\n".join(lines))
    print(
        f"colour_check: {len(pngs)} figures; {below} with palette colours closer than {DISTINCT_DE00:g} (CIEDE2000) "
        "to some eye, told apart by marker or line style (tests/test_figure_style.py)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
