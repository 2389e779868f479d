"""Ridge regression in closed form, its penalty chosen by cross-validation over time blocks.

Features are standardised (mean 0, standard deviation 1 over the fitted rows), the target
centred, and ``beta = (Z^T Z + n lambda I)^-1 Z^T (y - mean(y))`` (Hoerl & Kennard 1970,
Technometrics 12, 55; Hastie, Tibshirani & Friedman, *The Elements of Statistical Learning*,
2nd ed., sec. 3.4.1): ``lambda`` is per row, so its scale does not depend on the number of
rows. The penalty is the one of a grid with the least mean squared error over ``n_folds``
contiguous blocks of rows, each predicted by the fit on the others: rows are frames in time,
correlated over many frames, so shuffled folds would score on near copies of the rows fitted.
"""

from dataclasses import dataclass

import numpy as np

LAMBDAS = np.logspace(-6, 3, 28)
"""The penalties tried (per row, on standardised features)."""


@dataclass(frozen=True)
class RidgeModel:
    """A fitted ridge regression: ``predict(x) = intercept + ((x - mean) / scale) @ coefficients``."""

    mean: np.ndarray
    scale: np.ndarray
    coefficients: np.ndarray
    """On the standardised features (n_features,)."""
    intercept: float
    ridge_lambda: float

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Predictions (n_rows,) of the rows ``x`` (n_rows, n_features)."""
        return self.intercept + ((np.asarray(x, dtype=float) - self.mean) / self.scale) @ self.coefficients

    @property
    def raw_coefficients(self) -> np.ndarray:
        """The coefficients on the features as given (their units): ``coefficients / scale``."""
        return self.coefficients / self.scale


def fit_ridge(x: np.ndarray, y: np.ndarray, ridge_lambda: float) -> RidgeModel:
    """The ridge regression of ``y`` (n_rows,) on ``x`` (n_rows, n_features) with penalty
    ``ridge_lambda`` (per row); a constant feature gets coefficient 0."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    mean, scale = x.mean(axis=0), x.std(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    z = (x - mean) / scale
    n, m = z.shape
    coefficients = np.linalg.solve(z.T @ z + n * ridge_lambda * np.eye(m), z.T @ (y - y.mean()))
    return RidgeModel(mean, scale, coefficients, float(y.mean()), float(ridge_lambda))


def cross_validated_ridge(
    x: np.ndarray, y: np.ndarray, n_folds: int = 5, lambdas: np.ndarray = LAMBDAS
) -> tuple[RidgeModel, np.ndarray]:
    """The ridge fit of all rows with the penalty of ``lambdas`` whose blocked
    cross-validation error is least (the smallest such), and that error (len(lambdas),)
    [the units of ``y``, rms] per penalty."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(y) < 2 * n_folds:
        raise ValueError(f"{len(y)} rows cannot be split in {n_folds} folds of at least 2")
    folds = np.array_split(np.arange(len(y)), n_folds)
    errors = np.zeros(len(lambdas))
    for held in folds:
        kept = np.setdiff1d(np.arange(len(y)), held)
        for i, ridge_lambda in enumerate(lambdas):
            model = fit_ridge(x[kept], y[kept], ridge_lambda)
            errors[i] += np.sum((model.predict(x[held]) - y[held]) ** 2)
    errors = np.sqrt(errors / len(y))
    return fit_ridge(x, y, float(lambdas[int(np.argmin(errors))])), errors
