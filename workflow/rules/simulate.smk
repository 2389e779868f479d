rule simulate:
    """One case's time loop: noiseless lucky frames and telemetry."""
    input:
        screens=lambda w: f"results/turbulence/{turbulence_key(TURBULENCE[w.case])}.npy",
        screens_metadata=lambda w: f"results/turbulence/{turbulence_key(TURBULENCE[w.case])}.nc",
        reconstructor=lambda w: reconstructor_file(w.case),
        commands=lambda w: commands_file(w.case),
        calibration=lambda w: calibration_file(w.case),
        code=step_sources("simulation"),
    output:
        frames=frames_output("results/cases/{case}/frames.nc"),
        telemetry="results/cases/{case}/telemetry.nc",
    params:
        case=lambda w: canonical_json(CASES[w.case]),
        seed=STUDY["seed"],
        products=lambda w, input: ((["--reconstructor", input.reconstructor] if input.reconstructor else [])
                                   + (["--commands", input.commands] if input.commands else [])
                                   + (["--calibration", input.calibration] if input.calibration else [])),
    threads: 1
    priority: lambda w: simulate_priority(w.case)
    resources:
        # paper fidelity: 2-3 GB measured (the screens are memory-mapped)
        mem_mb=lambda w: mem_mb(simulate_memory_bytes(CASES[w.case]), 4000),
        runtime=60,  # minutes; paper fidelity: 4-10 per target, up to 30 for a 7-target field case
    log:
        "logs/simulate/{case}.log",
    benchmark:
        "results/benchmarks/simulate/{case}.tsv"
    shell:
        "{LUCKYAO} simulate --case {params.case:q} --name {wildcards.case:q} --seed {params.seed}"
        " --screens {input.screens:q} --screens-metadata {input.screens_metadata:q}"
        " {params.products:q} --frames {output.frames:q} --telemetry {output.telemetry:q} 2> {log:q}"
