"""The layer-space MAP estimate by preconditioned conjugate gradients, warm-started exposure to exposure.

Solves ``(H^T N^-1 H + C^-1) x = H^T N^-1 s`` (``H`` :mod:`.operators`, ``N`` :mod:`.noise`, ``C^-1``
:mod:`.prior`) for the layers ``x``: the minimum-variance estimate of the layers from the slopes
under the Gaussian prior (e.g. Ellerbroek 2002, JOSA A 19, 1803). Each exposure starts from the
previous exposure's solution and stops when the residual norm falls below ``rtol`` times the
right-hand side's norm (``rtol`` from a cold start, ``warm_rtol`` from a warm one; or after
``max_iterations``).
"""

from dataclasses import dataclass, field

import numpy as np

from . import kernels
from .noise import SlopeNoise, SubapertureNoise
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
    its approximate inverse) from ``x0``, until ``|b - A x| <= rtol |b|``; the vector updates and
    dot products by :mod:`.kernels` (sums in float64), the scalars in ``b``'s dtype."""
    norm_b = np.sqrt(kernels.dot(b.ravel(), b.ravel()))
    if norm_b == 0:
        return PcgResult(np.zeros_like(b), 0, 0.0)
    scalar = b.dtype.type
    x = np.array(x0, dtype=b.dtype)
    r = b - apply_a(x)
    norm_r = np.sqrt(kernels.dot(r.ravel(), r.ravel()))
    iterations = 0
    if norm_r > rtol * norm_b:
        z = precondition(r)
        p = np.array(z, dtype=b.dtype)
        rz = kernels.dot(r.ravel(), z.ravel())
        while iterations < max_iterations:
            ap = apply_a(p)
            alpha = rz / kernels.dot(p.ravel(), ap.ravel())
            norm_r = np.sqrt(kernels.advance(x.ravel(), r.ravel(), p.ravel(), ap.ravel(), scalar(alpha)))
            iterations += 1
            if norm_r <= rtol * norm_b:
                break
            z = precondition(r)
            rz_next = kernels.dot(r.ravel(), z.ravel())
            kernels.new_direction(p.ravel(), z.ravel(), scalar(rz_next / rz))
            rz = rz_next
    return PcgResult(x, iterations, float(norm_r / norm_b))


@dataclass(eq=False)
class LayerTomography:
    """The layers' MAP estimate from each exposure's slopes, warm-started, in ``dtype`` (the
    prior's and the preconditioner's); PCG to ``rtol`` from a cold start, to ``warm_rtol`` (default
    ``rtol``) from the previous solution; ``iterations`` records each solve's count."""

    operator: MeasurementOperator
    prior: BiharmonicPrior
    noise: SlopeNoise | SubapertureNoise
    preconditioner: FourierPreconditioner | None
    rtol: float = 3e-4
    max_iterations: int = 200
    dtype: type = np.float64
    warm_rtol: float | None = None
    iterations: list[int] = field(default_factory=list)
    _previous: np.ndarray | None = None

    def normal(self, layers: np.ndarray) -> np.ndarray:
        """``(H^T N^-1 H + C^-1) x``."""
        out = self.operator.adjoint(self.noise.weigh(self.operator.forward(layers)))
        out += self.prior.apply(layers)
        return out

    def right_hand_side(self, slopes: np.ndarray) -> np.ndarray:
        """``H^T N^-1 s`` for slopes ``(n_beacons, 2, n_valid)`` [rad]."""
        return self.operator.adjoint(self.noise.weigh(np.asarray(slopes, dtype=self.dtype)))

    def estimate(self, slopes: np.ndarray) -> np.ndarray:
        """Layers ``(n_layers, n, n)`` [m] of one exposure's tilt-removed slopes, warm-started."""
        b = self.right_hand_side(slopes)
        if self._previous is None:
            x0, rtol = np.zeros_like(b), self.rtol
        else:
            x0, rtol = self._previous, self.rtol if self.warm_rtol is None else self.warm_rtol
        precondition = (lambda r: r) if self.preconditioner is None else self.preconditioner.apply
        result = pcg(self.normal, b, x0, precondition, rtol, self.max_iterations)
        self._previous = result.solution
        self.iterations.append(result.iterations)
        return result.solution

    def reset(self) -> None:
        """Forget the warm start (the next exposure starts from zero)."""
        self._previous = None
