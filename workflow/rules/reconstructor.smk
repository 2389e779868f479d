rule reconstructor:
    """MAP tomographic reconstructors, shared by every case with the same geometry and prior."""
    input:
        code=step_sources("luckyao.steps.reconstructor"),
    output:
        "results/reconstructors/{rkey}.nc",
    log:
        "logs/reconstructor/{rkey}.log",
    benchmark:
        "results/benchmarks/reconstructor/{rkey}.tsv"
    priority: 10  # seconds each, before the screens: every AO simulation waits for them
    threads: 1
    resources:
        # at most 1.1 GB measured
        mem_mb=lambda w: mem_mb(reconstructor_memory_bytes(RECONSTRUCTOR_BY_KEY[w.rkey]), 1500),
        runtime=5,  # minutes; at most 1 measured
    params:
        spec=lambda w: canonical_json(RECONSTRUCTOR_BY_KEY[w.rkey]),
    shell:
        "{LUCKYAO} reconstructor --spec {params.spec:q} --out {output:q} 2> {log:q}"


rule commands:
    """AO command matrices (LTAO or GLAO) and DM slopes, shared by every case with the same system."""
    input:
        code=step_sources("luckyao.steps.reconstructor"),
    output:
        "results/commands/{ckey}.nc",
    log:
        "logs/commands/{ckey}.log",
    benchmark:
        "results/benchmarks/commands/{ckey}.tsv"
    priority: 10  # seconds each, before the screens: every AO simulation waits for them
    threads: 1
    resources:
        # at most 1.1 GB measured (32x32 WFS)
        mem_mb=lambda w: mem_mb(commands_memory_bytes(COMMANDS_BY_KEY[w.ckey]), 1500),
        runtime=5,  # minutes; at most 1 measured
    params:
        spec=lambda w: canonical_json(COMMANDS_BY_KEY[w.ckey]),
    shell:
        "{LUCKYAO} commands --spec {params.spec:q} --out {output:q} 2> {log:q}"
