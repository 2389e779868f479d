rule simulate:
    """One case's time loop: noiseless lucky frames and telemetry."""
    input:
        screens=lambda w: f"results/turbulence/{turbulence_key(TURBULENCE[w.case])}.npy",
        screens_metadata=lambda w: f"results/turbulence/{turbulence_key(TURBULENCE[w.case])}.nc",
        reconstructor=lambda w: reconstructor_file(w.case),
        commands=lambda w: commands_file(w.case),
        code=step_sources("simulation"),
    output:
        frames=frames_output("results/cases/{case}/frames.nc"),
        telemetry="results/cases/{case}/telemetry.nc",
    params:
        case=lambda w: canonical_json(CASES[w.case]),
        seed=STUDY["seed"],
    log:
        "logs/simulate/{case}.log",
    benchmark:
        "results/benchmarks/simulate/{case}.tsv"
    shell:
        "{LUCKYAO} simulate --case {params.case:q} --name {wildcards.case:q} --seed {params.seed}"
        " --screens {input.screens} --screens-metadata {input.screens_metadata}"
        " --reconstructor '{input.reconstructor}' --commands '{input.commands}'"
        " --frames {output.frames} --telemetry {output.telemetry} 2> {log}"
