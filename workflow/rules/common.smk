# Study config, validated once; lookups the rules share. No physics here.
import os
import re
import sys

from luckyao.config import (ConfigError, canonical_json, load_study, lucky_settings,
                            reconstructor_key, reconstructor_spec, turbulence_key, turbulence_spec)

STUDY_FILE = config.get("study", "config/config.yaml")
try:
    STUDY, CASES = load_study(STUDY_FILE)
except ConfigError as err:
    sys.exit(f"luckyao: invalid study config {STUDY_FILE}: {err}")

TURBULENCE = {name: turbulence_spec(STUDY, case) for name, case in CASES.items()}
TURBULENCE_BY_KEY = {turbulence_key(spec): spec for spec in TURBULENCE.values()}
RECONSTRUCTOR = {name: reconstructor_spec(case) for name, case in CASES.items()}
RECONSTRUCTOR_BY_KEY = {reconstructor_key(s): s for s in RECONSTRUCTOR.values() if s is not None}
LUCKYAO = f"OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1 {sys.executable} -m luckyao.cli"


def src(*modules):
    """Source files a rule's output depends on: an edit reruns exactly those jobs."""
    return [os.path.join(workflow.basedir, "src", "luckyao", f"{m}.py") for m in modules]


def reconstructor_file(case):
    """The case's cached reconstructor file, or [] without LGS."""
    spec = RECONSTRUCTOR[case]
    return f"results/reconstructors/{reconstructor_key(spec)}.nc" if spec else []


def frames_output(path):
    return path if STUDY.get("keep_frames", False) else temp(path)


wildcard_constraints:
    case="|".join(re.escape(c) for c in CASES),
    key="screens_[0-9a-f]{12}",
    rkey="reconstructor_[0-9a-f]{12}",
    fig="|".join(re.escape(f) for f in STUDY["figures"]),
