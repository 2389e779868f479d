rule turbulence:
    """Normalised phase screens shared by every case with the same turbulence spec."""
    input:
        code=step_sources("luckyao.steps.screens"),
    output:
        screens="results/turbulence/{key}.npy",
        metadata="results/turbulence/{key}.nc",
    log:
        "logs/turbulence/{key}.log",
    benchmark:
        "results/benchmarks/turbulence/{key}.tsv"
    priority: lambda w: screens_priority(w.key)  # the longest chains of work first
    threads: lambda w: screens_threads(w.key)  # 2 for a study's only screens job, else 1
    resources:
        mem_mb=lambda w: mem_mb(turbulence_memory_bytes(TURBULENCE_BY_KEY[w.key], screens_threads(w.key))),  # paper fidelity: 15800
        runtime=lambda w: screens_minutes(TURBULENCE_BY_KEY[w.key], screens_threads(w.key)),  # paper fidelity: 5 measured
    params:
        spec=lambda w: canonical_json(TURBULENCE_BY_KEY[w.key]),
    shell:
        "{LUCKYAO} turbulence --spec {params.spec:q} --screens {output.screens:q}"
        " --metadata {output.metadata:q} --threads {threads} 2> {log:q}"
