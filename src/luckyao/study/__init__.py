"""The study around the physics: typed config, the time loop, cached products, datasets,
figures and the command line the workflow calls.

Public objects, by module --
config: load_study, ConfigError; case: Case; simulation: simulate; turbulence / reconstructor:
the cached products; postprocess: lucky_case; figures: draw_figure; cli: main.
"""
