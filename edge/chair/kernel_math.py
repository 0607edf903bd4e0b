"""Arithmetic the compiled chair kernels share, written to round as the Python reference does.

edge/chair/kernel.py's docstring says why each is needed for the bit-for-bit agreement with
edge/chair/estimator.py: OpenBLAS sums dot products with fused multiply-adds (`fma`), Python's
`x ** 2` is libm's pow (`pow2`), Python 3.11's `sum` adds from 0 in order (`sum3`), and an angle
wraps as Python's float `%` does (`wrap`).
"""

from __future__ import annotations

import math

from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic


@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c rounded once, as OpenBLAS's kernels accumulate."""
    def codegen(context, builder, signature, args):
        return builder.fma(*args)
    return types.float64(types.float64, types.float64, types.float64), codegen


@intrinsic
def pow2(typingctx, x):
    """libm pow(x, 2.0), which is what Python's `x ** 2` computes (not always x * x).

    Declared `nobuiltin` so that LLVM keeps the call instead of rewriting it as x * x.
    """
    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        pow_fn = builder.module.globals.get("pow")
        if pow_fn is None:
            pow_fn = ir.Function(builder.module, ir.FunctionType(double, [double, double]), name="pow")
        pow_fn.attributes.add("nobuiltin")
        return builder.call(pow_fn, [args[0], ir.Constant(double, 2.0)])
    return types.float64(types.float64), codegen


@njit(inline='always')
def sum3(a, b, c):
    return 0.0 + a + b + c  # as Python's sum() (3.11): from 0, in order


@njit
def wrap(angle):
    return (angle + math.pi) % (2.0 * math.pi) - math.pi  # numba's float % follows Python's sign rule
