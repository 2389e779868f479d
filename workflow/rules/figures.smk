rule figure:
    """One figure and the tidy dataset it is drawn from."""
    input:
        lucky=lambda w: [f"results/cases/{c}/lucky.nc" for c in STUDY["figures"][w.fig]["cases"]],
        code=src("figures", "analytic"),
    output:
        pdf="figures/{fig}.pdf",
        png="figures/{fig}.png",
        data="figures/{fig}.nc",
    params:
        settings=lambda w: canonical_json(STUDY["figures"][w.fig]),
    log:
        "logs/figures/{fig}.log",
    shell:
        "{LUCKYAO} figure --id {wildcards.fig:q} --settings {params.settings:q}"
        " --out-prefix figures/{wildcards.fig} {input.lucky} 2> {log}"
