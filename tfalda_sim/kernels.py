"""Numba building blocks shared by kernels of several packages (the lowest layer: it
imports nothing of ours).

numba's on-disk cache (``cache=True``) keys a kernel on its own file only: after an edit
here, delete the ``__pycache__`` folders, or the kernels that use these keep the old
code."""

from __future__ import annotations

import sys

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

LITTLE_ENDIAN: bool = sys.byteorder == "little"
"""A compile-time constant of the kernels: the byte order of a 16-bit value."""


@intrinsic
def load_pair(typingctx, flat, k):  # type: ignore[no-untyped-def]  # numba's signature
    """``flat[k]`` and ``flat[k + 1]`` (a uint8 array whose elements are adjacent in
    memory, e.g. a row of a C-ordered image; both in bounds) in one unaligned 16-bit
    load: the two horizontal taps of a bilinear sample, one memory access instead of two.
    Stored to a uint16 array, its bytes are those two in that order, whatever the byte
    order; as a number, ``flat[k]`` is its low byte on little-endian machines
    (``LITTLE_ENDIAN``)."""
    if not (isinstance(flat, types.Array) and flat.dtype == types.uint8
            and isinstance(k, types.Integer)):
        return None

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        pair = builder.bitcast(builder.gep(data, [args[1]]), ir.IntType(16).as_pointer())
        return builder.load(pair, align=1)

    return types.uint16(flat, k), codegen
