"""Koiter shell forces with one thread per quadrature point (docs/theory/geometry.md#staging-patches-in-shared-memory,
the register budget): each thread contracts its point's gradient jet with the basis and adds the result to
its patch vertices with atomics. Three times the threads and the atomics of the one-thread-per-triangle
kernel (rule "3"), without its per-patch accumulator: fewer registers a thread, more warps in flight."""

from typing import Any

import warp as wp

from . import declare_overloads
from .limit_surface import jet_force
from .shell import MAX_PATCH, VolumeMoments, quadrature_point_jet


@wp.kernel
def point_forces_kernel(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
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
    forces: wp.array(dtype=Any),
):
    """`shell_forces_kernel`'s forces and energy densities, one thread per quadrature point q: its jet
    contracted with each patch vertex's basis row, added with one atomic per patch vertex."""
    q = wp.tid()
    t, row, g, g1, g2, g11, g12, g22 = quadrature_point_jet(
        x, patch_start, patch_vertices, triangle_type, basis, points_per_triangle, ref_metric, ref_metric_inv,
        ref_curvature, ref_weight, stretching_modulus, bending_modulus, nu, worlds, weights, moments, target, penalty,
        with_energy, energy_density, q,
    )  # fmt: skip
    start = patch_start[t]
    size = patch_start[t + 1] - start
    for k in range(wp.static(MAX_PATCH)):
        if k < size:
            wp.atomic_sub(forces, patch_vertices[start + k], jet_force(basis[row, k], g, g1, g2, g11, g12, g22))


declare_overloads(point_forces_kernel, x="vec3[]", weights="scalar[]", forces="vec3[]", basis="vec6[,]",
                  ref_metric="mat22[]", ref_metric_inv="mat22[]", ref_curvature="mat22[]", ref_weight="scalar[]",
                  stretching_modulus="scalar[]", bending_modulus="scalar[]", nu="scalar")  # fmt: skip
