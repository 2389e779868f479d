rule lucky:
    """Detector noise, frame selection, shift-and-add and scores for one case."""
    input:
        frames="results/cases/{case}/frames.nc",
        telemetry="results/cases/{case}/telemetry.nc",
        code=step_sources("postprocess"),
    output:
        "results/cases/{case}/lucky.nc",
    params:
        settings=lambda w: canonical_json(lucky_settings(STUDY, CASES, w.case)),
    log:
        "logs/lucky/{case}.log",
    benchmark:
        "results/benchmarks/lucky/{case}.tsv"
    shell:
        "{LUCKYAO} lucky --settings {params.settings:q} --frames {input.frames}"
        " --telemetry {input.telemetry} --out {output} 2> {log}"
