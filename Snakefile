# luckyao: every figure of the study from one command.
#   snakemake                                    # the default (quick) study, config/config.yaml
#   snakemake --configfile config/paper.yaml     # paper fidelity: an overlay of what differs
# The study config is validated (src/luckyao/studyspec/schema.yaml) before any job runs.

# Every config file read strictly before Snakemake reads it (studyspec/yamlfile.py): YAML alias
# bombs, duplicate keys and a top level that is not a mapping refused, naming the file.
# (A mapping alias bomb given with --configfile is merged by Snakemake's own command line before
# this file is read: `bash run.sh study` and `luckyao check` refuse it first.)
import os
import sys

from luckyao.studyspec.overrides import typed as _typed
from luckyao.studyspec.schema import ConfigError as _ConfigError
from luckyao.studyspec.schema import deep_merge as _deep_merge
from luckyao.studyspec.yamlfile import read_config_file as _read_config_file

try:
    OVERLAYS = [_read_config_file(_path) for _path in workflow.overwrite_configfiles if os.path.exists(_path)]
    if os.path.exists("config/config.yaml"):
        _read_config_file("config/config.yaml")
except _ConfigError as _err:
    sys.exit(f"luckyao: invalid study config: {_err}")


configfile: "config/config.yaml"


# --config values typed as YAML types them (Snakemake gives nested ones as strings: '0.5')
config.update(_deep_merge(config, _typed(dict(workflow.config_settings.config))))


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/turbulence.smk"
include: "workflow/rules/reconstructor.smk"
include: "workflow/rules/calibration.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/learned.smk"
include: "workflow/rules/lucky.smk"
include: "workflow/rules/figures.smk"


# The default target: every figure, and the FITS images of the cases they draw; or, when the
# overlays (--configfile, --config) only add cases, those cases alone (studyspec.overrides).
rule all:
    default_target: True
    input:
        []
        if ADDED_CASES
        else expand("figures/{fig}.{ext}", fig=list(STUDY["figures"]), ext=["pdf", "png", "html", "nc"]),
        expand("fits/{case}.fits", case=ADDED_CASES or DRAWN_CASES),
        # what the cases keep, so that one set aside or deleted is remade (kept_files)
        sorted({path for case in ADDED_CASES or DRAWN_CASES for path in kept_files(case)}),
