"""The cached LGS slopes product: every WFS exposure's slopes of an LGS chain, measured once.

The sensor is open loop (it never sees the DM), so a case's slopes depend on its LGS
chain, screens and seed (``studyspec.products.slopes_spec``), not on its AO or its targets: GLAO,
LTAO, another DM or a field with the same LGS measure the same slopes. The product job
(:func:`measure_lgs_slopes`) runs the case's sensor (:func:`lgs_sensor`) over the
exposures in the time loop's order; an AO case's simulation replays them (:class:`RecordedSlopes`), which gives bit
for bit the numbers of measuring them in the loop (tested).
"""

import json

import numpy as np
import xarray as xr

from ..atmosphere.screens import ScreenSet
from ..io.datasets import open_dataset, require_finite
from ..progress import Progress
from ..studyspec.case import Case
from ..studyspec.products import lgs_chain_config
from ..wfs.geometric import GeometricLgsSensor
from ..wfs.sensor import LgsSensor
from .calibration import slope_estimator

SLOPE_DIMS = ("exposure", "beacon", "axis", "subaperture")


def lgs_sensor(case: Case, screens: ScreenSet, seed: int, calibration=None) -> LgsSensor | GeometricLgsSensor:
    """The case's LGS sensor: physical optics, its slopes calibrated by ``calibration``
    (:func:`.calibration.build_calibration`) when the case asks for it, or geometric
    (``wfs.model``), its noise the case's NEA (``Case.slope_noise_covariance_rad2``)."""
    wfs = case.wfs
    if wfs.geometric:
        shack_hartmann = case.shack_hartmann()
        return GeometricLgsSensor(
            case.lgs,
            shack_hartmann,
            wfs.exposure_steps,
            list(case.layers),
            screens,
            seed,
            case.slope_noise_covariance_rad2(shack_hartmann),
        )
    sensor = LgsSensor(
        case.lgs,
        case.shack_hartmann(),
        wfs.exposure_steps,
        list(case.layers),
        screens,
        seed,
        wfs.photons_per_subaperture,
        wfs.read_noise_e,
    )
    sensor.estimator = slope_estimator(case, sensor.wfs, sensor.elongation, calibration)
    return sensor


def measure_lgs_slopes(spec: dict, screens: ScreenSet, calibration: xr.Dataset | None) -> xr.Dataset:
    """The slopes (exposure, beacon, axis, subaperture) [rad] of a ``studyspec.products.slopes_spec``:
    its sensor (calibrated by ``calibration`` when the WFS asks for it) over every exposure
    of the case's frames, each frame's layer scales taken as the time loop takes them."""
    case = Case.from_config(spec["case"])
    sensor = lgs_sensor(case, screens, spec["seed"], calibration)
    clock = case.clock
    e = clock.exposure_steps
    slopes = None
    progress = Progress("frames", case.n_frames)
    for frame in range(case.n_frames):
        steps = clock.steps(frame)
        layer_scales = case.layer_scales(steps)
        for i in clock.exposure_offsets():
            exposure = sensor.exposure_slopes(steps[i : i + e], layer_scales[i : i + e])
            if slopes is None:
                slopes = np.empty((clock.n_exposures,) + exposure.shape, exposure.dtype)
            slopes[clock.exposure(steps[i])] = exposure
        require_finite(slopes[clock.frame_exposures(frame)], f"LGS slopes of frame {frame}", "slopes", SLOPE_DIMS)
        progress.update(frame + 1)
    return xr.Dataset(
        {
            "slopes_rad": (
                SLOPE_DIMS,
                slopes,
                {
                    "units": "rad",
                    "long_name": "tilt-removed LGS WFS slopes of each exposure (exposure_steps time steps "
                    "from exposure * exposure_steps), in the units the tomography assumes",
                },
            )
        },
        attrs={"exposure_steps": e},
    )


class RecordedSlopes:
    """An LGS sensor replayed from its slopes product: what :func:`.simulation.simulate` asks of
    a sensor (``exposure_slopes``, ``exposure_steps``, ``n_steps_max``, ``n_slopes``)."""

    def __init__(self, slopes_rad: np.ndarray, exposure_steps: int):
        self.slopes_rad, self.exposure_steps = slopes_rad, exposure_steps
        self.n_steps_max = len(slopes_rad) * exposure_steps
        self.n_slopes = slopes_rad[0].size

    @classmethod
    def open(cls, path, config: dict, seed: int) -> "RecordedSlopes":
        """The slopes product at ``path``, after checking that it measured the LGS chain of
        the case ``config`` with ``seed`` (its screens are the product's key: the workflow's)."""
        product = open_dataset(path, "LGS slopes", allow_nan=())
        spec = json.loads(product.attrs["config_json"])
        if spec["case"] != lgs_chain_config(config) or spec["seed"] != seed:
            raise ValueError(
                f"'{path}' was not measured with this case's LGS chain and seed {seed}: "
                "its slopes cannot stand for this case's"
            )
        return cls(product["slopes_rad"].values, int(product.attrs["exposure_steps"]))

    def exposure_slopes(self, steps, layer_scales) -> np.ndarray:
        """The recorded slopes (beacon, axis, subaperture) of the exposure starting at ``steps[0]``."""
        if len(steps) != self.exposure_steps or steps[0] % self.exposure_steps:
            raise ValueError(f"an exposure is {self.exposure_steps} steps from a multiple of them, got {list(steps)}")
        return self.slopes_rad[int(steps[0]) // self.exposure_steps]
