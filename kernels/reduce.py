"""Block reductions: each block of REDUCTION_BLOCK threads sums its share in shared memory (Warp
tiles) and adds one partial sum atomically. Graph-capturable, with ~n/256 same-address atomics
instead of n (same-address atomics serialise on a GPU)."""

from typing import Any

import warp as wp

from . import declare_overloads

REDUCTION_BLOCK = wp.constant(256)


@wp.func
def block_add(total: wp.array(dtype=Any), index: int, value: Any):
    """total[index] += Σ value over the thread block (a shared-memory tile sum, one atomic per block);
    every thread of the block must call it (threads past the data pass a zero value)."""
    wp.tile_atomic_add(total, wp.tile_sum(wp.tile(value, preserve_type=True)), offset=index)


@wp.kernel
def block_sum_kernel(values: wp.array(dtype=Any), total: wp.array(dtype=Any)):
    """total[0] += Σ values (zeroed by the caller); launched tiled, one thread block per REDUCTION_BLOCK values."""
    block = wp.tid()
    tile = wp.tile_load(values, shape=REDUCTION_BLOCK, offset=block * REDUCTION_BLOCK)  # zero-padded past the end
    wp.tile_atomic_add(total, wp.tile_sum(tile))


declare_overloads(block_sum_kernel, values="scalar[]", total="scalar[]")
declare_overloads(block_sum_kernel, values="vec3[]", total="vec3[]")
