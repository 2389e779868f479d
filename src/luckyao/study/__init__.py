"""The study around the physics: typed config, the time loop, cached products, datasets,
figures and the command line the workflow calls."""

from ..exports import lazy_exports

EXPORTS = {
    "config": ("load_study", "ConfigError"),
    "case": ("Case",),
    "lucky_settings": ("LuckySettings",),
    "simulation": ("simulate", "Replay"),
    "turbulence": ("write_screens", "read_screens"),
    "postprocess": ("lucky_case",),
    "figures": ("draw_figure",),
    "cli": ("main",),
}
"""Public objects, by module (imported on first use: :mod:`luckyao.exports`)."""

__all__, __getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
