"""An atomic counter for the compiled kernels: ``fetch_add(a, i, k)`` adds ``k`` to ``a[i]``
and returns the value it had, as one indivisible step of the processor (LLVM's
``atomicrmw add``), so that threads can take work from one shared counter without two
taking the same item.  The threaded pass and the event windows' lanes claim their
segments and lanes this way (:mod:`mdgran.backends.fast_kernel`): a thread that finishes
early takes more, where a split fixed in advance leaves it waiting for the other."""
from __future__ import annotations

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def fetch_add(typingctx, arr, i, k):
    """``old = a[i]; a[i] += k; return old``, atomically (``a``: a 1-d int64 array)."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int64 and arr.ndim == 1
            and isinstance(i, types.Integer) and isinstance(k, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        aty, ity, kty = sig.args
        ary = context.make_array(aty)(context, builder, args[0])
        index = [context.cast(builder, args[1], ity, types.intp)]
        ptr = cgutils.get_item_pointer(context, builder, aty, ary, index, wraparound=False)
        value = context.cast(builder, args[2], kty, types.int64)
        return builder.atomic_rmw("add", ptr, value, "seq_cst")

    return types.int64(arr, i, k), codegen
