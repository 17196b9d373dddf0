"""The Schwarz branch inversion of eight compressions in vector instructions, for the fast
kernel's mean-force kicks.

``branch_t8(d, sigma, t_min, delta_min)`` is :func:`mdgran.model.contact_scalar.branch_t` of
each of the eight compressions in the tuple ``d``, bit for bit: the same operations in the same
order (``t = t_min + max(w, 0)``, ``w`` from ``min(rhs / sqrt(6 t_min^2), sqrt(rhs))``,
``rhs = sqrt(max(delta - delta_min, 0))``, then ``NEWTON_STEPS`` Newton steps ``w -= (w sq -
rhs) / (sq + w (w + 2 t_min) / sq)``, ``sq = sqrt(w^2 + 4 t_min w + 6 t_min^2)``), each one a
correctly rounded IEEE operation on four lanes at once (LLVM's ``<4 x double>``; no operation
is fused or reordered), ``min`` and ``max`` as numba compiles Python's.  One inversion is a
chain of dependent square roots and divisions: two chains of four lanes keep the processor's
dividers busy where one scalar chain waits on each result.  The law itself is written once,
in :mod:`mdgran.model.contact_scalar`; this is a second spelling of its arithmetic, held to it
by a test over generated compressions (tests/test_contact_scalar.py)."""
from __future__ import annotations

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..model.contact_scalar import NEWTON_STEPS, branch_t

LANES = 4
F64 = ir.DoubleType()
V4 = ir.VectorType(F64, LANES)


def _splat(builder, x):
    """A vector of four copies of the double x."""
    vec = ir.Constant(V4, [0.0] * LANES)
    for i in range(LANES):
        vec = builder.insert_element(vec, x, ir.Constant(ir.IntType(32), i))
    return vec


def _max(builder, a, b):
    """numba's ``max(a, b)`` on each lane: ``b if b > a else a``."""
    return builder.select(builder.fcmp_ordered(">", b, a), b, a)


def _min(builder, a, b):
    """numba's ``min(a, b)`` on each lane: ``b if b < a else a``."""
    return builder.select(builder.fcmp_ordered("<", b, a), b, a)


def _newton(builder, sqrt, d, t_min, delta_min, sqrt_big, big, four_t, two_t):
    """branch_t of the lanes of d (t_min > 0), its operations in branch_t's order."""
    zero = ir.Constant(V4, [0.0] * LANES)
    rhs = builder.call(sqrt, [_max(builder, builder.fsub(d, delta_min), zero)])
    w = _min(builder, builder.fdiv(rhs, sqrt_big), builder.call(sqrt, [rhs]))
    for _ in range(NEWTON_STEPS):
        sq = builder.call(sqrt, [builder.fadd(builder.fadd(builder.fmul(w, w),
                                                           builder.fmul(four_t, w)), big)])
        num = builder.fsub(builder.fmul(w, sq), rhs)
        den = builder.fadd(sq, builder.fdiv(builder.fmul(w, builder.fadd(w, two_t)), sq))
        w = builder.fsub(w, builder.fdiv(num, den))
    return builder.fadd(t_min, _max(builder, w, zero))


@intrinsic
def _newton8(typingctx, d, t_min, delta_min):
    """branch_t of the eight compressions ``d`` (a UniTuple of float64; t_min > 0)."""
    if not (isinstance(d, types.UniTuple) and d.count == 2 * LANES
            and d.dtype == types.float64 and t_min == types.float64
            and delta_min == types.float64):
        return None

    def codegen(context, builder, sig, args):
        tup, tm, dm = args
        sqrt = cgutils.get_or_insert_function(builder.module, ir.FunctionType(V4, [V4]),
                                              "llvm.sqrt.v4f64")
        sqrt1 = cgutils.get_or_insert_function(builder.module, ir.FunctionType(F64, [F64]),
                                               "llvm.sqrt.f64")
        big = builder.fmul(builder.fmul(ir.Constant(F64, 6.0), tm), tm)
        consts = (_splat(builder, tm), _splat(builder, dm),
                  _splat(builder, builder.call(sqrt1, [big])), _splat(builder, big),
                  _splat(builder, builder.fmul(ir.Constant(F64, 4.0), tm)),
                  _splat(builder, builder.fmul(ir.Constant(F64, 2.0), tm)))
        halves = []
        for h in range(2):
            vec = ir.Constant(V4, [0.0] * LANES)
            for i in range(LANES):
                vec = builder.insert_element(vec, builder.extract_value(tup, h * LANES + i),
                                             ir.Constant(ir.IntType(32), i))
            halves.append(_newton(builder, sqrt, vec, *consts))
        out = [builder.extract_element(halves[k // LANES], ir.Constant(ir.IntType(32),
                                                                        k % LANES))
               for k in range(2 * LANES)]
        return context.make_tuple(builder, sig.return_type, out)

    return d(d, t_min, delta_min), codegen


@njit(inline="always")
def branch_t8(d, sigma, t_min, delta_min):
    """:func:`mdgran.model.contact_scalar.branch_t` of the eight compressions of the tuple
    ``d`` of one law, bit for bit (module docstring); DMT (t_min = 0) one by one."""
    if t_min == 0.0:
        return (branch_t(d[0], sigma, t_min, delta_min), branch_t(d[1], sigma, t_min, delta_min),
                branch_t(d[2], sigma, t_min, delta_min), branch_t(d[3], sigma, t_min, delta_min),
                branch_t(d[4], sigma, t_min, delta_min), branch_t(d[5], sigma, t_min, delta_min),
                branch_t(d[6], sigma, t_min, delta_min), branch_t(d[7], sigma, t_min, delta_min))
    return _newton8(d, t_min, delta_min)
