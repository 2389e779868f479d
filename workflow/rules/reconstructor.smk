rule reconstructor:
    """MAP tomographic reconstructors, shared by every case with the same geometry and prior."""
    input:
        code=step_sources("reconstructor"),
    output:
        "results/reconstructors/{rkey}.nc",
    params:
        spec=lambda w: canonical_json(RECONSTRUCTOR_BY_KEY[w.rkey]),
    log:
        "logs/reconstructor/{rkey}.log",
    benchmark:
        "results/benchmarks/reconstructor/{rkey}.tsv"
    shell:
        "{LUCKYAO} reconstructor --spec {params.spec:q} --out {output} 2> {log}"


rule commands:
    """AO command matrices (LTAO or GLAO) and DM slopes, shared by every case with the same system."""
    input:
        code=step_sources("reconstructor"),
    output:
        "results/commands/{ckey}.nc",
    params:
        spec=lambda w: canonical_json(COMMANDS_BY_KEY[w.ckey]),
    log:
        "logs/commands/{ckey}.log",
    benchmark:
        "results/benchmarks/commands/{ckey}.tsv"
    shell:
        "{LUCKYAO} commands --spec {params.spec:q} --out {output} 2> {log}"
