"""Block reductions: each block of REDUCTION_BLOCK threads sums its share in shared memory (Warp
tiles) and adds one partial sum atomically. Graph-capturable, with ~n/256 same-address atomics
instead of n (same-address atomics serialise on a GPU)."""

from typing import Any

import warp as wp

from . import declare_overloads

REDUCTION_BLOCK = wp.constant(256)


def whole_blocks(n: int) -> int:
    """n rounded up to whole blocks of REDUCTION_BLOCK threads (a launch whose threads past n add zero)."""
    return -(-n // REDUCTION_BLOCK) * REDUCTION_BLOCK


@wp.func
def block_add(total: wp.array(dtype=Any), index: int, value: Any):
    """total[index] += Σ value over the thread block (a shared-memory tile sum, one atomic per block);
    every thread of the block must call it (threads past the data pass a zero value)."""
    wp.tile_atomic_add(total, wp.tile_sum(wp.tile(value, preserve_type=True)), offset=index)


@wp.kernel
def world_sum_kernel(values: wp.array(dtype=Any), worlds: int, threads: int, total: wp.array(dtype=Any)):
    """total[w] += Σ of world w's share of `values` (`worlds` equal blocks; into total[0] where total
    holds one entry): `threads` per world (whole blocks, no block straddling two worlds), thread t
    of world w taking its items t, t + threads, ... Zeroed by the caller."""
    items = values.shape[0] // worlds
    w = wp.tid() // threads
    s = type(values[0])(0.0)
    for i in range(wp.tid() - w * threads, items, threads):
        s += values[w * items + i]
    block_add(total, wp.min(w, total.shape[0] - 1), s)


declare_overloads(world_sum_kernel, values="scalar[]", total="scalar[]")
