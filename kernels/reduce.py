"""Block reductions: each block of REDUCTION_BLOCK threads sums its share in shared memory (Warp
tiles) and adds one partial sum atomically. Graph-capturable, with ~n/256 same-address atomics
instead of n (same-address atomics serialise on a GPU)."""

from typing import Any

import warp as wp

from . import declare_overloads

REDUCTION_BLOCK = wp.constant(256)


@wp.kernel
def block_sum_kernel(values: wp.array(dtype=Any), total: wp.array(dtype=Any)):
    """total[0] += Σ values (zeroed by the caller); launched tiled, one thread block per REDUCTION_BLOCK values."""
    block = wp.tid()
    tile = wp.tile_load(values, shape=REDUCTION_BLOCK, offset=block * REDUCTION_BLOCK)  # zero-padded past the end
    wp.tile_atomic_add(total, wp.tile_sum(tile))


declare_overloads(block_sum_kernel, values="scalar[]", total="scalar[]")
declare_overloads(block_sum_kernel, values="vec3[]", total="vec3[]")
