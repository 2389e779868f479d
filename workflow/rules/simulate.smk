rule lgs_slopes:
    """Every WFS exposure's slopes of an LGS chain, measured once for all the AO cases that
    differ only in their AO or targets (config.slopes_spec: GLAO, LTAO, another DM, a field):
    the sensor is open loop, so their simulations replay the same slopes."""
    input:
        screens=lambda w: f"results/turbulence/{SLOPES_BY_KEY[w.skey]['screens']}.npy",
        screens_metadata=lambda w: f"results/turbulence/{SLOPES_BY_KEY[w.skey]['screens']}.nc",
        calibration=lambda w: calibration_file(SLOPES_CASES[w.skey][0]),
        code=step_sources("luckyao.steps.lgs_slopes"),
    output:
        "results/slopes/{skey}.nc",  # kept, as the screens: a temporary one made again would rerun every case replaying it
    log:
        "logs/slopes/{skey}.log",
    benchmark:
        "results/benchmarks/slopes/{skey}.tsv"
    priority: lambda w: slopes_priority(w.skey)
    threads: 1
    resources:
        mem_mb=lambda w: mem_mb(slopes_memory_bytes(CASES[SLOPES_CASES[w.skey][0]]), 3000),
        runtime=lambda w: slopes_minutes(CASES[SLOPES_CASES[w.skey][0]]),  # paper fidelity: about half an LTAO simulation
    params:
        spec=lambda w: canonical_json(SLOPES_BY_KEY[w.skey]),
        calibration=lambda w, input: ["--calibration", input.calibration] if input.calibration else [],
    shell:
        "{LUCKYAO} slopes --spec {params.spec:q} --screens {input.screens:q}"
        " --screens-metadata {input.screens_metadata:q} {params.calibration:q} --out {output:q} 2> {log:q}"


rule simulate:
    """One case's time loop: noiseless lucky frames and telemetry. An AO case replays the
    slopes of its LGS chain (rule lgs_slopes); a no-AO case takes its LGS telemetry from the
    AO case that measures the same slopes (config.lgs_twin), when the study has one: its own
    loop then only images (a third of the cost)."""
    input:
        screens=lambda w: TURBULENCE[w.case].samples_path,
        screens_metadata=lambda w: TURBULENCE[w.case].path,
        reconstructor=lambda w: [] if LGS_TWIN[w.case] else reconstructor_file(w.case),
        commands=lambda w: commands_file(w.case),
        calibration=lambda w: simulation_calibration(w.case),
        # ancient: a remade slopes product or a rerun of the twin for its AO alone changes no
        # slope; whatever does (the LGS chain's config, screens, seed, code) is this case's own
        # params and inputs too
        slopes=lambda w: ancient(slopes_file(w.case)) if SLOPES[w.case] else [],
        lgs_twin=lambda w: ancient(f"results/cases/{LGS_TWIN[w.case]}/telemetry.nc") if LGS_TWIN[w.case] else [],
        code=step_sources("luckyao.steps.simulation"),
    output:
        **frames_output("results/cases/{case}/frames.nc"),  # none with replay_frames
        telemetry="results/cases/{case}/telemetry.nc",
    log:
        "logs/simulate/{case}.log",
    benchmark:
        "results/benchmarks/simulate/{case}.tsv"
    priority: lambda w: simulate_priority(w.case)
    threads: 1
    resources:
        # paper fidelity: 2-3 GB measured (the screens are memory-mapped)
        mem_mb=lambda w: mem_mb(simulate_memory_bytes(CASES[w.case], LGS_TWIN[w.case]), 4000),
        runtime=lambda w: simulate_minutes(CASES[w.case], LGS_TWIN[w.case]),  # paper fidelity: 4-10 per target, 30 for a 7-target field
    params:
        case=lambda w: canonical_json(CASES[w.case]),
        seed=STUDY["seed"],
        products=lambda w, input: (
            (["--reconstructor", input.reconstructor] if input.reconstructor else [])
            + (["--commands", input.commands] if input.commands else [])
            + (["--calibration", input.calibration] if input.calibration else [])
            + (["--slopes", input.slopes] if input.slopes else [])
            + (["--lgs-telemetry", input.lgs_twin] if input.lgs_twin else [])
        ),
        frames=lambda w, output: ["--frames", output.frames] if "frames" in output.keys() else [],
    shell:
        "{LUCKYAO} simulate --case {params.case:q} --name {wildcards.case:q} --seed {params.seed}"
        " --screens {input.screens:q} --screens-metadata {input.screens_metadata:q}"
        " {params.products:q} {params.frames:q} --telemetry {output.telemetry:q} 2> {log:q}"
