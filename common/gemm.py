"""numpy's own matrix product in compiled code (`gemm_nt`): the `cblas_dgemm` of the BLAS numpy
is linked against, called with the arguments numpy's `matmul` gives it for a C-contiguous
matrix times the transpose of another, so that a kernel's product is numpy's to the bit (a
product's rounding depends on the BLAS kernel and its blocking, not on the values alone).

numpy's wheels carry OpenBLAS built with 64-bit integers and prefixed names
(`scipy_cblas_dgemm64_`); where that function is not found (another numpy build) `AVAILABLE` is
False and the callers keep numpy's `@`. The function is found by name through numpy's own
extension module and given to the compiler under `SYMBOL`, so that a kernel cached on disk
finds it again in the next process.
"""

from __future__ import annotations

import ctypes
import importlib
from typing import Any

import llvmlite.binding as llvm
import numpy as np
from llvmlite import ir

from common import jit

# isort: off
from numba import types  # after common.jit: numba's BLAS module loaded alone first
from numba.core import cgutils
from numba.extending import intrinsic
# isort: on

SYMBOL = "fcu_numpy_cblas_dgemm64"
_NAMES = ("scipy_cblas_dgemm64_",)  # numpy's wheels (OpenBLAS, ILP64, prefixed)
ROW_MAJOR, NO_TRANS, TRANS = 101, 111, 112  # CBLAS_ORDER, CBLAS_TRANSPOSE


def _address() -> int | None:
    """The address of numpy's `cblas_dgemm` (ILP64), or None."""
    try:
        umath = ctypes.CDLL(importlib.import_module("numpy._core._multiarray_umath").__file__)
    except (OSError, ImportError, TypeError):
        return None
    for name in _NAMES:
        try:
            fn = getattr(umath, name)
        except AttributeError:
            continue
        address = ctypes.cast(fn, ctypes.c_void_p).value
        if address:
            return int(address)
    return None


_ADDRESS = _address()
if _ADDRESS is not None:
    llvm.add_symbol(SYMBOL, _ADDRESS)


def _dgemm_nt_typed(typingctx: Any, a: Any, b: Any, out: Any) -> Any:
    """cblas_dgemm(RowMajor, NoTrans, Trans, m, p, n, 1.0, a, n, b, n, 0.0, out, p): out
    (m x p) = a (m x n) times b (p x n) transposed, all three C-contiguous."""
    for x in (a, b, out):
        if not (isinstance(x, types.Array) and x.ndim == 2 and x.layout == "C"
                and x.dtype == types.float64):
            return None
    sig = types.void(a, b, out)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        arr_a = context.make_array(signature.args[0])(context, builder, args[0])
        arr_b = context.make_array(signature.args[1])(context, builder, args[1])
        arr_o = context.make_array(signature.args[2])(context, builder, args[2])
        i32, i64, f64 = ir.IntType(32), ir.IntType(64), ir.DoubleType()
        ptr = f64.as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [i32, i32, i32, i64, i64, i64, f64, ptr, i64,
                                               ptr, i64, f64, ptr, i64])
        fn = _cgutils.get_or_insert_function(builder.module, fnty, SYMBOL)
        a_shape = _cgutils.unpack_tuple(builder, arr_a.shape, 2)
        b_shape = _cgutils.unpack_tuple(builder, arr_b.shape, 2)
        m, n, p = a_shape[0], a_shape[1], b_shape[0]
        builder.call(fn, [ir.Constant(i32, ROW_MAJOR), ir.Constant(i32, NO_TRANS),
                          ir.Constant(i32, TRANS), m, p, n, ir.Constant(f64, 1.0),
                          builder.bitcast(arr_a.data, ptr), n,
                          builder.bitcast(arr_b.data, ptr), n, ir.Constant(f64, 0.0),
                          builder.bitcast(arr_o.data, ptr), p])
        return context.get_dummy_value()

    return sig, codegen


_cgutils: Any = cgutils
_dgemm_nt: Any = intrinsic(_dgemm_nt_typed)
AVAILABLE = _ADDRESS is not None


@jit.njit
def gemm_nt(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out = a @ b.T as numpy's `matmul` makes it (a: m x n, b: p x n, out: m x p, all
    C-contiguous float arrays, m, p > 1; only where `AVAILABLE`): the same BLAS call, so
    the same values to the bit."""
    _dgemm_nt(a, b, out)
