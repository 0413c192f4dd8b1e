"""Atomic loads and stores of int64 array elements, for compiled code: the one flag by
which one task of a parallel region tells the other that its work is no longer wanted
(tfm.kernels.contact._field_beside_solve)."""
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def atomic_load(typingctx, arr, i):
    """arr[i], read with acquire ordering (arr: int64 array)."""
    def codegen(context, builder, sig, args):
        aty = sig.args[0]
        ary = context.make_array(aty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aty, ary, [args[1]])
        return builder.load_atomic(ptr, "acquire", 8)
    return types.int64(arr, i), codegen


@intrinsic
def atomic_store(typingctx, arr, i, v):
    """arr[i] = v, written with release ordering (arr: int64 array)."""
    def codegen(context, builder, sig, args):
        aty = sig.args[0]
        ary = context.make_array(aty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aty, ary, [args[1]])
        val = context.cast(builder, args[2], sig.args[2], types.int64)
        builder.store_atomic(val, ptr, "release", 8)
        return context.get_dummy_value()
    return types.none(arr, i, v), codegen
