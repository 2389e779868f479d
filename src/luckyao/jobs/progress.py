"""The terminal of ``bash run.sh study``: Snakemake's log, one line per job, and a study-level
progress line.

Snakemake prints every job it starts as a block (``rule X:`` and indented ``input:``,
``output:``, ``reason:``... lines: some fifty source files of input per job). The study's
terminal shows instead one line per job started (its rule and wildcards) and, as each job
finishes, the jobs done, running and left with the time left (:meth:`Progress.seconds_left`):
each job left takes as long as its rule's jobs took so far, or, for a rule none of whose
jobs has finished, its declared runtime (``resources: runtime`` in ``workflow/rules``)
scaled by how the finished jobs compare with theirs; the sum is spread over as many jobs at
once as have run at once so far. Times are the log's own timestamps. Every other line
(errors, warnings, the job counts, the summary) is shown as Snakemake wrote it, but the
scheduler's ``Select jobs to execute...`` and ``Execute N jobs...``; Snakemake's own log
file (``.snakemake/log/``) keeps everything. ``--verbose`` or ``LUCKYAO_VERBOSE=1`` shows
Snakemake's log unchanged.
"""

import re
from collections import Counter
from datetime import datetime
from pathlib import Path

VERBOSE_ENV = "LUCKYAO_VERBOSE"

_TIMESTAMP = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$")
_SCHEDULER = re.compile(r"^(Select jobs to execute\.\.\.|Execute \d+ jobs\.\.\.)$")
_JOB = re.compile(r"^(?:local)?(?:rule|checkpoint) (\w+):$")
_FINISHED = re.compile(r"^Finished jobid: (\d+) \(Rule: (\w+)\)$")
_STEPS = re.compile(r"^(\d+) of (\d+) steps \(.*\) done$")
_STATS_ROW = re.compile(r"^(\w+)\s+(\d+)$")
_RULE = re.compile(r"^(?:local)?rule (\w+):", re.M)
_RUNTIME = re.compile(r"^\s+runtime=(\d+(?:\.\d+)?)", re.M)
_JOB_RUNTIME = re.compile(r"\bruntime=(\d+(?:\.\d+)?)")
"""A job block's ``resources:`` entry: the runtime Snakemake computed for that job [min]."""


def declared_runtimes(rule_dir="workflow/rules") -> dict[str, float]:
    """Each rule's declared ``runtime`` (minutes) in the workflow's rule files; rules without
    one (the targets ``all``, ``all_cases``) or whose runtime is computed per job (simulate,
    lucky: their first job's, from its block in the log) are left out."""
    runtimes = {}
    for path in sorted(Path(rule_dir).glob("*.smk")):
        text = path.read_text()
        starts = [(m.start(), m.group(1)) for m in _RULE.finditer(text)] + [(len(text), "")]
        for (start, name), (end, _) in zip(starts, starts[1:]):
            found = _RUNTIME.search(text, start, end)
            if found:
                runtimes[name] = float(found.group(1))
    return runtimes


def duration(seconds: float) -> str:
    """``45 s``, ``12 min``, ``2 h 05 min``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60:02d} min"


class Progress:
    """Reads Snakemake's log line by line (:meth:`feed`) and returns what the terminal shows."""

    def __init__(self, runtimes: dict[str, float]):
        self.runtimes = runtimes
        self.to_run: Counter = Counter()  # rule -> jobs not yet started
        self.running: dict[str, tuple[str, datetime]] = {}  # jobid -> rule, start
        self.took: dict[str, list[float]] = {}  # rule -> seconds its finished jobs took
        self.done, self.total = 0, 0
        self.started_at = self.now = None  # the first job's start, the log's latest time
        self._block: list[str] | None = None  # the job block being read
        self._stats = False  # reading the job counts
        self._blank = False  # a blank line held back

    def feed(self, line: str) -> list[str]:
        line = line.rstrip("\n")
        shown = []
        if self._block is not None:
            if line.startswith("    "):
                self._block.append(line)
                return []
            shown.append(self._job_started())
        kept = self._read(line)
        if not line.strip() and not self._stats:
            self._blank = True  # shown only before a line that is shown
            return shown
        if kept:
            shown += ([""] if self._blank else []) + kept
        self._blank = False
        return shown

    def _read(self, line: str) -> list[str]:
        """Take in one line (not of a job block); the lines it shows (none: dropped)."""
        if self._stats:
            row = _STATS_ROW.match(line)
            if row and row.group(1) == "total":
                self.total, self._stats = int(row.group(2)), False
            elif row:
                self.to_run[row.group(1)] += int(row.group(2))
            return [line]
        if line.startswith("Job stats:"):
            self._stats, self.to_run = True, Counter()
            return [line]
        stamp = _TIMESTAMP.match(line)
        if stamp:
            self.now = datetime.strptime(stamp.group(1), "%a %b %d %H:%M:%S %Y")
            return []
        if _SCHEDULER.match(line):
            return []
        if _JOB.match(line):
            self._block = [line]
            return []
        finished = _FINISHED.match(line)
        if finished:
            rule, start = self.running.pop(finished.group(1), (finished.group(2), None))
            if start is not None and self.now is not None:
                self.took.setdefault(rule, []).append((self.now - start).total_seconds())
            return []
        steps = _STEPS.match(line)
        if steps:
            self.done, self.total = int(steps.group(1)), int(steps.group(2))
            return [self.progress_line()]
        return [line]

    def close(self) -> list[str]:
        """What is left to show at the end of the log (a job block it ended on)."""
        return [self._job_started()] if self._block is not None else []

    def _job_started(self) -> str:
        block, self._block = self._block, None
        rule = _JOB.match(block[0]).group(1)
        fields = dict(entry.strip().split(": ", 1) for entry in block[1:] if ": " in entry)
        if "jobid" in fields and self.now is not None:
            self.running[fields["jobid"]] = (rule, self.now)
        declared = _JOB_RUNTIME.search(fields.get("resources", ""))
        if declared:  # a rule whose runtime is computed per job (e.g. from the case's size)
            self.runtimes.setdefault(rule, float(declared.group(1)))
        if self.to_run[rule] > 0:
            self.to_run[rule] -= 1
        if self.started_at is None:
            self.started_at = self.now
        what = f" ({fields['wildcards']})" if "wildcards" in fields else ""
        return f"[{self.now:%H:%M:%S}] {rule}{what}" if self.now else f"{rule}{what}"

    def seconds_left(self) -> float | None:
        """The estimated time to the end of the run; None before a job with a declared runtime
        has finished."""
        finished = [(rule, t) for rule, times in self.took.items() for t in times]
        declared = sum(self.runtimes.get(rule, 0.0) for rule, _ in finished)
        if not declared or self.now is None:
            return None
        scale = sum(t for _, t in finished) / declared  # seconds taken per declared minute

        def expected(rule: str) -> float:
            times = self.took.get(rule)
            return sum(times) / len(times) if times else scale * self.runtimes.get(rule, 0.0)

        running = [(rule, (self.now - start).total_seconds()) for rule, start in self.running.values()]
        work = sum(max(expected(rule) - ran, 0.0) for rule, ran in running)
        work += sum(n * expected(rule) for rule, n in self.to_run.items())
        elapsed = (self.now - self.started_at).total_seconds()
        busy = sum(t for _, t in finished) + sum(ran for _, ran in running)
        return work / max(busy / elapsed if elapsed > 0 else 1.0, 1.0)

    def progress_line(self) -> str:
        """``luckyao: 12 of 101 jobs done, 2 running, 87 left; about 4 min left``."""
        running = len(self.running)
        left = max(self.total - self.done - running, 0)
        line = f"luckyao: {self.done} of {self.total} jobs done, {running} running, {left} left"
        seconds = self.seconds_left() if self.done < self.total else None
        if seconds is None:
            return line
        rules_left = {rule for rule, _ in self.running.values()} | {rule for rule, n in self.to_run.items() if n}
        rough = any(rule not in self.took and self.runtimes.get(rule) for rule in rules_left)
        return f"{line}; about {duration(seconds)} left" + (" (rough: not every step timed yet)" if rough else "")
