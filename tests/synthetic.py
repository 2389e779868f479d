"""Synthetic lucky datasets for the figure tests: the variables a figure reads from a lucky.nc."""

import numpy as np
import xarray as xr

CRITERIA, FRACTIONS = ["strehl", "lgs_rms"], [0.01, 0.1, 1.0]


def lucky_dataset(value: float, n_blocks: int, **per_frame) -> xr.Dataset:
    """Strehl, FWHM and d50 all ``value`` (errors 0.01) for one target, the criteria
    :data:`CRITERIA`, the fractions :data:`FRACTIONS` and the noiseless detector; ``n_blocks``
    time blocks; ``per_frame``: per-frame variables (``frame_strehl`` gets a target and a detector)."""
    dims = ("target", "criterion", "fraction", "detector")
    shape = (1, len(CRITERIA), len(FRACTIONS), 1)
    data = {}
    for metric in ("strehl", "fwhm_arcsec", "d50_arcsec"):
        data[metric] = (dims, np.full(shape, value), {"units": "1", "long_name": metric})
        data[f"{metric}_error"] = (dims, np.full(shape, 0.01), {"units": "1", "long_name": "error"})
    for name, values in per_frame.items():
        data[name] = (
            (("target", "detector", "frame"), values[None, None, :]) if name == "frame_strehl" else (("frame",), values)
        )
    data["strehl_block"] = (("block",), np.zeros(n_blocks))
    n_frames = len(per_frame.get("frame_strehl", [])) or 100
    data["n_frames_selected"] = (("fraction",), [max(1, round(f * n_frames)) for f in FRACTIONS])
    return xr.Dataset(data, coords={"criterion": CRITERIA, "fraction": FRACTIONS, "detector": ["noiseless"]})
