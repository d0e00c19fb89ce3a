"""Koiter shell forces with each thread block's patch vertices staged in shared memory
(docs/theory/geometry.md#staging-patches-in-shared-memory).

A block of consecutive triangles (one thread each) first loads the union of its patches' control
vertices into a shared tile, computes every triangle's forces from that tile, sums them per vertex in
a second shared tile and adds that tile to the global forces: one global read and one global atomic
per union vertex and block, instead of one per patch entry. The union's capacity is a compile-time
tile shape, so there is one kernel per capacity (`staged_shell_forces_kernel`).

Warp runs a tile kernel's blocks on the CPU as a single lane, so on the CPU a block is one triangle.
"""

import functools
from typing import Any

import warp as wp

from .shell import MAX_PATCH, VolumeMoments, triangle_forces, world_volume_terms


@functools.cache
def staged_shell_forces_kernel(capacity: int):
    """The staged force kernel for blocks whose patch union has at most `capacity` vertices; launch it with
    `wp.launch_tiled(dim=[n_blocks], block_dim=triangles per block)`."""

    @wp.kernel(module="unique")
    def staged_shell_forces(
        x: wp.array(dtype=Any),
        patch_start: wp.array(dtype=wp.int32),
        patch_local: wp.array(dtype=wp.int32),
        triangle_type: wp.array(dtype=wp.int32),
        basis: wp.array2d(dtype=Any),
        points_per_triangle: int,
        ref_metric: wp.array(dtype=Any),
        ref_metric_inv: wp.array(dtype=Any),
        ref_curvature: wp.array(dtype=Any),
        ref_weight: wp.array(dtype=Any),
        stretching_modulus: wp.array(dtype=Any),
        bending_modulus: wp.array(dtype=Any),
        nu: Any,
        worlds: int,
        weights: wp.array(dtype=Any),
        moments: wp.array(dtype=VolumeMoments),
        target: wp.array(dtype=wp.float64),
        penalty: wp.array(dtype=wp.float64),
        with_energy: int,
        energy_density: wp.array(dtype=wp.float64),
        block_vertices: wp.array2d(dtype=wp.int32),
        forces: wp.array(dtype=Any),
    ):
        """`shell_forces_kernel`'s forces and energy densities; patch entry e of a triangle of block b
        is vertex block_vertices[b, patch_local[e]]."""
        block, lane = wp.tid()
        t = block * wp.block_dim() + lane
        n_triangles = triangle_type.shape[0]
        union = wp.tile_load(block_vertices[block], shape=capacity)
        positions = wp.tile_load_indexed(x, indices=union, shape=(capacity,), axis=0, storage="shared")
        summed = wp.tile_zeros(shape=capacity, dtype=x.dtype, storage="shared")
        active = t < n_triangles
        start = 0
        size = 0
        accumulated = wp.matrix(shape=(MAX_PATCH, 3), dtype=type(nu))
        if active:
            start = patch_start[t]
            size = patch_start[t + 1] - start
            w = t // (n_triangles // worlds)
            centroid, pressure = world_volume_terms(x, moments, target, penalty, worlds, w)
            accumulated = triangle_forces(
                positions, patch_start, patch_local, triangle_type, basis, points_per_triangle, ref_metric,
                ref_metric_inv, ref_curvature, ref_weight, stretching_modulus[w], bending_modulus[w], nu, weights,
                centroid, pressure, with_energy, energy_density, t,
            )  # fmt: skip
        for k in range(wp.static(MAX_PATCH)):  # every lane takes part in each cooperative add
            entry = 0
            if k < size:
                entry = patch_local[start + k]
            force = type(x[0])(accumulated[k, 0], accumulated[k, 1], accumulated[k, 2])
            wp.tile_scatter_add(summed, entry, force, k < size)
        wp.tile_atomic_add_indexed(forces, indices=union, t=summed, axis=0)

    return staged_shell_forces
