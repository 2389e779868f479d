"""A case's size-dependent keys, derived from its telescope's diameter (telescope size as a study axis).

A case that leaves out one of :data:`DERIVED_KEYS` gets it from ``telescope.diameter_m`` ``D``,
at a constant sub-aperture pitch (:func:`derive_size_defaults`, applied to every merged case by
``studyspec.study.validate_study``, so the resolved config holds the values and nothing downstream knows
they were derived):

- ``wfs.n_subapertures = round(D / p)``, ``p = telescope.subaperture_pitch_m`` (0.525 m: 8x8 on 4.2 m);
- ``ao.n_actuators = round(D / p) + 1`` (Fried geometry with that sensor);
- ``telescope.obscuration_m = r D`` to the millimetre, ``r = telescope.obscuration_ratio``
  (2/7: 1.2 m on 4.2 m);
- ``camera.n_pixels``: the smallest multiple of 8 (the detector draws noise 64 pixels at a time)
  without a prime factor above 5 (the camera FFT's size: FFTW transforms such sizes fastest)
  that gives at least ``camera.pixels_per_lambda_over_d`` (2) pixels per lambda/D at the camera's
  wavelength over its ``field_of_view_arcsec`` and at least two pixels per science pupil sample,
  so the image is not aliased without oversampling the FFT (``optics.imaging``). The pupil
  sampling is ``lambda / field`` (3.3 cm at 800 nm over 5"), whatever the diameter.

Besides the size, :func:`derived_case` gives a case that leaves out
``tomography.prior_r0_500nm_m`` the case's own ``atmosphere.r0_500nm_m``: the tomography's prior
follows the case's seeing unless the case pins it (``studyspec.study.plausibility_warnings``
names a pinned prior that differs).

A case with ``atmosphere.layer_variability`` (intermittent turbulence) gets that block's left-out
keys from the schema and its ``seed`` from the study's (:func:`seeded_case`), so the resolved
config alone gives its layers' strengths in time (``studyspec.case.Case``).

The turbulence strips are at least ``turbulence.min_across_diameters`` diameters wide across the
wind (:func:`screen_min_across_m`). Writing a derived key together with the parameter it would
be derived from (``wfs.n_subapertures`` with ``telescope.subaperture_pitch_m``) is refused by key.
"""

import copy
import math

from ..optics.pupil import Telescope
from ..units import ARCSEC_RAD
from .schema import ConfigError, case_defaults, load_schema

DERIVED_KEYS = {
    "telescope.obscuration_m": "telescope.obscuration_ratio",
    "wfs.n_subapertures": "telescope.subaperture_pitch_m",
    "ao.n_actuators": "telescope.subaperture_pitch_m",
    "camera.n_pixels": "camera.pixels_per_lambda_over_d",
}
"""Each key derived from the diameter when a case leaves it out -> the parameter it is derived with."""

PIXEL_MULTIPLE = 8
"""camera.n_pixels is a multiple of this (the detector's noise kernels take 64 pixels at a time)."""

FAST_FFT_PRIMES = (2, 3, 5)
"""camera.n_pixels has no other prime factor: the camera's FFT (its size, without oversampling)
takes 0.64 of the time at 512 as at 504 = 2^3 3^2 7, a fifth at 160 as at 152 = 2^3 19 (FFTW)."""


def _get(case: dict, path: str):
    block, key = path.split(".")
    return case.get(block, {}).get(key)


def _parameter(case: dict, path: str) -> float:
    """A derivation parameter: the case's value, by default the schema's."""
    value = _get(case, path)
    if value is None:
        block, key = path.split(".")
        value = case_defaults(block)[key]
    return value


def subapertures_across(diameter_m: float, pitch_m: float) -> int:
    """Whole sub-apertures across the diameter at about ``pitch_m`` each: ``round(D / p)``."""
    return int(round(diameter_m / pitch_m))


def camera_pixels(
    diameter_m: float, wavelength_m: float, field_of_view_arcsec: float, pixels_per_lambda_over_d: float
) -> int:
    """Pixels across the lucky camera's field: the smallest multiple of :data:`PIXEL_MULTIPLE`
    whose prime factors are :data:`FAST_FFT_PRIMES` with at least ``pixels_per_lambda_over_d``
    pixels per lambda/D and two per pupil sample (pupil sampling ``lambda / field``, the grid of
    ``optics.pupil.Telescope.grid_for``)."""
    field_rad = field_of_view_arcsec * ARCSEC_RAD
    pupil_samples = Telescope(diameter_m, 0.0).grid_for(wavelength_m / field_rad).n_pix
    needed = max(pixels_per_lambda_over_d * diameter_m * field_rad / wavelength_m, 2 * pupil_samples)
    n_pixels = PIXEL_MULTIPLE * math.ceil(needed / PIXEL_MULTIPLE - 1e-9)
    while not _has_only_factors(n_pixels, FAST_FFT_PRIMES):
        n_pixels += PIXEL_MULTIPLE
    return n_pixels


def _has_only_factors(n: int, primes) -> bool:
    """Whether ``n`` (> 0) is a product of powers of ``primes``."""
    for p in primes:
        while n % p == 0:
            n //= p
    return n == 1


def derive_size_defaults(case: dict, where: str) -> dict:
    """A copy of a merged case (schema-valid) with every missing key of :data:`DERIVED_KEYS`
    derived from ``telescope.diameter_m``; ``where`` names the case in errors (``cases.x``)."""
    for derived, parameter in DERIVED_KEYS.items():
        if _get(case, derived) is not None and _get(case, parameter) is not None:
            raise ConfigError(
                f"config key '{where}.{derived}': given with {parameter}, from which it is derived; give one of them"
            )
    out = copy.deepcopy(case)
    telescope, camera = out["telescope"], out["camera"]
    diameter_m = telescope["diameter_m"]
    pitch_m = _parameter(case, "telescope.subaperture_pitch_m")
    n_sub = subapertures_across(diameter_m, pitch_m)
    if n_sub < 2 and ("n_subapertures" not in out["wfs"] or "n_actuators" not in out["ao"]):
        raise ConfigError(
            f"config key '{where}.telescope.diameter_m': {diameter_m:g} m holds {n_sub} sub-apertures "
            f"of telescope.subaperture_pitch_m = {pitch_m:g} m; at least 2 are needed"
        )
    out["wfs"].setdefault("n_subapertures", n_sub)
    out["ao"].setdefault("n_actuators", n_sub + 1)
    if "obscuration_m" not in telescope:
        telescope["obscuration_m"] = round(_parameter(case, "telescope.obscuration_ratio") * diameter_m, 3)
    if "n_pixels" not in camera:
        camera["n_pixels"] = camera_pixels(
            diameter_m,
            camera["wavelength_m"],
            camera["field_of_view_arcsec"],
            _parameter(case, "camera.pixels_per_lambda_over_d"),
        )
    return out


PRIOR_KEY = "tomography.prior_r0_500nm_m"
"""The tomography's prior r0: by default the case's ``atmosphere.r0_500nm_m`` (:func:`derived_case`)."""


def derived_case(case: dict, where: str) -> dict:
    """A merged case (schema-valid) resolved: :func:`derive_size_defaults`, the prior's r0
    (:data:`PRIOR_KEY`) the case's mean r0 when left out, ``tomography.method`` left out when
    it is the default (``dense``), with the iterative method's keys, and ``wfs.model`` when it is
    the default (``physical``; a geometric case without :data:`PHYSICAL_WFS_KEYS`): a case that
    spells a default out keeps the config hash and product keys of one that does not."""
    out = derive_size_defaults(case, where)
    tomography = out["tomography"]
    tomography.setdefault("prior_r0_500nm_m", out["atmosphere"]["r0_500nm_m"])
    if tomography.get("method") == case_defaults("tomography")["method"]:
        del tomography["method"]
    if "method" not in tomography:
        tomography.pop("iterative_rtol", None)
    wfs = out["wfs"]
    if wfs.get("model") == case_defaults("wfs")["model"]:
        del wfs["model"]
    if wfs.get("model") == "geometric":
        if wfs.get("centroider", "cog") != "cog":
            raise ConfigError(
                f"config key '{where}.wfs.centroider': wfs.model geometric models the centre of gravity's "
                f"noise (cog), not {wfs['centroider']}"
            )
        for key in PHYSICAL_WFS_KEYS:
            wfs.pop(key, None)
    return out


PHYSICAL_WFS_KEYS = ("centroider", "threshold", "calibration", "calibration_draws")
"""The WFS keys of the physical-optics sensor only, left out of a geometric case's resolved config
(:func:`derived_case`), so that their values name none of its products."""


def seeded_case(case: dict, seed: int) -> dict:
    """A resolved case whose ``atmosphere.layer_variability``, if any, holds every key: the
    schema's defaults for those left out, and the study's ``seed`` unless it gives one
    (the case unchanged without the block: no other case's config or hash moves)."""
    atm = case["atmosphere"]
    if "layer_variability" not in atm:
        return case
    out = copy.deepcopy(case)
    keys = load_schema()["definitions"]["case"]["properties"]["atmosphere"]["properties"]["layer_variability"]
    defaults = {key: spec["default"] for key, spec in keys["properties"].items() if "default" in spec}
    out["atmosphere"]["layer_variability"] = {**defaults, "seed": seed, **atm["layer_variability"]}
    return out


def training_case(case: dict, seed: int) -> dict:
    """The config of a case's training twin (``ao.learned_training_seed`` = ``seed``): the case
    with its layers' strengths in time drawn from ``seed`` too, so that the twin shares no
    turbulence history with the frames the learned criterion scores (the case itself without
    ``atmosphere.layer_variability``)."""
    if "layer_variability" not in case["atmosphere"]:
        return case
    out = copy.deepcopy(case)
    out["atmosphere"]["layer_variability"]["seed"] = seed
    return out


def derived_keys(merged: dict, resolved: dict) -> dict[str, object]:
    """``{key path: value}`` of the keys a case left out and got derived (:data:`DERIVED_KEYS`,
    :data:`PRIOR_KEY`)."""
    return {path: _get(resolved, path) for path in [*DERIVED_KEYS, PRIOR_KEY] if _get(merged, path) is None}


def screen_min_across_m(turbulence: dict, diameter_m: float) -> float:
    """Width of the turbulence strips across the wind [m]: ``turbulence.min_across_m``, and
    at least ``turbulence.min_across_diameters`` telescope diameters when given."""
    return max(turbulence["min_across_m"], turbulence.get("min_across_diameters", 0.0) * diameter_m)
