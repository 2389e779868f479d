rule reconstructor:
    """MAP tomographic reconstructors, shared by every case with the same geometry and prior."""
    input:
        code=src("reconstructor", "tomography", "wfs", "lgs", "pupil"),
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
