"""The rules' lint: ``snakemake --lint``, failing on any lint but the two the workflow keeps by
design (docs/user-guide/running.md, "Report and lint"): no conda environment or container (the
environment is the ``.venv`` that ``run.sh`` builds, pinned by ``requirements.lock``), and the
``LUCKYAO`` command prefix used from outside the rules (a parameter would rerun the study when
the checkout moves). Usage: python tools/lint_rules.py (from the checkout)."""

import re
import subprocess
import sys

KEPT = (
    "Specify a conda environment or container for each rule.",
    "Shell command directly uses variable LUCKYAO from outside of the rule",
)

done = subprocess.run([sys.executable, "-m", "snakemake", "--lint", "--cores", "1"], capture_output=True, text=True)
lints = re.findall(r"^    \* (.+?):?$", done.stdout + done.stderr, flags=re.M)
if not lints and done.returncode:
    sys.exit(f"snakemake --lint failed:\n{done.stderr[-3000:]}")
unexpected = sorted({lint for lint in lints if not lint.startswith(KEPT)})
for lint in unexpected:
    print(f"snakemake --lint: {lint}", file=sys.stderr)
kept = sum(lint.startswith(KEPT) for lint in lints)
print(f"snakemake --lint: {kept} of {len(lints)} lints kept by design, {len(unexpected)} kinds to fix")
sys.exit(1 if unexpected else 0)
