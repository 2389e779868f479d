rule turbulence:
    """Normalised phase screens shared by every case with the same turbulence spec."""
    input:
        code=step_sources("turbulence"),
    output:
        screens="results/turbulence/{key}.npy",
        metadata="results/turbulence/{key}.nc",
    params:
        spec=lambda w: canonical_json(TURBULENCE_BY_KEY[w.key]),
    threads: 2  # two layers at once (independent draws: the same screens for any number)
    resources:
        mem_mb=16000,  # paper fidelity: 12 bytes per sample of the two largest layers, 11.8 GB
        runtime=15,  # minutes; paper fidelity: 5 measured
    log:
        "logs/turbulence/{key}.log",
    benchmark:
        "results/benchmarks/turbulence/{key}.tsv"
    shell:
        "{LUCKYAO} turbulence --spec {params.spec:q} --screens {output.screens:q}"
        " --metadata {output.metadata:q} --threads {threads} 2> {log:q}"
