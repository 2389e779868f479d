"""The ``learned`` selection criterion (``ao.learned_training_seed``): a ridge regression
(:mod:`luckyao.lucky.ridge`) of each frame's true corrected rms (``true_rms_nm``) on its
laser-only telemetry (:data:`FEATURES`), fitted on a training twin and applied to the case.

The twin is the same case run with another seed (other screens, other WFS noise: no frame it
is scored on was seen in training; results/training/<case>/telemetry.nc); :func:`train_model`
fits one model per target from its telemetry, :func:`learned_rms_nm` applies it to the case's
telemetry in the lucky job. The model predicts the truth the oracle ``true_rms`` ranks by: it
needs no image, so the twin images nothing, and the tilt it leaves out the lasers cannot see.
"""

import json

import numpy as np
import xarray as xr

from ..ao.budget import first_corrected_frame
from ..ao.laser_criteria import FRAME_CRITERIA, TARGET_CRITERIA
from ..io.datasets import provenance
from ..io.hashing import sha256
from ..lucky.ridge import LAMBDAS, RidgeModel, cross_validated_ridge
from ..studyspec.case import Case
from ..studyspec.scaling import training_case

FEATURES = ("lgs_rms", "lgs_residual_rms") + tuple(name for name, _ in TARGET_CRITERIA + FRAME_CRITERIA)
"""The telemetry criteria (variables ``<name>_nm``) the model is fitted on."""

TRAINING_TARGET = "true_rms_nm"
"""The telemetry variable the model predicts."""


def features(telemetry: xr.Dataset, target: int) -> np.ndarray:
    """A target's :data:`FEATURES` (frame, feature) [nm] from a telemetry with ``ao.laser_criteria``
    (a frame's criteria are every target's)."""
    missing = [name for name in FEATURES if f"{name}_nm" not in telemetry]
    if missing:
        raise ValueError(f"the telemetry has no {', '.join(missing)}: run the case with ao.laser_criteria: true")
    columns = [telemetry[f"{name}_nm"].values for name in FEATURES]
    return np.stack([c[target] if c.ndim == 2 else c for c in columns], axis=-1).astype(float)


def train_model(telemetry: xr.Dataset, n_folds: int = 5) -> xr.Dataset:
    """The model of each target fitted on a training twin's telemetry: its frames from the first
    whose every step holds a command (:func:`luckyao.ao.budget.first_corrected_frame`), the
    penalty by blocked cross-validation over ``n_folds`` time blocks."""
    config = json.loads(telemetry.attrs["config_json"])
    first = first_corrected_frame(Case.from_config(config))
    models, errors = [], []
    for target in range(telemetry.sizes["target"]):
        truth = telemetry[TRAINING_TARGET].values[target, first:].astype(float)
        model, error = cross_validated_ridge(features(telemetry, target)[first:], truth, n_folds)
        models.append(model)
        errors.append(error)
    dims = ("target", "feature")
    ds = xr.Dataset(
        {
            "coefficient": (
                dims,
                [m.coefficients for m in models],
                {"units": "nm", "long_name": "ridge coefficient of each standardised feature"},
            ),
            "feature_mean_nm": (dims, [m.mean for m in models], {"units": "nm", "long_name": "feature mean"}),
            "feature_scale_nm": (
                dims,
                [m.scale for m in models],
                {"units": "nm", "long_name": "feature standard deviation (its standardisation)"},
            ),
            "intercept_nm": (
                "target",
                [m.intercept for m in models],
                {"units": "nm", "long_name": "mean training true_rms_nm"},
            ),
            "ridge_lambda": (
                "target",
                [m.ridge_lambda for m in models],
                {"units": "1", "long_name": "ridge penalty per frame, chosen by blocked cross-validation"},
            ),
            "cv_rms_error_nm": (
                ("target", "penalty"),
                errors,
                {"units": "nm", "long_name": f"rms error of the {n_folds}-block cross-validated prediction"},
            ),
            "training_rms_nm": (
                "target",
                [np.std(telemetry[TRAINING_TARGET].values[t, first:]) for t in range(len(models))],
                {"units": "nm", "long_name": "standard deviation of the training true_rms_nm"},
            ),
        },
        coords={
            "feature": ("feature", list(FEATURES), {"units": "1", "long_name": "telemetry criterion (<name>_nm)"}),
            "penalty": ("penalty", LAMBDAS, {"units": "1", "long_name": "ridge penalty tried"}),
        },
    )
    seed = int(telemetry.attrs["seed"])
    ds.attrs.update(provenance(f"luckyao learned criterion trained on seed {seed}", config, seed))
    ds.attrs.update(training_seed=seed, training_target=TRAINING_TARGET, first_frame=first)
    return ds


def learned_rms_nm(model: xr.Dataset, telemetry: xr.Dataset, target: int) -> np.ndarray:
    """The predicted ``true_rms_nm`` (frame,) of a target from the case's telemetry, after
    checking that the model was trained on this case with another seed."""
    training, scored = int(model.attrs["training_seed"]), int(telemetry.attrs["seed"])
    if training == scored:
        raise ValueError(
            f"the learned model was trained on seed {training}, the seed of the frames it would score: "
            "set ao.learned_training_seed to another seed"
        )
    if model.attrs["config_sha256"] != sha256(training_case(json.loads(telemetry.attrs["config_json"]), training)):
        raise ValueError("the learned model was trained on another case's config: remake it")
    if list(model["feature"].values) != list(FEATURES):
        raise ValueError(f"the learned model's features are not {list(FEATURES)}: remake it")
    fitted = model.isel(target=target)
    ridge = RidgeModel(
        fitted["feature_mean_nm"].values,
        fitted["feature_scale_nm"].values,
        fitted["coefficient"].values,
        float(fitted["intercept_nm"]),
        float(fitted["ridge_lambda"]),
    )
    return ridge.predict(features(telemetry, target))
