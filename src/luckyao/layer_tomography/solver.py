"""The layer-space MAP estimate by preconditioned conjugate gradients, warm-started exposure to exposure.

Solves ``(H^T N^-1 H + C^-1) x = H^T N^-1 s`` (``H`` :mod:`.operators`, ``N`` :mod:`.noise`, ``C^-1``
:mod:`.prior`) for the layers ``x``: the minimum-variance estimate of the layers from the slopes
under the Gaussian prior (e.g. Ellerbroek 2002, JOSA A 19, 1803). Each exposure starts from the
previous exposure's solution and stops when the residual norm falls below ``rtol`` times the
right-hand side's norm (or after ``max_iterations``).
"""

from dataclasses import dataclass, field

import numpy as np

from .noise import SlopeNoise
from .operators import MeasurementOperator
from .preconditioner import FourierPreconditioner
from .prior import BiharmonicPrior


@dataclass
class PcgResult:
    solution: np.ndarray
    iterations: int
    relative_residual: float


def pcg(apply_a, b: np.ndarray, x0: np.ndarray, precondition, rtol: float, max_iterations: int) -> PcgResult:
    """Preconditioned conjugate gradients (``apply_a`` symmetric positive definite, ``precondition``
    its approximate inverse) from ``x0``, until ``|b - A x| <= rtol |b|``."""
    norm_b = float(np.linalg.norm(b))
    if norm_b == 0:
        return PcgResult(np.zeros_like(b), 0, 0.0)
    x = x0.copy()
    r = b - apply_a(x)
    norm_r = float(np.linalg.norm(r))
    iterations = 0
    if norm_r > rtol * norm_b:
        z = precondition(r)
        p = z.copy()
        rz = float(np.vdot(r, z))
        while iterations < max_iterations:
            ap = apply_a(p)
            alpha = rz / float(np.vdot(p, ap))
            x += alpha * p
            r -= alpha * ap
            iterations += 1
            norm_r = float(np.linalg.norm(r))
            if norm_r <= rtol * norm_b:
                break
            z = precondition(r)
            rz_next = float(np.vdot(r, z))
            p = z + (rz_next / rz) * p
            rz = rz_next
    return PcgResult(x, iterations, norm_r / norm_b)


@dataclass(eq=False)
class LayerTomography:
    """The layers' MAP estimate from each exposure's slopes, warm-started, in ``dtype`` (the
    prior's and the preconditioner's); ``iterations`` records each solve's count."""

    operator: MeasurementOperator
    prior: BiharmonicPrior
    noise: SlopeNoise
    preconditioner: FourierPreconditioner | None
    rtol: float = 3e-4
    max_iterations: int = 200
    dtype: type = np.float64
    iterations: list[int] = field(default_factory=list)
    _previous: np.ndarray | None = None

    def normal(self, layers: np.ndarray) -> np.ndarray:
        """``(H^T N^-1 H + C^-1) x``."""
        return self.operator.adjoint(self.noise.weigh(self.operator.forward(layers))) + self.prior.apply(layers)

    def right_hand_side(self, slopes: np.ndarray) -> np.ndarray:
        """``H^T N^-1 s`` for slopes ``(n_beacons, 2, n_valid)`` [rad]."""
        return self.operator.adjoint(self.noise.weigh(np.asarray(slopes, dtype=self.dtype)))

    def estimate(self, slopes: np.ndarray) -> np.ndarray:
        """Layers ``(n_layers, n, n)`` [m] of one exposure's tilt-removed slopes, warm-started."""
        b = self.right_hand_side(slopes)
        x0 = np.zeros_like(b) if self._previous is None else self._previous
        precondition = (lambda r: r) if self.preconditioner is None else self.preconditioner.apply
        result = pcg(self.normal, b, x0, precondition, self.rtol, self.max_iterations)
        self._previous = result.solution
        self.iterations.append(result.iterations)
        return result.solution

    def reset(self) -> None:
        """Forget the warm start (the next exposure starts from zero)."""
        self._previous = None
