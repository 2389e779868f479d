# Figures and FITS images are short jobs: on a cluster they run beside Snakemake itself
# instead of each queueing through sbatch.
localrules:
    figure,
    export,
    all_cases,


rule figure:
    """One figure and the tidy dataset it is drawn from."""
    input:
        settings=lambda w: FIGURE_SETTINGS[w.fig],
        lucky=lambda w: figure_inputs(w.fig),
        # a figure asked for alone exports its cases' FITS too; ancient: a new export never redraws it
        fits=lambda w: [ancient(f"fits/{case}.fits") for case in figure_cases(w.fig)],
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
    log:
        "logs/figures/{fig}.log",
    threads: 1
    resources:
        mem_mb=1500,  # at most 1 GB measured
        runtime=5,  # minutes; at most 2 measured
    params:
        prefix=lambda w: f"figures/{w.fig}",
        caption=lambda w: figure_caption_rst(w.fig),  # short, escaped: the report's caption
    shell:
        "{LUCKYAO} figure --id {wildcards.fig:q} --settings-file {input.settings:q}"
        " --out-prefix {params.prefix:q} {input.lucky:q} 2> {log:q}"


rule export:
    """A case's integrated and long-exposure images as FITS (an image extension each, an INDEX table)."""
    input:
        lucky="results/cases/{case}/lucky.nc",
        code=step_sources("luckyao.io.fits"),
    output:
        "fits/{case}.fits",
    log:
        "logs/export/{case}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    shell:
        "{LUCKYAO} export {input.lucky:q} --out {output:q} 2> {log:q}"


rule all_cases:
    """Every case of the study, those no figure shows too, with its FITS images."""
    input:
        expand("fits/{case}.fits", case=list(CASES)),
        sorted({path for case in CASES for path in kept_files(case)}),  # one set aside is remade
