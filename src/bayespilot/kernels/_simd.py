"""An 8-wide double vector for numba kernels: the type, its operations, and the CPU check.

numba has no vector type of its own, and its auto-vectoriser does not turn the
segmented likelihood kernel (:mod:`._segmented`: eight independent recursions,
one per vector lane) into vector code.  This module declares ``V8``, a numba
type whose value is the generic LLVM vector ``<8 x double>``, and the few
operations that kernel needs, as ``numba.extending.intrinsic`` functions that
emit LLVM IR directly.

Portability: generic vector IR (``fadd``, ``fmul``, ``llvm.fma.v8f64``, loads
and stores of ``<8 x double>``, ``shufflevector``) is lowered by LLVM for any
target: one zmm register with AVX-512, two ymm with AVX2, four xmm (or NEON
q) registers elsewhere, and ``llvm.fma`` becomes a library call on a CPU
without fused multiply-add.  The results are the same on every target (each
lane does IEEE arithmetic, and ``vfma`` is always fused: one rounding).  Only
:func:`vclamp_abs` uses an x86 instruction (AVX-512DQ ``VRANGEPD``), and only
when the target numba compiles for has ``avx512dq``; otherwise it emits a
compare-and-select form with the same result.

Everything here is compiled inline into its caller, so the kernels that use it
cache as usual (``cache=True``): the ``V8`` values never cross a function
boundary that numba pickles.  The loads and stores do no bounds checking: the
caller guarantees the index range.
"""

from __future__ import annotations

import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, models, register_model

__all__ = ["W", "V8Type", "v8", "target_features", "vload", "vstore", "vbcast", "vbload",
           "vzero", "vadd", "vsub", "vmul", "vfma", "vfnma", "vclamp_abs", "vclamp_abs_minmax",
           "atomic_fetch_add"]

#: Lanes per vector.
W = 8
_VT = ir.VectorType(ir.DoubleType(), W)
_I32 = ir.IntType(32)


def _feature_set(flat: str) -> frozenset[str]:
    """The enabled features of an LLVM feature string ("+avx512f,-amx-tile,...")."""
    return frozenset(f[1:] for f in flat.split(",") if f.startswith("+"))


def target_features() -> frozenset[str]:
    """The CPU features numba compiles for, e.g. ``{"avx2", "fma", "avx512f", ...}``.

    The same string numba gives LLVM: ``NUMBA_CPU_FEATURES`` if it is set,
    otherwise the host CPU's features (LLVM's ``get_host_cpu_features``), with
    the AVX families removed when ``NUMBA_ENABLE_AVX=0``.  Empty on a host
    LLVM cannot query.
    """
    flat = numba.config.CPU_FEATURES
    if flat is None:
        from numba.core.codegen import get_host_cpu_features

        flat = get_host_cpu_features()
    return _feature_set(flat or "")


def _codegen_features(context) -> frozenset[str]:
    """Features of the target machine the code being generated is for."""
    flat = getattr(context.codegen(), "_tm_features", None)
    return _feature_set(flat) if isinstance(flat, str) else target_features()


class V8Type(types.Type):
    """Eight float64 lanes held as one LLVM ``<8 x double>`` value."""

    def __init__(self) -> None:
        super().__init__(name="V8")


v8 = V8Type()


@register_model(V8Type)
class _V8Model(models.PrimitiveModel):
    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, _VT)


def _is_c_float_array(a) -> bool:
    return isinstance(a, types.Array) and a.dtype == types.float64 and a.layout == "C"


def _vec_ptr(context, builder, aryty, ary, idx):
    arr = context.make_array(aryty)(context, builder, ary)
    return builder.bitcast(builder.gep(arr.data, [idx]), _VT.as_pointer())


@intrinsic
def vload(typingctx, arr, idx):
    """The 8 doubles ``arr.flat[idx:idx + 8]`` of a C-contiguous float64 array (no bounds check)."""
    if not (_is_c_float_array(arr) and isinstance(idx, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        return builder.load(_vec_ptr(context, builder, sig.args[0], args[0], args[1]), align=8)
    return v8(arr, idx), codegen


@intrinsic
def vstore(typingctx, arr, idx, v):
    """Write ``v`` to ``arr.flat[idx:idx + 8]`` (C-contiguous float64 array, no bounds check)."""
    if not (_is_c_float_array(arr) and isinstance(idx, types.Integer) and v == v8):
        return None

    def codegen(context, builder, sig, args):
        builder.store(args[2], _vec_ptr(context, builder, sig.args[0], args[0], args[1]), align=8)
        return context.get_dummy_value()
    return types.none(arr, idx, v), codegen


@intrinsic
def vbcast(typingctx, x):
    """``x`` (a float) in every lane."""
    if not isinstance(x, types.Float):
        return None

    def codegen(context, builder, sig, args):
        val = context.cast(builder, args[0], sig.args[0], types.float64)
        one = builder.insert_element(ir.Constant(_VT, ir.Undefined), val, ir.Constant(_I32, 0))
        return builder.shuffle_vector(one, ir.Constant(_VT, ir.Undefined),
                                      ir.Constant(ir.VectorType(_I32, W), [0] * W))
    return v8(x), codegen


@intrinsic
def vbload(typingctx, arr, idx):
    """``arr.flat[idx]`` (C-contiguous float64 array, no bounds check) in every lane: one
    broadcast load, without the negative-index wrap-around numba puts on ``arr[idx]``."""
    if not (_is_c_float_array(arr) and isinstance(idx, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        a = context.make_array(sig.args[0])(context, builder, args[0])
        val = builder.load(builder.gep(a.data, [args[1]]), align=8)
        one = builder.insert_element(ir.Constant(_VT, ir.Undefined), val, ir.Constant(_I32, 0))
        return builder.shuffle_vector(one, ir.Constant(_VT, ir.Undefined),
                                      ir.Constant(ir.VectorType(_I32, W), [0] * W))
    return v8(arr, idx), codegen


@intrinsic
def vzero(typingctx):
    """0.0 in every lane."""
    def codegen(context, builder, sig, args):
        return ir.Constant(_VT, [0.0] * W)
    return v8(), codegen


def _binary(op: str, doc: str):
    @intrinsic
    def f(typingctx, a, b):
        if not (a == v8 and b == v8):
            return None

        def codegen(context, builder, sig, args):
            return getattr(builder, op)(args[0], args[1])
        return v8(a, b), codegen
    f.__doc__ = doc
    return f


vadd = _binary("fadd", "a + b, lane by lane.")
vsub = _binary("fsub", "a - b, lane by lane.")
vmul = _binary("fmul", "a * b, lane by lane.")


def _fma(builder, a, b, c):
    fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_VT, [_VT] * 3),
                                        "llvm.fma.v8f64")
    return builder.call(fn, [a, b, c])


@intrinsic
def vfma(typingctx, a, b, c):
    """a * b + c with one rounding (``llvm.fma``: always fused, on every target)."""
    if not (a == v8 and b == v8 and c == v8):
        return None

    def codegen(context, builder, sig, args):
        return _fma(builder, *args)
    return v8(a, b, c), codegen


@intrinsic
def vfnma(typingctx, a, b, c):
    """c - a * b with one rounding."""
    if not (a == v8 and b == v8 and c == v8):
        return None

    def codegen(context, builder, sig, args):
        return _fma(builder, builder.fneg(args[0]), args[1], args[2])
    return v8(a, b, c), codegen


def _clamp_select(builder, x, d):
    """min(max(x, -d), d) by ordered compares (x86 MAXPD/MINPD semantics): for d >= 0 and x
    not NaN this is sign(x) min(|x|, d), the value of VRANGEPD below (up to the sign of a
    zero result, which the kernel's subtraction cannot tell apart)."""
    nd = builder.fneg(d)
    lo = builder.select(builder.fcmp_ordered(">", x, nd), x, nd)
    return builder.select(builder.fcmp_ordered("<", lo, d), lo, d)


def _clamp_range(builder, x, d):
    """VRANGEPD with imm8 = 0b0010: min(|x|, |d|), sign of x (AVX-512DQ)."""
    fn = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(_VT, [_VT, _VT, _I32, _VT, ir.IntType(8), _I32]),
        "llvm.x86.avx512.mask.range.pd.512")
    return builder.call(fn, [x, d, ir.Constant(_I32, 0b0010), x, ir.Constant(ir.IntType(8), 0xFF),
                             ir.Constant(_I32, 4)])


@intrinsic
def vclamp_abs(typingctx, x, d):
    """x clamped to [-d, d] for d >= 0 (the part of x inside a dead zone of half-width d).

    One AVX-512DQ ``VRANGEPD`` when the target has it (one instruction instead
    of two, in the kernel's busiest port), else :func:`vclamp_abs_minmax`'s
    compare-and-select form.  The choice is made when the caller is compiled,
    from the features of the target machine; numba's cache keys on those
    features, so a cached kernel is never loaded on a CPU it was not built for.
    """
    if not (x == v8 and d == v8):
        return None

    def codegen(context, builder, sig, args):
        if "avx512dq" in _codegen_features(context):
            return _clamp_range(builder, args[0], args[1])
        return _clamp_select(builder, args[0], args[1])
    return v8(x, d), codegen


@intrinsic
def vclamp_abs_minmax(typingctx, x, d):
    """:func:`vclamp_abs` by compare-and-select on every target (for tests of the two forms)."""
    if not (x == v8 and d == v8):
        return None

    def codegen(context, builder, sig, args):
        return _clamp_select(builder, args[0], args[1])
    return v8(x, d), codegen


@intrinsic
def atomic_fetch_add(typingctx, arr, idx, val):
    """``arr[idx] += val`` atomically on an int64 array; returns the value before."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int64
            and isinstance(idx, types.Integer) and isinstance(val, types.Integer)):
        return None

    def codegen(context, builder, sig, args):
        a = context.make_array(sig.args[0])(context, builder, args[0])
        i = context.cast(builder, args[1], sig.args[1], types.intp)
        v = context.cast(builder, args[2], sig.args[2], types.int64)
        ptr = builder.gep(a.data, [i])
        return builder.atomic_rmw("add", ptr, v, "seq_cst")
    return types.int64(arr, idx, val), codegen
