"""LLVM IR helpers for numba intrinsics that work on ``LANES`` float32 at once.

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


def splat(builder, value, lanes: int = LANES):
    """``value`` in every lane."""
    vector = ir.VectorType(value.type, lanes)
    single = builder.insert_element(ir.Constant(vector, None), value, ir.Constant(_I32, 0))
    zeros = ir.Constant(ir.VectorType(_I32, lanes), [0] * lanes)
    return builder.shuffle_vector(single, ir.Constant(vector, None), zeros)


def first_lanes(builder, count):
    """Mask of lanes ``k < count`` (``count`` an i64)."""
    lanes = ir.Constant(ir.VectorType(count.type, LANES), list(range(LANES)))
    return builder.icmp_unsigned("<", lanes, splat(builder, count))


def load(builder, pointer, mask, vector: ir.VectorType = VECTOR):
    """``pointer[k]`` in the lanes of ``mask`` (others undefined; nothing read there)."""
    name, size = ("f32", 4) if vector.element == F32 else (f"i{vector.element.width}", vector.element.width // 8)
    return call(builder, f"llvm.masked.load.v{LANES}{name}.p0", vector,
                [pointer, ir.Constant(_I32, size), mask, ir.Constant(vector, None)])


def store(builder, value, pointer, mask):
    """``pointer[k] = value[k]`` in the lanes of ``mask``."""
    call(builder, f"llvm.masked.store.v{LANES}f32.p0", ir.VoidType(),
         [value, pointer, ir.Constant(_I32, 4), mask])


def gather_pairs(builder, values, index, mask):
    """``(values[index[k]], values[index[k] + 1])`` of float32 ``values`` in the lanes of
    ``mask``: each adjacent pair is one 8-byte element of a gather, half the elements
    of two float32 gathers."""
    halves = [ir.Constant(ir.VectorType(_I32, _HALF), list(range(h * _HALF, (h + 1) * _HALF))) for h in range(2)]
    pairs = ir.VectorType(ir.DoubleType(), _HALF)
    loaded = []
    for half in halves:
        pointers = builder.gep(values, [builder.shuffle_vector(index, ir.Constant(index.type, None), half)],
                               source_etype=F32)
        pointers.type = ir.VectorType(ir.PointerType(), _HALF)  # a GEP with a vector index: one address per lane
        lanes = builder.shuffle_vector(mask, ir.Constant(MASK, None), half)
        got = call(builder, f"llvm.masked.gather.v{_HALF}f64.v{_HALF}p0", pairs,
                   [pointers, ir.Constant(_I32, 4), lanes, ir.Constant(pairs, None)])
        loaded.append(builder.bitcast(got, VECTOR))
    even = ir.Constant(ir.VectorType(_I32, LANES), list(range(0, 2 * LANES, 2)))
    odd = ir.Constant(ir.VectorType(_I32, LANES), list(range(1, 2 * LANES, 2)))
    return builder.shuffle_vector(*loaded, even), builder.shuffle_vector(*loaded, odd)


def fmuladd_vector(builder, a, b, c):
    """``a b + c`` of LANES float32, fused where the target has FMA."""
    return call(builder, f"llvm.fmuladd.v{LANES}f32", VECTOR, [a, b, c])


@intrinsic
def fmuladd(typingctx, a, b, c):
    """``a b + c`` of float32 (jit only), fused where the target has FMA: states which product
    of a sum of products is fused, which contraction leaves to the code generator."""
    if not all(x == types.float32 for x in (a, b, c)):
        raise TypingError("fmuladd: float32 only")

    def codegen(context, builder, signature, args):
        return call(builder, "llvm.fmuladd.f32", F32, list(args))

    return types.float32(a, b, c), codegen
