"""Vector intrinsics of the detector-noise streams (:mod:`luckyao.lucky.noise_streams`): the LANES
interleaved xoshiro256++ generators stepped as one vector, and the ziggurat's rectangle test of
16 deviates at once.

Speed-only machinery (numba intrinsics on :mod:`luckyao.simd`): it stands for two plain loops,
each generator stepped in turn (``noise_streams._xoshiro``) and each deviate's test ``m <
k[layer]`` with ``x = m w[layer]`` one at a time, and gives their bits; the streams and the
noise model are in ``lucky/noise_streams.py``.

Numba's LLVM leaves both loops scalar: the generators' states live in arrays that the output might
alias (each step loads and stores them), and the ziggurat reads its tables at indices drawn from
the bits (``table[idx[k]]``, which it cannot bound for its alias checks). These intrinsics state
the vector form (:mod:`luckyao.simd`: the states in registers, the table reads as
``llvm.masked.gather``); they do the same integer and float32 operations on each value as the
scalar loops, so the streams and the deviates are bit for bit the same (``tests/test_detector.py``).
"""

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

from .. import simd

GENERATORS = 8
"""Interleaved xoshiro256++ generators: one vector of 8 uint64 (``noise_streams.LANES``)."""

DEVIATES = simd.LANES
"""Deviates of one rectangle test (:func:`ziggurat_rectangle`): 16 int32 words."""

_I64 = ir.IntType(64)
_I32 = ir.IntType(32)
_STATE = ir.VectorType(_I64, GENERATORS)
_WORDS = ir.VectorType(_I32, DEVIATES)


def _vector(value: int, vector: ir.VectorType):
    return ir.Constant(vector, [value] * vector.count)


def _rotl(builder, x, k: int):
    """``(x << k) | (x >> (64 - k))`` of each uint64 (``llvm.fshl``: one rotate where there is one)."""
    amount = _vector(k, _STATE)
    return simd.call(builder, f"llvm.fshl.v{GENERATORS}i64", _STATE, [x, x, amount])


@intrinsic
def xoshiro_fill(typingctx, states, out):
    """``out[i + g]``, g < 8, the outputs of generator ``g`` of the xoshiro256++ states ``states``
    (4, 8) uint64 (word, generator), stepped once per 8 values of ``out`` (m,) uint64 (m a multiple
    of 8, not checked), the states left stepped (jit only): the scalar step of each generator in turn."""
    if not all(isinstance(a, types.Array) and a.dtype == types.uint64 and a.layout == "C" for a in (states, out)):
        raise TypingError("xoshiro_fill: C-contiguous uint64 arrays")

    def codegen(context, builder, signature, args):
        states_, out_ = (context.make_array(t)(context, builder, a) for t, a in zip(signature.args, args))
        pointers = [
            builder.bitcast(builder.gep(states_.data, [ir.Constant(_I64, GENERATORS * w)]), _STATE.as_pointer())
            for w in range(4)
        ]
        slots = [cgutils.alloca_once(builder, _STATE) for _ in range(4)]
        for slot, pointer in zip(slots, pointers):
            builder.store(builder.load(pointer, align=8), slot)
        size = builder.extract_value(out_.shape, 0)
        steps = builder.udiv(size, ir.Constant(_I64, GENERATORS))
        with cgutils.for_range(builder, steps) as loop:
            a, b, c, d = (builder.load(slot) for slot in slots)
            result = builder.add(_rotl(builder, builder.add(a, d), 23), a)
            to = builder.gep(out_.data, [builder.mul(loop.index, ir.Constant(_I64, GENERATORS))])
            builder.store(result, builder.bitcast(to, _STATE.as_pointer()), align=8)
            t = builder.shl(b, _vector(17, _STATE))
            c = builder.xor(c, a)
            d = builder.xor(d, b)
            b = builder.xor(b, c)
            a = builder.xor(a, d)
            c = builder.xor(c, t)
            d = _rotl(builder, d, 45)
            for slot, value in zip(slots, (a, b, c, d)):
                builder.store(value, slot)
        for slot, pointer in zip(slots, pointers):
            builder.store(builder.load(slot), pointer, align=8)
        return context.get_dummy_value()

    return types.void(states, out), codegen


@intrinsic
def ziggurat_rectangle(typingctx, words, start, widths, limits, out):
    """The rectangle test of the ziggurat for the 16 words ``words[start:start + 16]`` (int32:
    bits 0-7 the layer ``i``, 8 the sign, 9-31 the magnitude ``m``): ``out[start + k] = ±m
    widths[i]`` (float32) and, returned as an int64 bit mask (bit k), whether ``m >= limits[i]``
    (int32): the deviates to finish by the slow path (jit only; nothing bounds-checked)."""
    if not (
        isinstance(words, types.Array)
        and words.dtype == types.int32
        and words.layout == "C"
        and isinstance(limits, types.Array)
        and limits.dtype == types.int32
        and isinstance(widths, types.Array)
        and widths.dtype == types.float32
        and isinstance(out, types.Array)
        and out.dtype == types.float32
        and out.layout == "C"
    ):
        raise TypingError("ziggurat_rectangle: int32 words and limits, float32 widths and out")

    def codegen(context, builder, signature, args):
        words_, widths_, limits_, out_ = (
            context.make_array(signature.args[i])(context, builder, args[i]) for i in (0, 2, 3, 4)
        )
        first = context.cast(builder, args[1], signature.args[1], types.int64)
        every = ir.Constant(simd.MASK, [1] * DEVIATES)
        r = simd.load(builder, builder.gep(words_.data, [first]), every, _WORDS)
        layer = builder.and_(r, _vector(0xFF, _WORDS))
        magnitude = builder.and_(builder.ashr(r, _vector(9, _WORDS)), _vector(0x7FFFFF, _WORDS))
        sign = builder.and_(builder.ashr(r, _vector(8, _WORDS)), _vector(1, _WORDS))
        width = _gather(builder, widths_.data, layer, simd.F32)
        limit = _gather(builder, limits_.data, layer, _I32)
        x = builder.fmul(builder.sitofp(magnitude, simd.VECTOR), width)
        # x - 2 sign x, as the scalar code (not a negation: m = 0 gives +0 either sign)
        twice = builder.sitofp(builder.shl(sign, _vector(1, _WORDS)), simd.VECTOR)
        simd.store(builder, builder.fsub(x, builder.fmul(twice, x)), builder.gep(out_.data, [first]), every)
        failed = builder.icmp_signed(">=", magnitude, limit)
        return builder.zext(builder.bitcast(failed, ir.IntType(DEVIATES)), _I64)

    return types.int64(words, start, widths, limits, out), codegen


def _gather(builder, table, index, element: ir.Type):
    """``table[index[k]]`` of each lane (a ``llvm.masked.gather``)."""
    vector = ir.VectorType(element, DEVIATES)
    pointers = builder.gep(table, [index], source_etype=element)
    pointers.type = ir.VectorType(ir.PointerType(), DEVIATES)  # a GEP with a vector index: one address per lane
    name = "f32" if element == simd.F32 else "i32"
    return simd.call(
        builder,
        f"llvm.masked.gather.v{DEVIATES}{name}.v{DEVIATES}p0",
        vector,
        [pointers, ir.Constant(_I32, 4), ir.Constant(simd.MASK, [1] * DEVIATES), ir.Constant(vector, None)],
    )
