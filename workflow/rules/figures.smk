# Figures and FITS images are short jobs: on a cluster they run beside Snakemake itself
# instead of each queueing through sbatch.
localrules: figure, export, all_cases


def figure_settings_file(fig):
    """The file that carries a figure's settings (its config, its cases' resolved configs, the
    seed) to its job, so that they are not a (report-visible, very long) parameter. Named by
    their hash and written here, while the workflow is parsed, when missing: new settings are
    a new input, so the figure is redrawn exactly when they change; a file is never
    rewritten, so a dry run of another config cannot change one a live run reads; and no job
    is spent on it (a rule with a run directive costs a Snakemake start-up, ~6 s, each)."""
    settings = figure_settings(fig)
    path = f"results/figures/settings/{fig}_{sha256(settings)[:12]}.json"
    if not os.path.exists(path):
        with atomic_path(path) as partial:
            partial.write_text(canonical_json(settings))
    return path


FIGURE_SETTINGS = {fig: figure_settings_file(fig) for fig in STUDY["figures"]}


rule figure:
    """One figure and the tidy dataset it is drawn from."""
    input:
        settings=lambda w: FIGURE_SETTINGS[w.fig],
        lucky=lambda w: figure_inputs(w.fig),
        code=step_sources("luckyao.figures"),
    output:
        pdf="figures/{fig}.pdf",
        png="figures/{fig}.png",
        page=report(  # the PNG in a page: the report opens it at the window's width
            "figures/{fig}.html",
            caption="../report/figure.rst",
            category="Figures",
            labels=lambda w, output: figure_report_labels(w.fig, output.data),
        ),
        data="figures/{fig}.nc",
    params:
        prefix=lambda w: f"figures/{w.fig}",
        caption=lambda w: figure_caption_rst(w.fig),  # short, escaped: the report's caption
    threads: 1
    resources:
        mem_mb=1500,  # at most 1 GB measured
        runtime=5,  # minutes; at most 2 measured
    log:
        "logs/figures/{fig}.log",
    shell:
        "{LUCKYAO} figure --id {wildcards.fig:q} --settings-file {input.settings:q}"
        " --out-prefix {params.prefix:q} {input.lucky:q} 2> {log:q}"


rule export:
    """A case's integrated and long-exposure images as FITS (one image extension each)."""
    input:
        lucky="results/cases/{case}/lucky.nc",
        code=step_sources("luckyao.io.fits"),
    output:
        "fits/{case}.fits",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    log:
        "logs/export/{case}.log",
    shell:
        "{LUCKYAO} export {input.lucky:q} --out {output:q} 2> {log:q}"


rule all_cases:
    """Every case of the study, those no figure shows too, with its FITS images."""
    input:
        expand("fits/{case}.fits", case=list(CASES)),
        sorted({path for case in CASES for path in kept_files(case)}),  # one set aside is remade
