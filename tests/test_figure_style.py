"""Figures a person reads at a glance (issue 45): one screen each with its legend, the
fraction axis read 1, 10, 100 %, r0 in cm, series told apart by line style and marker as
well as colour, coinciding curves drawn once, and a palette that stays apart to
colour-blind eyes. Drawn from the published figures' own datasets."""

from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_hex

from luckyao.api import draw
from luckyao.figures.colour_vision import DISTINCT_DE00, MACHADO_2009, VISIONS, ciede2000, closest_pair, simulate
from luckyao.figures.quality import coinciding_label
from luckyao.figures.style import DISTINCT_COLOURS, DPI, PALETTE, SCREEN_INCHES, parameter
from luckyao.io.datasets import open_dataset

FIGURES = Path(__file__).resolve().parents[1] / "figures"
PUBLISHED_RUNS = ("paper", "telescopes", "stars", "selection")
PUBLISHED = [path for run in PUBLISHED_RUNS for path in sorted(FIGURES.glob(f"{run}/*.nc"))]


def drawn(path: Path, laid_out: bool = True):
    fig = draw(open_dataset(path, "figure data", remake=False))
    if laid_out:
        FigureCanvasAgg(fig).draw()  # tick labels and legends placed
    return fig


@pytest.fixture(scope="module")
def ltao():
    return drawn(FIGURES / "paper" / "ltao.nc")


def test_ciede2000_matches_the_published_test_pairs():
    """Sharma, Wu & Dalal (2005), table 1: pairs 1, 7, 17, 18, 19 and 24 (rounded to 1e-4)."""
    pairs = [
        ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
        ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
        ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
        ((50.0, 2.5, 0.0), (61.0, -5.0, 29.0), 22.8977),
        ((50.0, 2.5, 0.0), (56.0, -27.0, -3.0), 31.9030),
        ((50.0, 2.5, 0.0), (50.0, 3.1736, 0.5854), 1.0000),
    ]
    for lab1, lab2, expected in pairs:
        assert ciede2000(np.array(lab1), np.array(lab2)) == pytest.approx(expected, abs=1e-4)
        assert ciede2000(np.array(lab2), np.array(lab1)) == pytest.approx(expected, abs=1e-4)


def test_dichromat_simulation_keeps_greys_and_merges_red_with_green():
    """Machado et al. (2009): a grey is seen as it is (every row sums to 1); Okabe-Ito's
    vermilion and bluish green, far apart to normal eyes, come within half of that."""
    for matrix in MACHADO_2009.values():
        assert matrix.sum(axis=1) == pytest.approx(np.ones(3), abs=1e-5)
        assert simulate(np.array([0.5, 0.5, 0.5]), "deuteranopia") == pytest.approx([0.5] * 3, abs=1e-4)
    normal = closest_pair(["#D55E00", "#009E73"], "normal")[0]
    for vision in MACHADO_2009:
        assert closest_pair(["#D55E00", "#009E73"], vision)[0] < 0.4 * normal


def test_the_palette_stays_apart_to_colour_blind_eyes():
    """The first colours, a figure's first series, at least DISTINCT_DE00 apart (CIEDE2000)
    to normal, deuteranope and protanope eyes (the old palette: 12.2 for protanopes)."""
    for vision in VISIONS:
        distance, a, b = closest_pair(PALETTE[:DISTINCT_COLOURS], vision)
        assert distance >= DISTINCT_DE00, f"{vision}: {a} and {b} only {distance:.1f} apart"


@pytest.mark.parametrize("path", PUBLISHED, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_figure_fits_one_screen_and_tells_its_series_apart(path):
    """At most 1920 x 1200 pixels; two series of a legend drawn alike but for colour have
    colours at least DISTINCT_DE00 apart to normal, deuteranope and protanope eyes."""
    fig = drawn(path, laid_out=False)
    width, height = fig.get_size_inches() * DPI
    assert width <= SCREEN_INCHES[0] * DPI + 0.5 and height <= SCREEN_INCHES[1] * DPI + 0.5
    assert_told_apart(legend_styles(fig))


@pytest.mark.parametrize("name", ["noised50", "noise"])
def test_the_noise_figures_are_one_screen_with_their_legend(name):
    """noised50 was 1935 x 4485 pixels (24 panels) with its legend four screens down."""
    fig = drawn(FIGURES / "paper" / f"{name}.nc")
    assert tuple(fig.get_size_inches() * DPI) == pytest.approx((1920, 1200))
    assert len([ax for ax in fig.axes if ax.get_visible()]) == {"noised50": 4 * 6, "noise": 4 * 3}[name]
    box = fig.bbox
    (legend,) = fig.legends
    extent = legend.get_window_extent()
    assert box.x0 <= extent.x0 and extent.x1 <= box.x1 and box.y0 <= extent.y0 and extent.y1 <= box.y1


def test_the_fraction_axis_reads_1_10_100_percent(ltao):
    for ax in ltao.axes:
        low, high = ax.get_xlim()
        labels = [t.get_text() for t in ax.get_xticklabels() if low <= t.get_position()[0] <= high]
        assert labels == ["1", "10", "100"]
        assert ax.get_xlabel() == "frames selected [%]"


def test_r0sweep_reads_r0_in_cm():
    fig = drawn(FIGURES / "paper" / "r0sweep.nc")
    for ax in fig.axes:
        assert ax.get_xlabel() == "r0 at 500 nm [cm]"
        for line in ax.get_lines():
            x = np.asarray(line.get_xdata(), dtype=float)
            assert x.size == 0 or (x.min() >= 10 and x.max() <= 25)  # 10 to 25 cm, not 0.1 to 0.25 m
    assert "atmosphere.r0_500nm_m" not in fig.get_suptitle()
    assert parameter("atmosphere.r0_500nm_m").label() == "r0 at 500 nm [cm]"
    assert parameter("some.key_m").label() == "some.key_m"


def legend_styles(fig) -> dict[str, tuple]:
    """Label -> (colour, line style, marker) of every line in the figure's legends."""
    styles = {}
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    for legend in legends:
        for handle, text in zip(legend.legend_handles, legend.get_texts()):
            if hasattr(handle, "get_linestyle") and hasattr(handle, "get_marker"):
                styles[text.get_text()] = (to_hex(handle.get_color()), handle.get_linestyle(), handle.get_marker())
    return styles


def assert_told_apart(styles: dict[str, tuple]) -> None:
    for (a, (colour_a, ls_a, marker_a)), (b, (colour_b, ls_b, marker_b)) in combinations(styles.items(), 2):
        if (ls_a, marker_a) == (ls_b, marker_b) and colour_a != colour_b:
            for vision in VISIONS:
                distance = closest_pair([colour_a, colour_b], vision)[0]
                assert distance >= DISTINCT_DE00, f"{a} and {b}: {distance:.1f} apart ({vision})"


def test_ltao_series_differ_by_line_style_or_marker_not_colour_alone(ltao):
    """The five LTAO cases (all solid lines: the old code drew them alike but for colour,
    vermilion and bluish green among them) differ by marker as well."""
    styles = legend_styles(ltao)
    assert_told_apart(styles)
    ltao_markers = [marker for label, (_, _, marker) in styles.items() if label.startswith("LTAO")]
    assert len(ltao_markers) == 5 and len(set(ltao_markers)) == 5


def test_coinciding_no_ao_curves_are_drawn_once(ltao):
    """Selected by Strehl, the three no-AO cases give one curve (their WFS plays no part):
    drawn once, labelled with all three; selected by the LGS rms they differ, and stay."""
    strehl_row = [ax for ax in ltao.axes if ax.get_title(loc="left").startswith("(b)")][0]
    dashed = [line for line in strehl_row.get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == 1
    assert dashed[0].get_label() == "no AO, 8x8 WFS = 16x16 WFS = 32x32 WFS (identical)"
    rms_row = [ax for ax in ltao.axes if ax.get_title(loc="left").startswith("(a)")][0]
    assert len([line for line in rms_row.get_lines() if line.get_linestyle() == "--"]) == 3


def test_coinciding_label_names_what_differs():
    assert coinciding_label(["LTAO, r0 15 cm"]) == "LTAO, r0 15 cm"
    assert coinciding_label(["no AO, 8x8 WFS", "no AO, 16x16 WFS"]) == "no AO, 8x8 WFS = 16x16 WFS (identical)"
