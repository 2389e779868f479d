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
    threads: 1
    priority: lambda w: simulate_priority(w.case)
    resources:
        mem_mb=4000,  # paper fidelity: 2-3 GB measured (the screens are memory-mapped)
        runtime=60,  # minutes; paper fidelity: 4-10 per target, up to 30 for a 7-target field case
    log:
        "logs/simulate/{case}.log",
    benchmark:
        "results/benchmarks/simulate/{case}.tsv"
    shell:
        "{LUCKYAO} simulate --case {params.case:q} --name {wildcards.case:q} --seed {params.seed}"
        " --screens {input.screens} --screens-metadata {input.screens_metadata}"
        " --reconstructor '{input.reconstructor}' --commands '{input.commands}' --calibration '{input.calibration}'"
        " --frames {output.frames} --telemetry {output.telemetry} 2> {log}"
