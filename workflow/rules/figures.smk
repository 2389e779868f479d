rule figure:
    """One figure and the tidy dataset it is drawn from."""
    input:
        lucky=lambda w: figure_inputs(w.fig),
        code=step_sources("figures"),
    output:
        pdf="figures/{fig}.pdf",
        png=report(
            "figures/{fig}.png",
            caption="../report/figure.rst",
            category="Figures",
            labels=lambda w, output: figure_report_labels(w.fig, output.data),
        ),
        data="figures/{fig}.nc",
    params:
        settings=lambda w: canonical_json(figure_settings(w.fig)),
        prefix=lambda w: f"figures/{w.fig}",
    threads: 1
    resources:
        mem_mb=1500,  # at most 1 GB measured
        runtime=5,  # minutes; at most 2 measured
    log:
        "logs/figures/{fig}.log",
    shell:
        "{LUCKYAO} figure --id {wildcards.fig:q} --settings {params.settings:q}"
        " --out-prefix {params.prefix:q} {input.lucky:q} 2> {log:q}"

