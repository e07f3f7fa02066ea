"""Samples in vector lanes: a numba type for :data:`LANES` float64 values held in one
LLVM vector (``<8 x double>``), so that a kernel can run the same arithmetic on several
samples at once with the CPU's vector instructions.

numba's compiler does not vectorise the kernels' per-body loops on its own: the bodies'
rows live in one array, and it cannot prove that a store does not alias a later load.
With :data:`vec` the lanes are explicit. Its ``+``, ``-``, ``*``, ``/`` (with another
:data:`vec` or a float, broadcast) are the IEEE operations of each lane, in the order the
source gives, with no fused multiply-add, so a function written for floats computes, lane
by lane, the same bits when given :data:`vec` values. The kernels' generic helpers
(``_mv``, ``_cross``, the inverse dynamics' per-body stages) are reused unchanged.

Arrays of :data:`vec` are views made by :func:`lanes2d` over a float64 buffer (aligned to
the vector's size inside it, so the loads and stores are aligned ones; allocate the
buffer with :func:`lanes_size` entries); they never leave compiled code. The lane count
is fixed at 8: AVX-512 holds it in one register, AVX2 in two, other CPUs split it as
their vector width requires (LLVM legalises the type), so the code is correct anywhere
and the bits are the same everywhere.
"""

from __future__ import annotations

import operator

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, models, overload, register_jitable, register_model
from numba.np.arrayobj import make_array, populate_array

LANES = 8
_LL = ir.VectorType(ir.DoubleType(), LANES)
_I32 = ir.IntType(32)


class VecType(types.Type):
    """:data:`LANES` float64 lanes in one LLVM vector."""

    def __init__(self) -> None:
        super().__init__(name=f"f64x{LANES}")


vec = VecType()


@register_model(VecType)
class _VecModel(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _LL)


def _splat(builder, x):
    v = ir.Constant(_LL, ir.Undefined)
    for j in range(LANES):
        v = builder.insert_element(v, x, ir.Constant(_I32, j))
    return v


@register_jitable
def lanes_size(n, m):
    """Entries of the float64 buffer that :func:`lanes2d` needs for an (n, m) array of
    vectors (one vector more, for the alignment); callable from compiled code."""
    return (n * m + 1) * LANES


def _is_f64_buffer(buf) -> bool:
    return (isinstance(buf, types.Array) and buf.ndim == 1 and buf.layout == "C"
            and buf.dtype == types.float64)


@intrinsic
def splat(typingctx, x):
    """The float ``x`` in every lane."""
    if not isinstance(x, (types.Float, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        return _splat(builder, context.cast(builder, args[0], sig.args[0], types.float64))

    return vec(x), codegen


@intrinsic
def lane(typingctx, v, j):
    """Lane ``j`` of ``v``."""
    if not (isinstance(v, VecType) and isinstance(j, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        return builder.extract_element(args[0], args[1])

    return types.float64(v, j), codegen


@intrinsic
def shift_in(typingctx, v, x):
    """``v``'s lanes moved up by one, the float ``x`` in lane 0: ``[x, v[0], ...,
    v[LANES - 2]]``."""
    if not (isinstance(v, VecType) and isinstance(x, types.Float)):
        return None

    def codegen(context, builder, sig, args):
        mask = ir.Constant(ir.VectorType(_I32, LANES), [LANES] + list(range(LANES - 1)))
        return builder.shuffle_vector(args[0], _splat(builder, args[1]), mask)

    return vec(v, x), codegen


@intrinsic
def vload(typingctx, buf, off):
    """``buf[off : off + LANES]`` of a 1-D C-contiguous float64 array as a vector (any
    alignment; bounds are the caller's)."""
    if not _is_f64_buffer(buf):
        return None

    def codegen(context, builder, sig, args):
        a = make_array(sig.args[0])(context, builder, args[0])
        p = cgutils.gep_inbounds(builder, a.data, args[1])
        return builder.load(builder.bitcast(p, _LL.as_pointer()), align=8)

    return vec(buf, types.intp), codegen


@intrinsic
def lanes2d(typingctx, buf, n, m):
    """An (n, m) C-contiguous array of vectors over the float64 1-D buffer ``buf`` (at
    least :func:`lanes_size` ``(n, m)`` entries), starting at its first entry aligned to a
    vector's size. Borrowed: no owner, valid while ``buf`` lives; never return it to
    Python."""
    if not _is_f64_buffer(buf):
        return None
    ret = types.Array(vec, 2, "C")

    def codegen(context, builder, sig, args):
        src = make_array(sig.args[0])(context, builder, args[0])
        dst = make_array(ret)(context, builder)
        i64 = ir.IntType(64)
        size = LANES * 8
        addr = builder.ptrtoint(src.data, i64)
        pad = builder.and_(builder.sub(ir.Constant(i64, 0), addr), ir.Constant(i64, size - 1))
        data = builder.inttoptr(builder.add(addr, pad), _LL.as_pointer())
        isz = context.get_constant(types.intp, size)
        populate_array(dst, data=data, shape=cgutils.pack_array(builder, [args[1], args[2]]),
                       strides=cgutils.pack_array(builder, [builder.mul(isz, args[2]), isz]),
                       itemsize=isz, meminfo=None, parent=None)
        return dst._getvalue()

    return ret(buf, types.intp, types.intp), codegen


@intrinsic
def lanes_start(typingctx, buf):
    """Index of the entry of ``buf`` where :func:`lanes2d`'s array starts (0 .. LANES - 1):
    lane ``j`` of that array's vector ``(r, c)`` (``m`` columns) is the float
    ``buf[lanes_start(buf) + (r * m + c) * LANES + j]``."""
    if not _is_f64_buffer(buf):
        return None

    def codegen(context, builder, sig, args):
        src = make_array(sig.args[0])(context, builder, args[0])
        i64 = ir.IntType(64)
        addr = builder.ptrtoint(src.data, i64)
        pad = builder.and_(builder.sub(ir.Constant(i64, 0), addr), ir.Constant(i64, LANES * 8 - 1))
        return builder.lshr(pad, ir.Constant(i64, 3))

    return types.intp(buf), codegen


def _binop(name: str):
    """The intrinsic of LLVM's ``name`` (``fadd``, ...) on two operands, floats splat."""

    @intrinsic
    def op(typingctx, a, b):
        def codegen(context, builder, sig, args):
            xs = [v if t == vec else _splat(builder, context.cast(builder, v, t, types.float64))
                  for t, v in zip(sig.args, args, strict=True)]
            return getattr(builder, name)(xs[0], xs[1])

        return vec(a, b), codegen

    return op


def _operand(t) -> bool:
    return isinstance(t, (VecType, types.Float, types.Integer))


def _overload_of(impl):
    def ov(a, b):
        if (isinstance(a, VecType) or isinstance(b, VecType)) and _operand(a) and _operand(b):
            return lambda a, b: impl(a, b)

    return ov


for _ops, _name in (((operator.add, operator.iadd), "fadd"),
                    ((operator.sub, operator.isub), "fsub"),
                    ((operator.mul, operator.imul), "fmul"),
                    ((operator.truediv, operator.itruediv), "fdiv")):
    _ov = _overload_of(_binop(_name))
    for _o in _ops:
        overload(_o)(_ov)


@intrinsic
def _neg(typingctx, a):
    def codegen(context, builder, sig, args):
        return builder.fneg(args[0])

    return vec(a), codegen


@overload(operator.neg)
def _ov_neg(a):
    if isinstance(a, VecType):
        return lambda a: _neg(a)


__all__ = ["LANES", "vec", "VecType", "lanes_size", "splat", "lane", "shift_in", "vload",
           "lanes2d", "lanes_start"]
