"""The layer tomography's compiled kernels (luckyao.layer_tomography.kernels) against plain numpy
formulas of the same operators, written here: the ray tracing and the gradient give the same bits
in float32, the prior, the preconditioner and the PCG the same numbers to float32 (or float64)
rounding, and the compiled measurement operator is its own adjoint's transpose in float32."""

import numpy as np
import pytest
import scipy.fft
from test_layer_tomography import small_tomography

from luckyao.layer_tomography.operators import EDGE_WEIGHTS
from luckyao.layer_tomography.solver import PcgResult, pcg

RNG = np.random.default_rng(11)


def numpy_trace(beacon, layers):
    """One beacon's pupil phase: the four bilinear taps of each layer as array slices."""
    m = beacon.m
    out = np.zeros((m, m), dtype=layers.dtype)
    for layer, (column, row) in zip(layers, beacon.offsets):
        c0, r0 = int(np.floor(column)), int(np.floor(row))
        fc, fr = column - c0, row - r0
        for dr, wr in ((0, 1 - fr), (1, fr)):
            for dc, wc in ((0, 1 - fc), (1, fc)):
                out += wr * wc * layer[r0 + dr : r0 + dr + m, c0 + dc : c0 + dc + m]
    return out


def numpy_trace_adjoint_add(beacon, phase, layers):
    m = beacon.m
    for layer, (column, row) in zip(layers, beacon.offsets):
        c0, r0 = int(np.floor(column)), int(np.floor(row))
        fc, fr = column - c0, row - r0
        for dr, wr in ((0, 1 - fr), (1, fr)):
            for dc, wc in ((0, 1 - fc), (1, fc)):
                layer[r0 + dr : r0 + dr + m, c0 + dc : c0 + dc + m] += wr * wc * phase


def edge_means(phase, o, n, axis):
    p = np.moveaxis(phase, axis, 0)
    return np.moveaxis(sum(w * p[t : t + o * n : o] for t, w in enumerate(EDGE_WEIGHTS[o])), 0, axis)


def numpy_gradient(gradient, phase):
    """Slopes: the differences of the sub-apertures' trapezoid edge means over ``d``."""
    o, n, d = gradient.oversampling, gradient.valid.shape[0], gradient.subaperture_m
    along_y, along_x = edge_means(phase, o, n, 0), edge_means(phase, o, n, 1)
    sx = (along_y[:, o::o] - along_y[:, 0:-1:o]) / d
    sy = (along_x[o::o, :] - along_x[0:-1:o, :]) / d
    return np.stack([sx[gradient.valid], sy[gradient.valid]])


def numpy_gradient_adjoint(gradient, slopes):
    o, n, m, d = gradient.oversampling, gradient.valid.shape[0], gradient.m, gradient.subaperture_m
    gx, gy = np.zeros((n, n), dtype=slopes.dtype), np.zeros((n, n), dtype=slopes.dtype)
    gx[gradient.valid], gy[gradient.valid] = slopes[0] / d, slopes[1] / d
    tx, ty = np.zeros((n, m), dtype=slopes.dtype), np.zeros((m, n), dtype=slopes.dtype)
    tx[:, o::o] += gx
    tx[:, 0:-1:o] -= gx
    ty[o::o, :] += gy
    ty[0:-1:o, :] -= gy
    phase = np.zeros((m, m), dtype=slopes.dtype)
    for t, weight in enumerate(EDGE_WEIGHTS[o]):
        phase[t : t + o * n : o, :] += weight * tx
        phase[:, t : t + o * n : o] += weight * ty
    return phase


def numpy_preconditioner(preconditioner, residual):
    """``F^-1 A(k)^-1 F r``: every frequency's ``n_layers x n_layers`` product by ``matmul``."""
    spectrum = np.moveaxis(scipy.fft.rfft2(residual), 0, -1)[..., None]
    coupled = np.matmul(preconditioner.inverse.astype(complex), spectrum)[..., 0]
    return scipy.fft.irfft2(np.moveaxis(coupled, -1, 0), s=(preconditioner.n, preconditioner.n))


def numpy_pcg(apply_a, b, x0, precondition, rtol, max_iterations):
    norm_b = np.linalg.norm(b)
    x = x0.copy()
    r = b - apply_a(x)
    z = precondition(r)
    p, rz, iterations = z.copy(), np.vdot(r, z), 0
    while iterations < max_iterations and np.linalg.norm(r) > rtol * norm_b:
        ap = apply_a(p)
        alpha = rz / np.vdot(p, ap)
        x, r, iterations = x + alpha * p, r - alpha * ap, iterations + 1
        z = precondition(r)
        rz, previous = np.vdot(r, z), rz
        p = z + (rz / previous) * p
    return PcgResult(x, iterations, np.linalg.norm(r) / norm_b)


@pytest.mark.parametrize("samples", [1, 2])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_ray_tracing_and_gradient_equal_numpy(samples, dtype):
    """The compiled stencils against the numpy slices on random layers, phases and slopes: the
    same bits in float64; in float32 the gradient's bits, and the ray tracing within 1e-6 of the
    largest value (numpy multiplies by float64 weights then rounds, the kernel by float32 weights)."""
    tomo = small_tomography(samples, dtype=dtype)
    op = tomo.operator
    layers = RNG.normal(size=op.grids.shape).astype(dtype)
    slopes = RNG.normal(size=(2, op.gradient.n_valid)).astype(dtype)
    traced = np.testing.assert_array_equal if dtype == np.float64 else close
    for beacon in op.beacons:
        phase = RNG.normal(size=(beacon.m, beacon.m)).astype(dtype)
        traced(beacon.forward(layers), numpy_trace(beacon, layers))
        compiled, reference = layers.copy(), layers.copy()
        beacon.adjoint_add(phase, compiled)
        numpy_trace_adjoint_add(beacon, phase, reference)
        traced(compiled, reference)
        np.testing.assert_array_equal(op.gradient.forward(phase), numpy_gradient(op.gradient, phase))
        np.testing.assert_array_equal(op.gradient.adjoint(slopes), numpy_gradient_adjoint(op.gradient, slopes))
    assert beacon.forward(layers).dtype == op.gradient.adjoint(slopes).dtype == dtype


def close(actual, desired, relative=1e-6):
    """``actual`` within ``relative`` of ``desired``'s largest value, and of its dtype."""
    assert actual.dtype == desired.dtype
    np.testing.assert_allclose(actual, desired, rtol=0, atol=relative * np.abs(desired).max())


@pytest.mark.parametrize("samples", [1, 2])
def test_measurement_operator_is_adjoint_in_float32(samples):
    """``<H x, s> = <x, H^T s>`` to float32 rounding (1e-5 of ``|H x| |s|``; the two sides of the
    float64 operator agree to 1e-12, tests/test_layer_tomography.py)."""
    op = small_tomography(samples, dtype=np.float32).operator
    x = RNG.normal(size=op.grids.shape).astype(np.float32)
    s = RNG.normal(size=(len(op.beacons), 2, op.gradient.n_valid)).astype(np.float32)
    hx, hts = op.forward(x), op.adjoint(s)
    assert hx.dtype == hts.dtype == np.float32
    left, right = np.vdot(hx.astype(float), s.astype(float)), np.vdot(x.astype(float), hts.astype(float))
    assert abs(left - right) <= 1e-5 * np.linalg.norm(hx) * np.linalg.norm(s)


@pytest.mark.parametrize("dtype, rtol", [(np.float64, 1e-10), (np.float32, 1e-5)])
def test_prior_and_preconditioner_equal_their_matrices(dtype, rtol):
    """The prior's stencils against its assembled sparse matrix ``blockdiag w_l L_l^T L_l``, the
    preconditioner's Hermitian half against the full per-frequency products, on random layers."""
    tomo = small_tomography(dtype=dtype)
    layers = RNG.normal(size=tomo.operator.grids.shape)
    reference = (tomo.prior.matrix() @ layers.ravel()).reshape(layers.shape)
    close(tomo.prior.apply(layers.astype(dtype)), reference.astype(dtype), rtol)
    reference = numpy_preconditioner(tomo.preconditioner, layers)
    close(tomo.preconditioner.apply(layers.astype(dtype)), reference.astype(dtype), rtol)


def test_pcg_takes_the_numpy_iterations():
    """In float64 the fused PCG takes numpy's iterates, cold and warm-started: the same count to
    the same tolerance and the same solution to 1e-5 of its largest value (the dot products sum
    in another order; the system's condition number, ~1e4, amplifies that rounding: measured 1e-6)."""
    tomo = small_tomography(dtype=np.float64)
    op = tomo.operator
    slopes = op.forward(1e-7 * RNG.normal(size=op.grids.shape)) + 1e-7 * RNG.normal(
        size=(len(op.beacons), 2, op.gradient.n_valid)
    )
    b = tomo.right_hand_side(slopes)
    rough = numpy_pcg(tomo.normal, b, np.zeros_like(b), tomo.preconditioner.apply, 1e-3, 200).solution
    for x0 in (np.zeros_like(b), 0.5 * rough):
        compiled = pcg(tomo.normal, b, x0, tomo.preconditioner.apply, 1e-8, 500)
        reference = numpy_pcg(tomo.normal, b, x0, tomo.preconditioner.apply, 1e-8, 500)
        assert compiled.iterations == reference.iterations
        close(compiled.solution, reference.solution, 1e-5)
