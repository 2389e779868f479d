"""Friendly edges: report captions that no config text can add markup to, one-line
errors from every command-line subcommand, and an ETA that starts after compilation."""

import logging
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from docutils.core import publish_parts

from luckyao.jobs.report import figure_caption, rst_text
from luckyao.studyspec.study import validate_study

pytestmark = pytest.mark.workflow  # runs Snakemake, a study or the command line: -m 'not workflow' skips it

TINY = Path(__file__).resolve().parent / "data" / "tiny.yaml"
HOSTILE = [
    "<script>alert(1)</script>",
    "x``\n\n.. raw:: html\n\n   <script>alert(2)</script>\n\n``",
    "`click <javascript:alert(3)>`_",
    "*bold* :raw-html:`<b>` |sub| [#]_ \\",
]


@pytest.mark.parametrize("text", HOSTILE)
def test_config_text_reaches_the_report_as_text_never_as_markup(text):
    """Rendered as Snakemake renders captions (docutils to HTML, raw HTML allowed), an
    escaped name shows its characters and creates no element."""
    html = publish_parts(f"Figure **{rst_text(text)}**.", writer="html")["body"]
    assert "<script" not in html and "<a " not in html and "<b>" not in html
    shown = html.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", '"').replace("&amp;", "&")
    assert " ".join(text.split()) in shown


def test_a_hostile_detector_and_figure_name_stay_text_in_the_whole_caption():
    study = yaml.safe_load(TINY.read_text())
    cases = validate_study(study)
    figure = dict(study["figures"]["quality"], detector=HOSTILE[1])
    caption = figure_caption(HOSTILE[0], figure, study, cases)
    html = publish_parts(caption, writer="html")["body"]
    assert "<script" not in html
    shown = html.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", '"').replace("&amp;", "&")
    assert " ".join(HOSTILE[1].split()) in shown and HOSTILE[0] in shown
    assert "Cases" in html and "no AO, 4.2 m, r0 20 cm" in html


def luckyao(*args):
    return subprocess.run([sys.executable, "-m", "luckyao", *args], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize(
    "args",
    [
        ["table", "{tiny}"],
        ["table", "{missing}"],
        ["figure", "--id", "x", "--settings-file", "{missing}", "--out-prefix", "{tmp}/x"],
        ["figure", "--id", "x", "--settings", "{{not json", "--out-prefix", "{tmp}/x"],
        ["export", "{missing}", "--out", "{tmp}/x.fits"],
        ["lucky", "--settings", "{{}}", "--frames", "{missing}", "--telemetry", "{missing}", "--out", "{tmp}/l.nc"],
        [
            "simulate",
            "--case",
            "{{}}",
            "--name",
            "x",
            "--seed",
            "1",
            "--screens",
            "{missing}",
            "--screens-metadata",
            "{missing}",
            "--frames",
            "{tmp}/f.nc",
            "--telemetry",
            "{tmp}/t.nc",
        ],
        ["turbulence", "--spec", "{{}}", "--screens", "{tmp}/s.npy", "--metadata", "{tmp}/s.nc"],
        ["reconstructor", "--spec", "{{}}", "--out", "{tmp}/r.nc"],
        ["commands", "--spec", "{{}}", "--out", "{tmp}/c.nc"],
        ["verify", "{missing}"],
        ["check", "{missing}"],
    ],
)
def test_every_subcommand_fails_in_one_line_without_a_traceback(args, tmp_path):
    """A wrong file or argument: exit status 1 and one line naming the problem."""
    names = {"tiny": str(TINY), "missing": str(tmp_path / "missing.nc"), "tmp": str(tmp_path)}
    result = luckyao(*(a.format(**names) for a in args))
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr
    problems = [line for line in result.stderr.splitlines() if " INFO " not in line]
    assert len(problems) == 1, result.stderr
    if args[0] == "table" and "tiny" in args[1]:
        assert "not a long_exposure_table figure's data" in problems[0] or "unreadable" in problems[0]


def test_the_eta_counts_from_the_first_chunk_not_from_the_compilation(monkeypatch, caplog):
    """A first chunk of 10 frames that takes 100 s (numba compiling), then 10 frames/s:
    the ETA is the remaining frames at 10 frames/s, not at the mean rate with the
    compilation in it."""
    from luckyao import progress

    clock = iter([0.0, 100.0, 101.0, 102.0])
    monkeypatch.setattr(progress.time, "monotonic", lambda: next(clock))
    with caplog.at_level(logging.INFO, logger="luckyao.progress"):
        reporter = progress.Progress("frames", 1000, every_s=0)
        reporter.update(10)  # t = 100 s: the compilation
        reporter.update(20)  # t = 101 s
        reporter.update(30)  # t = 102 s
    last = caplog.records[-1].getMessage()
    assert "10.0/s" in last and "ETA 97 s" in last, last
