"""The study's terminal (issue 45): one line per job instead of Snakemake's job blocks with
their fifty source-file inputs, and a progress line (done, running, left, time left) as
each job finishes; checked on a recorded log of the default study and on a small one."""

import gzip
from pathlib import Path

import pytest

from luckyao.jobs.live_run import run_snakemake, verbose
from luckyao.jobs.progress import VERBOSE_ENV, Progress, declared_runtimes, duration

REPO = Path(__file__).resolve().parents[1]
RECORDED = REPO / "tests" / "data" / "snakemake_study.log.gz"
"""Snakemake 9.27's log of ``bash run.sh study`` (the default study, 101 jobs), as recorded."""


def shown(lines, runtimes=None) -> list[str]:
    progress = Progress(declared_runtimes(REPO / "workflow" / "rules") if runtimes is None else runtimes)
    out = []
    for line in lines:
        out += progress.feed(line)
    return out + progress.close()


@pytest.fixture(scope="module")
def recorded():
    with gzip.open(RECORDED, "rt") as log:
        lines = log.readlines()
    return lines, shown(lines)


def test_no_job_lists_its_inputs(recorded):
    lines, out = recorded
    assert sum(line.startswith("    input: ") for line in lines) == 101  # Snakemake lists them
    assert not any("input:" in line or "src/luckyao/" in line for line in out)
    assert len(out) < len(lines) / 2


def test_one_line_per_job_started(recorded):
    lines, out = recorded
    started = [line for line in out if line.startswith("[") and "] " in line and not line.startswith("[Sat")]
    assert len(started) == 101
    assert "] simulate (case=ltao_r0_13.5cm)" in "\n".join(started)


def test_a_progress_line_per_job_done(recorded):
    _, out = recorded
    progress = [line for line in out if line.startswith("luckyao: ") and " jobs done" in line]
    assert len(progress) == 101
    assert progress[0].startswith("luckyao: 1 of 101 jobs done, ")
    assert progress[-1] == "luckyao: 101 of 101 jobs done, 0 running, 0 left"
    assert all(" left; about " in line for line in progress[1:-1])


SMALL = """\
Job stats:
job      count
-----  -------
a            2
b            1
all          1
total        4

Select jobs to execute...
Execute 1 jobs...

[Sat Nov 28 01:00:00 2026]
localrule a:
    input: src/x.py, src/y.py
    output: out/a1
    jobid: 1
    wildcards: n=1
    resources: tmpdir=/tmp, runtime=1
[Sat Nov 28 01:01:00 2026]
Finished jobid: 1 (Rule: a)
1 of 4 steps (25%) done
Execute 2 jobs...

[Sat Nov 28 01:01:00 2026]
localrule a:
    input: src/x.py, src/y.py
    output: out/a2
    jobid: 2
    wildcards: n=2
    resources: tmpdir=/tmp, runtime=1

[Sat Nov 28 01:01:00 2026]
localrule b:
    input: out/a1
    output: out/b
    jobid: 3
    resources: tmpdir=/tmp, runtime=2
[Sat Nov 28 01:01:30 2026]
Finished jobid: 2 (Rule: a)
2 of 4 steps (50%) done
[Sat Nov 28 01:01:40 2026]
Error in rule b:
    message: None
    jobid: 3
    log: logs/b.log (check log file(s) for error details)

Shutting down, this might take some time.
""".splitlines(keepends=True)


def test_the_time_left_from_the_jobs_timed_and_the_runtimes_declared():
    """After a (declared 1 min) took 60 s: a takes 60 s, b (declared 2 min) 120 s: 180 s on
    one job at a time. Then a's jobs took 45 s on average, b (45 s per declared minute: 90 s)
    has run 30 s, and two jobs ran at once for 30 of the 90 s: (90 - 30) / (120 / 90) = 45 s."""
    out = shown(SMALL, {"a": 1.0, "b": 2.0})
    assert out[:8] == ["Job stats:", "job      count", "-----  -------", "a            2", "b            1",
                       "all          1", "total        4", "[01:00:00] a (n=1)"]  # fmt: skip
    rough = " (rough: not every step timed yet)"
    assert out[8] == "luckyao: 1 of 4 jobs done, 0 running, 3 left; about 3 min left" + rough
    assert out[9:11] == ["[01:01:00] a (n=2)", "[01:01:00] b"]
    assert out[11] == "luckyao: 2 of 4 jobs done, 1 running, 1 left; about 45 s left" + rough


def test_errors_are_shown_as_snakemake_wrote_them():
    out = shown(SMALL, {"a": 1.0, "b": 2.0})
    assert out[12:] == [
        "Error in rule b:",
        "    message: None",
        "    jobid: 3",
        "    log: logs/b.log (check log file(s) for error details)",
        "",
        "Shutting down, this might take some time.",
    ]


def test_the_rules_declared_runtimes_are_read():
    runtimes = declared_runtimes(REPO / "workflow" / "rules")
    assert runtimes["figure"] == 5 and runtimes["reconstructor"] == 5
    texts = [path.read_text() for path in (REPO / "workflow/rules").glob("*.smk")]
    declared = sum(text.count("runtime=") - text.count("runtime=lambda") for text in texts)
    assert len(runtimes) == declared and "all" not in runtimes
    assert not {"simulate", "lgs_slopes", "calibration", "turbulence"} & set(runtimes)  # each job's own estimate
    # a rule whose runtime is computed per job: the first job's, from its block in the log
    progress = Progress(runtimes)
    for line in (
        "[Sat Nov 28 04:06:27 2026]",
        "rule simulate:",
        "    jobid: 3",
        "    resources: tmpdir=/tmp, runtime=85, mem_mb=3400",
    ):
        progress.feed(line)
    progress.close()
    assert progress.runtimes["simulate"] == 85


def test_durations_read_as_a_person_says_them():
    assert [duration(s) for s in (45, 150, 3600 + 5 * 60)] == ["45 s", "2 min", "1 h 05 min"]


def test_verbose_shows_snakemake_unchanged(monkeypatch):
    monkeypatch.delenv(VERBOSE_ENV, raising=False)
    assert not verbose(["--cores", "2"])
    assert verbose(["--verbose"])
    monkeypatch.setenv(VERBOSE_ENV, "1")
    assert verbose([])


def test_snakemakes_errors_and_exit_status_come_through(capfd):
    assert run_snakemake(["--no-such-option"], None) == 2
    assert "--no-such-option" in capfd.readouterr().err
