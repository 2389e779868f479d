rule lucky:
    """Detector noise, frame selection, shift-and-add and scores for one case."""
    input:
        frames=lambda w: [] if REPLAY_FRAMES else f"results/cases/{w.case}/frames.nc",
        telemetry="results/cases/{case}/telemetry.nc",
        replay=lambda w: replay_screens(w.case),
        learned=lambda w: learned_file(w.case),
        code=step_sources("luckyao.steps.postprocess"),
    output:
        "results/cases/{case}/lucky.nc",
    log:
        "logs/lucky/{case}.log",
    benchmark:
        "results/benchmarks/lucky/{case}.tsv"
    priority: 10  # a finished simulation's frame cube is post-processed (and, if temporary, deleted) first
    threads: 1
    resources:
        mem_mb=lambda w: lucky_mem_mb(w.case),
        runtime=lambda w: lucky_minutes(VIEW.cases[w.case].lucky_settings),  # paper fidelity: up to 15 measured
    params:
        settings=lambda w: canonical_json(VIEW.cases[w.case].lucky_settings),
        frames=lambda w, input: ["--frames", input.frames] if input.frames else [],
        replay=lambda w, input: (
            ["--screens", input.replay[0], "--screens-metadata", input.replay[1]] if input.replay else []
        ),
        learned=lambda w, input: ["--learned-model", input.learned] if input.learned else [],
    shell:
        "{LUCKYAO} lucky --settings {params.settings:q} {params.frames:q}"
        " --telemetry {input.telemetry:q} --out {output:q} {params.replay:q} {params.learned:q} 2> {log:q}"
