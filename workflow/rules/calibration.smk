rule calibration:
    """The WFS slope response (push-pull dithers through the sensor model), shared by every
    case with the same sensor, estimator and mean seeing."""
    input:
        code=step_sources("luckyao.steps.calibration"),
    output:
        "results/calibrations/{wkey}.nc",
    log:
        "logs/calibration/{wkey}.log",
    benchmark:
        "results/benchmarks/calibration/{wkey}.tsv"
    priority: 10  # before the screens: the simulations that use it wait for it
    threads: 1
    resources:
        mem_mb=lambda w: mem_mb(calibration_memory_bytes(CALIBRATION_BY_KEY[w.wkey]), margin=1.0),
        runtime=lambda w: calibration_minutes(CALIBRATION_BY_KEY[w.wkey]),  # minutes; at least 5
    params:
        spec=lambda w: canonical_json(CALIBRATION_BY_KEY[w.wkey]),
    shell:
        "{LUCKYAO} calibration --spec {params.spec:q} --out {output:q} 2> {log:q}"
