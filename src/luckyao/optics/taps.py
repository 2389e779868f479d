"""The minor-axis taps of :func:`luckyao.optics.propagation._sample_kernel`, ``LANES`` grid points at once.

Speed-only machinery (numba intrinsics on :mod:`luckyao.simd`): it stands for the plain loop
over a line's grid points, ``grid[p] += v[t[p]] + c[p] (v[t[p] + 1] - v[t[p]])`` (the
association below), and gives its bits; the physics of the propagation is in
``optics/propagation.py``.

A grid point on line ``a`` at minor tap ``t`` with weight ``c`` adds the
interpolation of ``v = between_a`` (the line's major-axis interpolation) to
its value ``g``: ``g + (v[t] + c (v[t + 1] - v[t]))`` where both lines of its
line pair are in the mask, ``(g + v[t]) + c (v[t + 1] - v[t])`` where only its
own line is (the association, and the fused multiply-adds, of the scalar code
these replace: the published numbers depend on them). Intrinsics
(:mod:`luckyao.simd`) because numba's LLVM leaves this step scalar: the reads
of ``v`` are indexed; here each lane's pair ``v[t], v[t + 1]`` is one 8-byte
element of a gather, and the grid is read and written contiguously.
"""

from llvmlite import ir
from numba import types
from numba.core.errors import TypingError
from numba.extending import intrinsic

from .. import simd

_I64 = ir.IntType(64)
_TAPS = ir.VectorType(ir.IntType(32), simd.LANES)


def _lerp(builder, grid, first, second, weight, paired):
    """The interpolated values added to ``grid`` (pair association where ``paired``)."""
    step = builder.fsub(second, first)
    return builder.select(
        paired,
        builder.fadd(grid, simd.fmuladd_vector(builder, weight, step, first)),
        simd.fmuladd_vector(builder, weight, step, builder.fadd(grid, first)),
    )


def _check(*arrays):
    """TypingError unless every array is C-contiguous (the intrinsics read raw data)."""
    if not all(isinstance(a, types.Array) and a.layout == "C" for a in arrays):
        raise TypingError("taps: arrays must be C-contiguous")


def _integers(context, builder, signature, args, which):
    """The arguments at positions ``which`` as i64."""
    return [context.cast(builder, args[i], signature.args[i], types.int64) for i in which]


@intrinsic
def row_taps(typingctx, lines, tap, weight, start, count, pair, grid, offset, row):
    """``grid[offset + h row + b] += taps of lines[h] at tap[b], weight[b]`` for ``start <= b <
    start + count`` (``count <= LANES``) and the rows ``h`` of grid line pair ``pair`` (its
    runs' ``lines``: 1 the first, 2 the second, 3 both, paired): contiguous points."""
    _check(lines, tap, weight, grid)
    if tap.dtype != types.int32 or lines.ndim != 2:
        raise TypingError("row_taps: lines 2-d, tap int32")

    def codegen(context, builder, signature, args):
        lines_, tap_, weight_, grid_ = (
            context.make_array(signature.args[i])(context, builder, args[i]) for i in (0, 1, 2, 6)
        )
        start, count, pair, offset, row = _integers(context, builder, signature, args, (3, 4, 5, 7, 8))
        lanes = simd.first_lanes(builder, count)
        taps = simd.load(builder, builder.gep(tap_.data, [start]), lanes, _TAPS)
        weights = simd.load(builder, builder.gep(weight_.data, [start]), lanes)
        paired = simd.splat(builder, builder.icmp_signed("==", pair, ir.Constant(_I64, 3)))
        line_length = builder.udiv(builder.extract_value(lines_.strides, 0), ir.Constant(_I64, 4))  # floats
        for h in range(2):
            with builder.if_then(builder.trunc(builder.lshr(pair, ir.Constant(_I64, h)), ir.IntType(1))):
                line = builder.gep(lines_.data, [builder.mul(line_length, ir.Constant(_I64, h))])
                first, second = simd.gather_pairs(builder, line, taps, lanes)
                first_point = builder.add(builder.add(offset, start), builder.mul(row, ir.Constant(_I64, h)))
                points = builder.gep(grid_.data, [first_point])
                grid = simd.load(builder, points, lanes)
                simd.store(builder, _lerp(builder, grid, first, second, weights, paired), points, lanes)
        return context.get_dummy_value()

    return types.void(lines, tap, weight, start, count, pair, grid, offset, row), codegen


@intrinsic
def column_taps(typingctx, lines, tap, weight, y, grid, offset, codes, count):
    """``grid[offset + x] += taps of lines[x] at tap[y], weight[y]`` for ``x < count <= LANES``:
    one point of ``count`` adjacent columns, whose between lines are the rows of ``lines``;
    ``codes[offset + x]``: 3 pair association, 1 or 2 single, 0 outside the mask (untouched)."""
    _check(lines, tap, weight, grid, codes)
    if tap.dtype != types.int32 or codes.dtype != types.int8 or lines.ndim != 2:
        raise TypingError("column_taps: lines 2-d, tap int32, codes int8")

    def codegen(context, builder, signature, args):
        lines_, tap_, weight_, grid_, codes_ = (
            context.make_array(signature.args[i])(context, builder, args[i]) for i in (0, 1, 2, 4, 6)
        )
        y, offset, count = _integers(context, builder, signature, args, (3, 5, 7))
        code_type = ir.VectorType(ir.IntType(8), simd.LANES)
        code = simd.load(builder, builder.gep(codes_.data, [offset]), simd.first_lanes(builder, count), code_type)
        active = builder.and_(
            simd.first_lanes(builder, count),
            builder.icmp_unsigned("!=", code, ir.Constant(code_type, [0] * simd.LANES)),
        )
        row = builder.udiv(builder.extract_value(lines_.strides, 0), ir.Constant(_I64, 4))  # floats per line
        lane_rows = builder.mul(
            ir.Constant(ir.VectorType(_I64, simd.LANES), list(range(simd.LANES))), simd.splat(builder, row)
        )
        tap = builder.sext(builder.load(builder.gep(tap_.data, [y])), _I64)
        index = builder.trunc(builder.add(lane_rows, simd.splat(builder, tap)), _TAPS)
        first, second = simd.gather_pairs(builder, lines_.data, index, active)
        weights = simd.splat(builder, builder.load(builder.gep(weight_.data, [y])))
        points = builder.gep(grid_.data, [offset])
        grid = simd.load(builder, points, active)
        paired = builder.icmp_unsigned("==", code, ir.Constant(code_type, [3] * simd.LANES))
        simd.store(builder, _lerp(builder, grid, first, second, weights, paired), points, active)
        return context.get_dummy_value()

    return types.void(lines, tap, weight, y, grid, offset, codes, count), codegen
