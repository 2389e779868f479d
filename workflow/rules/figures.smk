rule figure:
    """One figure and the tidy dataset it is drawn from."""
    input:
        lucky=lambda w: figure_inputs(w.fig),
        code=step_sources("figures"),
    output:
        pdf="figures/{fig}.pdf",
        png="figures/{fig}.png",
        data="figures/{fig}.nc",
    params:
        settings=lambda w: canonical_json(figure_settings(w.fig)),
    log:
        "logs/figures/{fig}.log",
    shell:
        "{LUCKYAO} figure --id {wildcards.fig:q} --settings {params.settings:q}"
        " --out-prefix figures/{wildcards.fig} {input.lucky} 2> {log}"


def figure_settings(fig):
    """The figure's config, its cases' resolved configs, the seed, and the detector sweep."""
    figure = STUDY["figures"][fig]
    sweep = {"sweep_detectors": sweep_detectors(STUDY["lucky"])} if figure["kind"] == "quality_vs_signal" else {}
    return {**figure, "seed": STUDY["seed"], "case_configs": {c: CASES[c] for c in figure["cases"]}, **sweep}


def figure_inputs(fig):
    """The cases' lucky datasets; none for the geometry-only asterism figure."""
    figure = STUDY["figures"][fig]
    if figure["kind"] == "asterism":
        return []
    return [f"results/cases/{c}/lucky.nc" for c in figure["cases"]]
