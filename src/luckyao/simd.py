"""LLVM IR helpers for numba intrinsics that work on ``LANES`` float32 at once, and two such
intrinsics: :func:`fmuladd` (also of float64), :func:`transpose`.

Speed-only machinery: nothing here models anything, and no number depends on it being used.
It stands for plain numba code: ``values[index[k]]`` read in a loop (a gather), ``a * b + c``
with numba's ``contract`` fast-math flag (:func:`fmuladd`), a loop copying ``values[starts[r]
+ x]`` to ``out[x, r]`` (:func:`transpose`); each gives the bits of that plain code. The
intrinsics built on it: ``optics/taps.py``, ``lucky/stream_vectors.py``; the WFS kernels'
transposes (``wfs/kernels.py``).

Numba's LLVM leaves a loop scalar when its loads are indexed
(``values[index[k]]``: it cannot bound them for its run-time alias checks),
and it fuses a multiply into an add only where the product has no other use.
An intrinsic (``numba.extending.intrinsic``) built from these helpers states
both: indexed loads as ``llvm.masked.gather``, fused multiply-adds as
``llvm.fmuladd``. Both are target-independent. With AVX-512 a gather is
``vgatherdpd``/``vgatherqpd`` (:func:`gather_pairs`: 8 adjacent float32 pairs
per instruction); where LLVM deems gathers slow (``NUMBA_CPU_NAME=haswell``)
or the CPU has none (``generic``: SSE2) it lowers them to scalar loads.
``llvm.fmuladd`` is one FMA instruction where the target has FMA, else a
multiply then an add: what numba's ``contract`` fast-math flag gives. So an
intrinsic gives the bits of the scalar code it replaces on every CPU, however
it is lowered (checked against the scalar kernels compiled for each target).
:func:`transpose` moves values only, by shuffles of whole registers.
"""

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import intrinsic

LANES = 16
"""Values of one vector: one AVX-512 register of float32."""

F32 = ir.FloatType()
VECTOR = ir.VectorType(F32, LANES)
MASK = ir.VectorType(ir.IntType(1), LANES)
_I32 = ir.IntType(32)
_HALF = LANES // 2


def call(builder, name: str, result: ir.Type, args: list):
    """A call of LLVM intrinsic ``name`` (declared on first use)."""
    function_type = ir.FunctionType(result, [a.type for a in args])
    return builder.call(cgutils.get_or_insert_function(builder.module, function_type, name), args)


def splat(builder, value):
    """``value`` in every lane."""
    vector = ir.VectorType(value.type, LANES)
    single = builder.insert_element(ir.Constant(vector, None), value, ir.Constant(_I32, 0))
    zeros = ir.Constant(ir.VectorType(_I32, LANES), [0] * LANES)
    return builder.shuffle_vector(single, ir.Constant(vector, None), zeros)


def first_lanes(builder, count):
    """Mask of lanes ``k < count`` (``count`` an i64)."""
    lanes = ir.Constant(ir.VectorType(count.type, LANES), list(range(LANES)))
    return builder.icmp_unsigned("<", lanes, splat(builder, count))


def load(builder, pointer, mask, vector: ir.VectorType = VECTOR):
    """``pointer[k]`` in the lanes of ``mask`` (others undefined; nothing read there)."""
    name, size = ("f32", 4) if vector.element == F32 else (f"i{vector.element.width}", vector.element.width // 8)
    return call(
        builder,
        f"llvm.masked.load.v{LANES}{name}.p0",
        vector,
        [pointer, ir.Constant(_I32, size), mask, ir.Constant(vector, None)],
    )


def store(builder, value, pointer, mask):
    """``pointer[k] = value[k]`` in the lanes of ``mask``."""
    call(builder, f"llvm.masked.store.v{LANES}f32.p0", ir.VoidType(), [value, pointer, ir.Constant(_I32, 4), mask])


def gather_pairs(builder, values, index, mask):
    """``(values[index[k]], values[index[k] + 1])`` of float32 ``values`` in the lanes of
    ``mask``: each adjacent pair is one 8-byte element of a gather, half the elements
    of two float32 gathers."""
    halves = [ir.Constant(ir.VectorType(_I32, _HALF), list(range(h * _HALF, (h + 1) * _HALF))) for h in range(2)]
    pairs = ir.VectorType(ir.DoubleType(), _HALF)
    loaded = []
    for half in halves:
        pointers = builder.gep(
            values, [builder.shuffle_vector(index, ir.Constant(index.type, None), half)], source_etype=F32
        )
        pointers.type = ir.VectorType(ir.PointerType(), _HALF)  # a GEP with a vector index: one address per lane
        lanes = builder.shuffle_vector(mask, ir.Constant(MASK, None), half)
        got = call(
            builder,
            f"llvm.masked.gather.v{_HALF}f64.v{_HALF}p0",
            pairs,
            [pointers, ir.Constant(_I32, 4), lanes, ir.Constant(pairs, None)],
        )
        loaded.append(builder.bitcast(got, VECTOR))
    even = ir.Constant(ir.VectorType(_I32, LANES), list(range(0, 2 * LANES, 2)))
    odd = ir.Constant(ir.VectorType(_I32, LANES), list(range(1, 2 * LANES, 2)))
    return builder.shuffle_vector(*loaded, even), builder.shuffle_vector(*loaded, odd)


def fmuladd_vector(builder, a, b, c):
    """``a b + c`` of LANES float32, fused where the target has FMA."""
    return call(builder, f"llvm.fmuladd.v{LANES}f32", VECTOR, [a, b, c])


@intrinsic
def fmuladd(typingctx, a, b, c):
    """``a b + c`` of float32 or float64 (all three the same; jit only), fused where the target has
    FMA: states which product of a sum of products is fused, which contraction leaves to the code
    generator."""
    kinds = {types.float32: ("f32", F32), types.float64: ("f64", ir.DoubleType())}
    if a not in kinds or not a == b == c:
        raise TypingError("fmuladd: three float32 or three float64")
    name, result = kinds[a]

    def codegen(context, builder, signature, args):
        return call(builder, f"llvm.fmuladd.{name}", result, list(args))

    return a(a, b, c), codegen


@intrinsic
def transpose(typingctx, values, offset, index, start, rows, columns, out, out_start, out_stride):
    """``out[out_start + c out_stride + r] = values[offset + index[start + r] + c]`` for
    ``r < rows <= LANES``, ``c < columns <= LANES`` (jit only): a block of rows, each
    ``columns`` contiguous float32, written as columns, through registers (16 loads,
    64 two-register shuffles, 16 stores for 16 x 16). ``values``, ``out`` float32,
    ``index`` int32, all C-contiguous; nothing is bounds-checked."""
    arrays = (values, index, out)
    if not all(isinstance(a, types.Array) and a.layout == "C" for a in arrays):
        raise TypingError("transpose: arrays must be C-contiguous")
    if values.dtype != types.float32 or out.dtype != types.float32 or index.dtype != types.int32:
        raise TypingError("transpose: float32 values and out, int32 index")

    def codegen(context, builder, signature, args):
        values_, index_, out_ = (context.make_array(signature.args[i])(context, builder, args[i]) for i in (0, 2, 6))
        offset, start, rows, columns, out_start, out_stride = (
            context.cast(builder, args[i], signature.args[i], types.int64) for i in (1, 3, 4, 5, 7, 8)
        )
        base = builder.gep(values_.data, [offset])
        in_rows, in_columns = first_lanes(builder, rows), first_lanes(builder, columns)
        starts = load(builder, builder.gep(index_.data, [start]), in_rows, ir.VectorType(_I32, LANES))
        block = []
        for r in range(LANES):  # rows past ``rows``: nothing read, nothing stored
            row = builder.sext(builder.extract_element(starts, ir.Constant(_I32, r)), start.type)
            read = builder.and_(in_columns, splat(builder, builder.extract_element(in_rows, ir.Constant(_I32, r))))
            block.append(load(builder, builder.gep(base, [row]), read))
        for bit in (1 << b for b in range(LANES.bit_length() - 1)):  # swap that bit of the row and column indices
            low = ir.Constant(ir.VectorType(_I32, LANES), [LANES + (c ^ bit) if c & bit else c for c in range(LANES)])
            high = ir.Constant(ir.VectorType(_I32, LANES), [LANES + c if c & bit else c ^ bit for c in range(LANES)])
            for r in range(LANES):
                if not r & bit:
                    block[r], block[r | bit] = (
                        builder.shuffle_vector(block[r], block[r | bit], low),
                        builder.shuffle_vector(block[r], block[r | bit], high),
                    )
        for c in range(LANES):
            with builder.if_then(builder.icmp_signed("<", ir.Constant(columns.type, c), columns)):
                point = builder.add(out_start, builder.mul(out_stride, ir.Constant(out_stride.type, c)))
                store(builder, block[c], builder.gep(out_.data, [point]), in_rows)
        return context.get_dummy_value()

    return types.void(values, offset, index, start, rows, columns, out, out_start, out_stride), codegen
