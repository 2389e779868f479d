"""Redraw published figures from their own datasets: each ``<name>.nc`` given is drawn again
(``luckyao.api.draw``, as the workflow draws it) to ``<name>.png`` beside it. For a change of
drawing only (style, labels, layout): the datasets, and so every number, stay as they are.

Usage (from the checkout):
    .venv/bin/python tools/redraw_figures.py figures/paper/*.nc figures/telescopes/*.nc figures/stars/*.nc"""

import sys
from pathlib import Path

from luckyao.api import draw
from luckyao.figures.style import DPI
from luckyao.io.datasets import open_dataset

if len(sys.argv) < 2:
    sys.exit(__doc__)
for name in sys.argv[1:]:
    path = Path(name)
    fig = draw(open_dataset(path, "figure data", remake=False))
    fig.savefig(path.with_suffix(".png"), dpi=DPI)
    width, height = fig.get_size_inches() * DPI
    print(f"{path.with_suffix('.png')}: {width:.0f} x {height:.0f} pixels")
