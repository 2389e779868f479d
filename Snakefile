# luckyao: every figure of the study from one command.
#   snakemake                                    # the default (quick) study, config/config.yaml
#   snakemake --configfile config/paper.yaml     # paper fidelity: an overlay of what differs
# The study config is validated (src/luckyao/study/config.schema.yaml) before any job runs.

configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/turbulence.smk"
include: "workflow/rules/reconstructor.smk"
include: "workflow/rules/calibration.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/lucky.smk"
include: "workflow/rules/figures.smk"


rule all:
    input:
        expand("figures/{fig}.{ext}", fig=list(STUDY["figures"]), ext=["pdf", "png", "html", "nc"]),
        expand("fits/{case}.fits", case=DRAWN_CASES),
        # what the drawn cases keep, so that one set aside or deleted is remade (kept_files)
        sorted({path for case in DRAWN_CASES for path in kept_files(case)}),
    default_target: True
