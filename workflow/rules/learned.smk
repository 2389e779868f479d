rule simulate_training:
    """A case's training twin (ao.learned_training_seed): its time loop with the training seed,
    on its own screens, LGS slopes and layer strengths, imaging nothing: the telemetry its learned criterion
    is fitted on (no frame the criterion scores is seen in training)."""
    input:
        screens=lambda w: TRAINING[w.case].screens.samples_path,
        screens_metadata=lambda w: TRAINING[w.case].screens.path,
        reconstructor=lambda w: reconstructor_file(w.case),
        commands=lambda w: commands_file(w.case),
        calibration=lambda w: simulation_calibration(w.case),
        slopes=lambda w: TRAINING[w.case].slopes.path,
        code=step_sources("luckyao.steps.simulation"),
    output:
        "results/training/{case}/telemetry.nc",
    log:
        "logs/simulate_training/{case}.log",
    benchmark:
        "results/benchmarks/simulate_training/{case}.tsv"
    priority: lambda w: simulate_priority(w.case)
    threads: 1
    resources:
        mem_mb=lambda w: mem_mb(simulate_memory_bytes(CASES[w.case]), 4000),
        runtime=lambda w: simulate_minutes(CASES[w.case]),  # an upper bound: it images nothing
    params:
        case=lambda w: canonical_json(TRAINING[w.case].config),
        seed=lambda w: TRAINING[w.case].seed,
        calibration=lambda w, input: ["--calibration", input.calibration] if input.calibration else [],
    shell:
        "{LUCKYAO} simulate --case {params.case:q} --name {wildcards.case:q}.training --seed {params.seed}"
        " --screens {input.screens:q} --screens-metadata {input.screens_metadata:q}"
        " --reconstructor {input.reconstructor:q} --commands {input.commands:q} --slopes {input.slopes:q}"
        " {params.calibration:q} --telemetry {output:q} 2> {log:q}"


rule learned_model:
    """The learned criterion of a case: a ridge regression of the frame's true rms on its laser
    telemetry, fitted on the training twin's (steps/learned.py), read by the case's lucky job."""
    input:
        telemetry="results/training/{case}/telemetry.nc",
        code=step_sources("luckyao.steps.learned"),
    output:
        "results/training/{case}/learned.nc",
    log:
        "logs/learned/{case}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,  # minutes
    shell:
        "{LUCKYAO} learn --telemetry {input.telemetry:q} --out {output:q} 2> {log:q}"
