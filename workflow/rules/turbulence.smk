rule turbulence:
    """Normalised phase screens shared by every case with the same turbulence spec."""
    input:
        code=step_sources("turbulence"),
    output:
        screens="results/turbulence/{key}.npy",
        metadata="results/turbulence/{key}.nc",
    params:
        spec=lambda w: canonical_json(TURBULENCE_BY_KEY[w.key]),
    threads: 1
    resources:
        mem_mb=16000,  # paper fidelity: 12.8 GB measured
        runtime=15,  # minutes; paper fidelity: 5 measured
    log:
        "logs/turbulence/{key}.log",
    benchmark:
        "results/benchmarks/turbulence/{key}.tsv"
    shell:
        "{LUCKYAO} turbulence --spec {params.spec:q} --screens {output.screens}"
        " --metadata {output.metadata} 2> {log}"
