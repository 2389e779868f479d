"""Hooks of the gallery build (named by string in ``conf.py``, so the config stays picklable)."""

from pathlib import Path

OUTPUT = Path(__file__).resolve().parents[1] / "_build" / "gallery-output"


def reset_argv(gallery_conf, script_vars):
    """An example's command-line arguments: its output folder, in the build folder (the
    tutorial's ``OUT_DIR``), so that no example writes into the source tree."""
    return [str(OUTPUT / Path(script_vars["src_file"]).stem)]
