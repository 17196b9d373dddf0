"""A cache hint for the compiled kernels: ``prefetch_row(a, i)`` asks the processor to bring
row ``i`` of array ``a`` into its caches and returns at once (LLVM's ``llvm.prefetch``; no
result changes, only when the row's memory is read).  For rows read later whose index is
known early, far apart in a long chain: a kicked contact's memo row
(:mod:`mdgran.backends.fast_kernel`)."""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def prefetch_row(typingctx, arr, i):
    """Prefetch the first element of row ``i`` of ``arr`` (for reading, kept in every cache
    level: ``prefetcht0`` on x86)."""
    if not (isinstance(arr, types.Array) and isinstance(i, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        aty, ity = sig.args
        ary = context.make_array(aty)(context, builder, args[0])
        index = [context.cast(builder, args[1], ity, types.intp)]
        index += [context.get_constant(types.intp, 0)] * (aty.ndim - 1)
        ptr = cgutils.get_item_pointer(context, builder, aty, ary, index, wraparound=False)
        byte_ptr, i32 = ir.IntType(8).as_pointer(), ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [byte_ptr, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0i8")
        # (address, 0: read, 3: keep in all levels, 1: data cache)
        builder.call(fn, [builder.bitcast(ptr, byte_ptr), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(arr, i), codegen
