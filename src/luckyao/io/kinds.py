"""What kind of luckyao dataset a file holds, from the title every dataset carries
(``io.datasets.provenance``), so that a command given the wrong file says what it expected
and what it got instead of failing on a missing variable."""

import xarray as xr

KINDS = (
    ("luckyao lucky imaging of case ", "a case's lucky-imaging results (results/cases/<case>/lucky.nc)"),
    ("luckyao telemetry of case ", "a case's telemetry (results/cases/<case>/telemetry.nc)"),
    ("luckyao frames of case ", "a case's frame cube (results/cases/<case>/frames.nc)"),
    ("luckyao figure ", "a figure's data (figures/<id>.nc)"),
    ("luckyao normalised phase screens", "phase screens' metadata (results/turbulence/)"),
    ("luckyao tomographic reconstructors", "tomographic reconstructors (results/reconstructors/)"),
    ("luckyao AO command matrix", "an AO command matrix (results/commands/)"),
    ("luckyao LGS slopes", "an LGS slopes product (results/slopes/)"),
    ("luckyao WFS slope-response calibration", "a WFS calibration (results/calibrations/)"),
)
"""(title prefix, what the dataset is) of every kind of dataset the workflow writes."""


def dataset_kind(ds: xr.Dataset) -> str:
    """What ``ds`` is, in words (from its ``title``)."""
    title = str(ds.attrs.get("title", ""))
    for prefix, what in KINDS:
        if title.startswith(prefix):
            return what
    return f"a dataset titled {title!r}, not one luckyao writes" if title else "a dataset with no luckyao title"


def require_kind(ds: xr.Dataset, prefix: str, where: str) -> None:
    """A ValueError naming ``where`` (the file or call), the kind expected (the title
    ``prefix`` of :data:`KINDS`) and the kind ``ds`` is, unless its title starts with ``prefix``."""
    if not str(ds.attrs.get("title", "")).startswith(prefix):
        expected = dict(KINDS)[prefix]
        raise ValueError(f"{where}: expected {expected}, got {dataset_kind(ds)}")
