# Study config, validated once at the edge; lookups the rules share. No physics here.
import re
import sys

from luckyao.study.code_deps import step_sources
from luckyao.study.config import (ConfigError, canonical_json, commands_key, commands_spec, lucky_settings,
                                  reconstructor_key, reconstructor_spec, sweep_detectors, turbulence_key,
                                  turbulence_spec, validate_study)

try:
    CASES = validate_study(config)
except ConfigError as err:
    sys.exit("\n".join(f"luckyao: invalid study config: {problem}" for problem in str(err).splitlines()))
STUDY = config

TURBULENCE = {name: turbulence_spec(STUDY, case) for name, case in CASES.items()}
TURBULENCE_BY_KEY = {turbulence_key(spec): spec for spec in TURBULENCE.values()}
RECONSTRUCTOR = {name: reconstructor_spec(case) for name, case in CASES.items()}
RECONSTRUCTOR_BY_KEY = {reconstructor_key(s): s for s in RECONSTRUCTOR.values() if s is not None}
COMMANDS = {name: commands_spec(case) for name, case in CASES.items()}
COMMANDS_BY_KEY = {commands_key(s): s for s in COMMANDS.values() if s is not None}
LUCKYAO = f"OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1 {sys.executable} -m luckyao"


def reconstructor_file(case):
    """The case's cached reconstructor file, or [] without LGS."""
    spec = RECONSTRUCTOR[case]
    return f"results/reconstructors/{reconstructor_key(spec)}.nc" if spec else []


def commands_file(case):
    """The case's cached AO command-matrix file, or [] without AO."""
    spec = COMMANDS[case]
    return f"results/commands/{commands_key(spec)}.nc" if spec else []


def frames_output(path):
    return path if STUDY.get("keep_frames", False) else temp(path)


wildcard_constraints:
    case="|".join(re.escape(c) for c in CASES),
    key="screens_[0-9a-f]{12}",
    rkey="reconstructor_[0-9a-f]{12}",
    ckey="commands_[0-9a-f]{12}",
    fig="|".join(re.escape(f) for f in STUDY["figures"]),
