"""Koiter shell energy and exact forces at quadrature points (docs/theory/shell.md).

Global sums (energy, volume) accumulate in float64 whatever the dtype, so that float32 runs
resolve energy changes and V - V̄ far below the float32 spacing of their totals.

Batched worlds (`Mesh.union`): the arrays hold `worlds` equal blocks (world w's vertices, triangles
and points contiguous); per-world parameters (AC, AI, moduli, V̄, μV) are arrays indexed by the
item's world, and the volume moments are one per world.

One thread per quadrature point. The active reference (ā⁻¹, ā, b̄, dω̄ weight) is computed by
`koiter_reference_kernel` or `bilayer_reference_kernel` whenever c changes; the energy kernels read it. Forces are the exact
negative gradient, scattered to the patch's control vertices with atomics, or (deterministic)
kept per point as a gradient jet (g, g,1, g,2, g,11, g,12, g,22) and gathered per vertex in a
fixed order: no atomics, bitwise-reproducible sums.
"""

from typing import Any

import warp as wp

from . import declare_overloads
from .limit_surface import (
    basis_row,
    entry_point,
    first_form,
    patch_jet,
    patch_scalar,
    point_volume_moments,
    second_form,
)
from .reduce import block_add

MAX_PATCH = wp.constant(18)  # control vertices of a patch (valence N + 6): vertices of valence up to 12
VolumeMoments = wp.types.vector(length=7, dtype=wp.float64)  # [S, ⅓ ∫ x·n dω, Σ x_I] (`volume_kernel`)


@wp.func
def store_reference(q: int, a_bar: Any, b_bar: Any, weight: Any, ref_metric: wp.array(dtype=Any),
                    ref_metric_inv: wp.array(dtype=Any), ref_curvature: wp.array(dtype=Any), ref_weight: wp.array(dtype=Any)):  # fmt: skip
    """The active reference at q: ā, ā⁻¹, b̄ and the reference area weight sqrt(det ā) w."""
    ref_metric[q] = a_bar
    ref_metric_inv[q] = wp.inverse(a_bar)
    ref_curvature[q] = b_bar
    ref_weight[q] = wp.sqrt(wp.determinant(a_bar)) * weight


@wp.kernel
def koiter_reference_kernel(
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    rest_metric: wp.array(dtype=Any),
    rest_curvature: wp.array(dtype=Any),
    AC: wp.array(dtype=Any),
    AI: wp.array(dtype=Any),
    worlds: int,
    ref_metric: wp.array(dtype=Any),
    ref_metric_inv: wp.array(dtype=Any),
    ref_curvature: wp.array(dtype=Any),
    ref_weight: wp.array(dtype=Any),
):
    """ā = e^{-AC c} ā⁰, b̄ = (1 - AI c) b̄⁰ (paper Eq. 2; docs/theory/shell.md), AC and AI of q's world."""
    q = wp.tid()
    w = q // (rest_metric.shape[0] // worlds)
    t, row = basis_row(triangle_type, points_per_triangle, q)
    cq = patch_scalar(c, patch_start, patch_vertices, basis, t, row)
    a_bar = wp.exp(-AC[w] * cq) * rest_metric[q]
    b_bar = (type(cq)(1.0) - AI[w] * cq) * rest_curvature[q]
    store_reference(q, a_bar, b_bar, weights[q % points_per_triangle], ref_metric, ref_metric_inv, ref_curvature,
                    ref_weight)  # fmt: skip


@wp.kernel
def bilayer_reference_kernel(
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    rest_metric: wp.array(dtype=Any),
    rest_curvature: wp.array(dtype=Any),
    AC: wp.array(dtype=Any),
    bilayer_A: wp.array(dtype=Any),
    worlds: int,
    ref_metric: wp.array(dtype=Any),
    ref_metric_inv: wp.array(dtype=Any),
    ref_curvature: wp.array(dtype=Any),
    ref_weight: wp.array(dtype=Any),
):
    """ā = Λ² ā⁰ with Λ² = e^{-AC c}, b̄ = Λ b̄⁰ - A c ā⁰ (the supplement's bilayer; docs/theory/shell.md)."""
    q = wp.tid()
    w = q // (rest_metric.shape[0] // worlds)
    t, row = basis_row(triangle_type, points_per_triangle, q)
    cq = patch_scalar(c, patch_start, patch_vertices, basis, t, row)
    stretch = wp.exp(-AC[w] * cq)
    a0 = rest_metric[q]
    b_bar = wp.sqrt(stretch) * rest_curvature[q] - (bilayer_A[w] * cq) * a0
    store_reference(q, stretch * a0, b_bar, weights[q % points_per_triangle], ref_metric, ref_metric_inv, ref_curvature,
                    ref_weight)  # fmt: skip


@wp.func
def material_energy(strain: Any, nu: Any):
    """(1-ν) tr(E²) + ν (tr E)² of a mixed strain tensor."""
    tr = wp.trace(strain)
    return (type(nu)(1.0) - nu) * wp.trace(strain * strain) + nu * tr * tr


@wp.func
def material_stress(strain: Any, inv: Any, nu: Any):
    """∂/∂(covariant tensor) of material_energy(inv (X - X̄)): 2(1-ν) inv E ... symmetric."""
    two = type(nu)(2.0)
    return two * (type(nu)(1.0) - nu) * (strain * inv) + (two * nu * wp.trace(strain)) * inv


@wp.func
def koiter_jet(
    x: Any,
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    t: int,
    row: int,
    ref_inv: Any,
    ref_metric: Any,
    ref_curvature: Any,
):
    """Strains of the limit surface at one point: E = ā⁻¹(a - ā), K = ā⁻¹(b - b̄), plus the jet,
    the unit normal n and the area element j = |x,1 × x,2|."""
    p, x1, x2, x11, x12, x22 = patch_jet(x, patch_start, patch_vertices, basis, t, row)
    membrane, bending, n, j = jet_strains(x1, x2, x11, x12, x22, ref_inv, ref_metric, ref_curvature)
    return membrane, bending, p, x1, x2, x11, x12, x22, n, j


@wp.func
def jet_strains(x1: Any, x2: Any, x11: Any, x12: Any, x22: Any, ref_inv: Any, ref_metric: Any, ref_curvature: Any):
    """E = ā⁻¹(a - ā), K = ā⁻¹(b - b̄), the unit normal n and the area element j of a limit-surface jet."""
    cross = wp.cross(x1, x2)
    j = wp.length(cross)
    n = cross / j
    membrane = ref_inv * (first_form(x1, x2) - ref_metric)
    bending = ref_inv * (second_form(n, x11, x12, x22) - ref_curvature)
    return membrane, bending, n, j


@wp.func
def koiter_density(membrane: Any, bending: Any, stretching_modulus: Any, bending_modulus: Any, nu: Any):
    """Stretching plus bending energy per reference area (docs/theory/shell.md)."""
    return stretching_modulus * material_energy(membrane, nu) + bending_modulus * material_energy(bending, nu)


@wp.kernel
def koiter_energy_kernel(
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
    energy_density: wp.array(dtype=wp.float64),
):
    """(E_S + E_B) density × dω̄ at every point (docs/theory/shell.md), in float64; differentiable (autodiff path)."""
    q = wp.tid()
    w = q // (ref_weight.shape[0] // worlds)
    t, row = basis_row(triangle_type, points_per_triangle, q)
    membrane, bending, p, x1, x2, x11, x12, x22, n, j = koiter_jet(
        x, patch_start, patch_vertices, basis, t, row, ref_metric_inv[q], ref_metric[q], ref_curvature[q]
    )
    density = koiter_density(membrane, bending, stretching_modulus[w], bending_modulus[w], nu)
    energy_density[q] = wp.float64(density * ref_weight[q])


@wp.func
def koiter_gradient_jet(
    membrane: Any, bending: Any, inv: Any, w: Any, stretching_modulus: Any, bending_modulus: Any, nu: Any,
    x1: Any, x2: Any, x11: Any, x12: Any, x22: Any, n: Any, j: Any,
):  # fmt: skip
    """∂(E_S + E_B)/∂(x,1, x,2, x,11, x,12, x,22) at one point (hand-derived, docs/theory/shell.md)."""
    # ∂W/∂a_αβ = S, ∂W/∂b_αβ = B (symmetric)
    S = (stretching_modulus * w) * material_stress(membrane, inv, nu)
    B = (bending_modulus * w) * material_stress(bending, inv, nu)
    two = type(w)(2.0)
    # a_αβ = a_α·a_β  ->  ∂/∂a_γ = 2 S_γβ a_β
    g1 = two * (S[0, 0] * x1 + S[0, 1] * x2)
    g2 = two * (S[1, 0] * x1 + S[1, 1] * x2)
    # b_αβ = n·x,αβ with n = a_1×a_2/|a_1×a_2|: through n, m·dn = u·d(a_1×a_2), u = (I - nnᵀ) m / j
    m = B[0, 0] * x11 + two * B[0, 1] * x12 + B[1, 1] * x22
    u = (m - wp.dot(n, m) * n) / j
    g1 += wp.cross(x2, u)
    g2 += wp.cross(u, x1)
    return g1, g2, B[0, 0] * n, two * B[0, 1] * n, B[1, 1] * n


@wp.func
def point_gradient_jet(
    x: Any,
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    t: int,
    row: int,
    q: int,
    ref_metric: wp.array(dtype=Any),
    ref_metric_inv: wp.array(dtype=Any),
    ref_curvature: wp.array(dtype=Any),
    ref_weight: wp.array(dtype=Any),
    stretching_modulus: Any,
    bending_modulus: Any,
    nu: Any,
    weight: Any,
    centroid: Any,
    pressure: wp.float64,
    with_energy: int,
    energy_density: wp.array(dtype=wp.float64),
):
    """Point q's gradient jet (g, g,1, g,2, g,11, g,12, g,22) of E_S + E_B + E_V (its energy density
    written with `with_energy`). Volume: 2 μV (V - V̄) ⅓ w [dx·(a_1×a_2) + da_1·(a_2×r) + da_2·(r×a_1)],
    r = x - x̄ (`pressure` = ⅔ μV (V - V̄))."""
    inv = ref_metric_inv[q]
    membrane, bending, p, x1, x2, x11, x12, x22, n, j = koiter_jet(
        x, patch_start, patch_vertices, basis, t, row, inv, ref_metric[q], ref_curvature[q]
    )
    return strains_gradient_jet(membrane, bending, inv, p, x1, x2, x11, x12, x22, n, j, q, ref_weight[q],
                                stretching_modulus, bending_modulus, nu, weight, centroid, pressure, with_energy,
                                energy_density)  # fmt: skip


@wp.func
def strains_gradient_jet(
    membrane: Any, bending: Any, inv: Any, p: Any, x1: Any, x2: Any, x11: Any, x12: Any, x22: Any, n: Any, j: Any,
    q: int, w: Any, stretching_modulus: Any, bending_modulus: Any, nu: Any, weight: Any, centroid: Any,
    pressure: wp.float64, with_energy: int, energy_density: wp.array(dtype=wp.float64),
):  # fmt: skip
    """`point_gradient_jet` from point q's strains and jet (reference area weight w, quadrature weight `weight`)."""
    if with_energy != 0:
        energy_density[q] = wp.float64(koiter_density(membrane, bending, stretching_modulus, bending_modulus, nu) * w)
    g1, g2, g11, g12, g22 = koiter_gradient_jet(membrane, bending, inv, w, stretching_modulus, bending_modulus, nu,
                                                x1, x2, x11, x12, x22, n, j)  # fmt: skip
    scale = type(w)(pressure) * weight
    r = p - centroid
    return scale * j * n, g1 + scale * wp.cross(x2, r), g2 + scale * wp.cross(r, x1), g11, g12, g22


@wp.func
def triangle_forces(
    x: Any,
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    ref_metric: wp.array(dtype=Any),
    ref_metric_inv: wp.array(dtype=Any),
    ref_curvature: wp.array(dtype=Any),
    ref_weight: wp.array(dtype=Any),
    stretching: Any,
    bending: Any,
    nu: Any,
    weights: wp.array(dtype=Any),
    centroid: Any,
    pressure: wp.float64,
    with_energy: int,
    energy_density: wp.array(dtype=wp.float64),
    t: int,
):
    """Triangle t's forces on its patch vertices, one row per patch entry (and its points' energy densities
    with `with_energy`): each point's gradient jet contracted with the basis and summed over the points."""
    size = patch_start[t + 1] - patch_start[t]
    accumulated = wp.matrix(shape=(MAX_PATCH, 3), dtype=type(nu))  # one row per patch vertex
    for point in range(points_per_triangle):
        q = t * points_per_triangle + point
        row = triangle_type[t] * points_per_triangle + point
        g, g1, g2, g11, g12, g22 = point_gradient_jet(
            x, patch_start, patch_vertices, basis, t, row, q, ref_metric, ref_metric_inv, ref_curvature, ref_weight,
            stretching, bending, nu, weights[point], centroid, pressure, with_energy, energy_density,
        )  # fmt: skip
        for k in range(wp.static(MAX_PATCH)):  # unrolled: the accumulators stay in registers
            if k < size:
                b = basis[row, k]
                f = b[0] * g + b[1] * g1 + b[2] * g2 + b[3] * g11 + b[4] * g12 + b[5] * g22
                for c in range(3):
                    accumulated[k, c] = accumulated[k, c] - f[c]
    return accumulated


@wp.kernel(module="unique")  # its own module: compiled for its launch (FORCE_BLOCK), not the whole module twice
def shell_forces_kernel(
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
    triangles: wp.array(dtype=wp.int32),
    energy_density: wp.array(dtype=wp.float64),
    forces: wp.array(dtype=Any),
):
    """One thread per triangle of the list `triangles`: the energy density at its points (`with_energy`)
    and the exact forces -∂(E_S + E_B + E_V)/∂x of its patch (volume term with penalty > 0; `moments` must
    hold the volume moments; the x̄ part comes from `volume_centroid_force`), added to `forces` with one
    atomic per patch vertex."""
    t = triangles[wp.tid()]
    start = patch_start[t]
    size = patch_start[t + 1] - start
    w = t // (triangle_type.shape[0] // worlds)
    centroid, pressure = world_volume_terms(x, moments, target, penalty, worlds, w)
    accumulated = triangle_forces(
        x, patch_start, patch_vertices, triangle_type, basis, points_per_triangle, ref_metric, ref_metric_inv,
        ref_curvature, ref_weight, stretching_modulus[w], bending_modulus[w], nu, weights, centroid, pressure,
        with_energy, energy_density, t,
    )  # fmt: skip
    for k in range(wp.static(MAX_PATCH)):
        if k < size:
            force = type(x[0])(accumulated[k, 0], accumulated[k, 1], accumulated[k, 2])
            wp.atomic_add(forces, patch_vertices[start + k], force)


@wp.kernel
def shell_force_jets_kernel(
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
    jets: wp.array2d(dtype=Any),
):
    """As shell_forces_kernel, one thread per quadrature point, writing the point's gradient jet to
    `jets` for the deterministic `gather_forces_kernel` (no atomics)."""
    q = wp.tid()
    w = q // (ref_weight.shape[0] // worlds)
    t, row = basis_row(triangle_type, points_per_triangle, q)
    centroid, pressure = world_volume_terms(x, moments, target, penalty, worlds, w)
    g, g1, g2, g11, g12, g22 = point_gradient_jet(
        x, patch_start, patch_vertices, basis, t, row, q, ref_metric, ref_metric_inv, ref_curvature, ref_weight,
        stretching_modulus[w], bending_modulus[w], nu, weights[q % points_per_triangle], centroid, pressure,
        with_energy, energy_density,
    )  # fmt: skip
    jets[q, 0] = g
    jets[q, 1] = g1
    jets[q, 2] = g2
    jets[q, 3] = g11
    jets[q, 4] = g12
    jets[q, 5] = g22


@wp.kernel
def sum_kernel(values: wp.array(dtype=Any), total: wp.array(dtype=Any)):
    """total[0] += Σ values (differentiable; the analytic path reduces with wp.utils.array_sum)."""
    i = wp.tid()
    wp.atomic_add(total, 0, values[i])


@wp.func
def moments_centroid(m: VolumeMoments, n_vertices: int):
    """x̄ of one world's moments."""
    return wp.vec3d(m[4], m[5], m[6]) / wp.float64(n_vertices)


@wp.func
def moments_normal_sum(m: VolumeMoments):
    return wp.vec3d(m[0], m[1], m[2])


@wp.func
def volume_about_centroid(m: VolumeMoments, n_vertices: int):
    """V = ⅓ ∫ (x - x̄)·n dω = V₀ - x̄·S: exactly translation invariant (docs/theory/shell.md)."""
    return m[3] - wp.dot(moments_centroid(m, n_vertices), moments_normal_sum(m))


@wp.func
def volume_pressure(m: VolumeMoments, n_vertices: int, target: wp.float64, penalty: wp.float64):
    """⅔ μV (V - V̄), the factor of the volume term's point jets."""
    return wp.float64(2.0) / wp.float64(3.0) * penalty * (volume_about_centroid(m, n_vertices) - target)


@wp.func
def world_volume_terms(x: wp.array(dtype=Any), moments: wp.array(dtype=VolumeMoments),
                       target: wp.array(dtype=wp.float64), penalty: wp.array(dtype=wp.float64), worlds: int, w: int):
    """World w's centroid x̄ (in x's type) and `volume_pressure`, shared by every point of the world."""
    vertices = x.shape[0] // worlds
    centroid = type(x[0])(moments_centroid(moments[w], vertices))
    return centroid, volume_pressure(moments[w], vertices, target[w], penalty[w])


@wp.func
def volume_item(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    worlds: int,
    w: int,
    i: int,
):
    """Item i of world w's share of the world's volume moments: its quadrature point i's terms of
    S = ⅓ ∫ n dω and V₀ = ⅓ ∫ x·n dω, and its control point i's of Σx (float64)."""
    area_normal = wp.vec3d()
    moment = wp.float64(0.0)
    xi = wp.vec3d()
    points = triangle_type.shape[0] * points_per_triangle // worlds
    vertices = x.shape[0] // worlds
    if i < points:
        area_normal, moment = point_volume_moments(x, patch_start, patch_vertices, triangle_type, basis, weights,
                                                   points_per_triangle, w * points + i)  # fmt: skip
    if i < vertices:
        xi = wp.vec3d(x[w * vertices + i])
    return area_normal, moment, xi


@wp.kernel
def volume_terms_kernel(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    terms: wp.array(dtype=VolumeMoments),
):
    """terms_i = item i's share of the volume moments (`volume_item`; one world), for a differentiable sum."""
    i = wp.tid()
    a, v, y = volume_item(x, patch_start, patch_vertices, triangle_type, basis, weights, points_per_triangle, 1, 0, i)
    terms[i] = VolumeMoments(a[0], a[1], a[2], v, y[0], y[1], y[2])


@wp.kernel
def volume_kernel(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    worlds: int,
    items: int,
    threads: int,
    moments: wp.array(dtype=VolumeMoments),
):
    """moments[w] += world w's volume moments [S, V₀, Σx] over its max(points, vertices) `items`,
    `threads` per world (whole blocks), thread t of world w taking items t, t + threads, ...
    (`volume_item`; docs/theory/shell.md; V = V₀ - x̄·S about the control centroid,
    `volume_about_centroid`). Zeroed by the caller; one atomic per block."""
    w = wp.tid() // threads
    area_normal = wp.vec3d()
    moment = wp.float64(0.0)
    xi = wp.vec3d()
    for i in range(wp.tid() - w * threads, items, threads):
        a, v, y = volume_item(x, patch_start, patch_vertices, triangle_type, basis, weights, points_per_triangle,
                              worlds, w, i)  # fmt: skip
        area_normal += a
        moment += v
        xi += y
    block_add(moments, w, VolumeMoments(area_normal[0], area_normal[1], area_normal[2], moment, xi[0], xi[1], xi[2]))


@wp.func
def volume_centroid_force(moments: wp.array(dtype=VolumeMoments), target: wp.array(dtype=wp.float64),
                          penalty: wp.array(dtype=wp.float64), vertices: int, i: int):  # fmt: skip
    """The x̄ part of -∂E_V/∂x_I, the same on every vertex of I's world w: 2 μV (V - V̄) S / N."""
    w = i // vertices
    m = moments[w]
    d = volume_about_centroid(m, vertices) - target[w]
    return moments_normal_sum(m) * (wp.float64(2.0) * penalty[w] * d / wp.float64(vertices))


@wp.kernel
def volume_centroid_forces_kernel(
    moments: wp.array(dtype=VolumeMoments), target: wp.array(dtype=wp.float64), penalty: wp.array(dtype=wp.float64),
    worlds: int, forces: wp.array(dtype=Any),
):  # fmt: skip
    """forces = the x̄ part of -∂E_V/∂x (overwritten: it starts the atomic scatter's sum)."""
    i = wp.tid()
    forces[i] = type(forces[i])(volume_centroid_force(moments, target, penalty, forces.shape[0] // worlds, i))


@wp.kernel
def volume_energy_kernel(moments: wp.array(dtype=VolumeMoments), vertices: int, target: wp.array(dtype=wp.float64),
                         penalty: wp.array(dtype=wp.float64), energy: wp.array(dtype=wp.float64)):  # fmt: skip
    """E_V = μV (V - V̄)² of world w (one thread each; `vertices` per world) added to energy[w] (float64;
    to energy[0], the total, where energy holds one entry)."""
    w = wp.tid()
    d = volume_about_centroid(moments[w], vertices) - target[w]
    wp.atomic_add(energy, wp.min(w, energy.shape[0] - 1), penalty[w] * d * d)


@wp.kernel
def gather_forces_kernel(
    jets: wp.array2d(dtype=Any),
    vertex_entry_start: wp.array(dtype=wp.int32),
    vertex_entries: wp.array(dtype=wp.int32),
    entry_triangle: wp.array(dtype=wp.int32),
    patch_start: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    moments: wp.array(dtype=VolumeMoments),
    target: wp.array(dtype=wp.float64),
    penalty: wp.array(dtype=wp.float64),
    worlds: int,
    forces: wp.array(dtype=Any),
):
    """Deterministic forces (overwritten): vertex I gathers -Σ N_I,· · (g, g1, g2, g11, g12, g22) over the quadrature
    points of every patch it belongs to, in a fixed order (no atomics; bitwise reproducible), plus the
    volume's x̄ part."""
    i = wp.tid()
    f = type(forces[i])()
    vertices = forces.shape[0] // worlds
    if penalty[i // vertices] > wp.float64(0.0):
        f = type(forces[i])(volume_centroid_force(moments, target, penalty, vertices, i))
    for e in range(vertex_entry_start[i], vertex_entry_start[i + 1]):
        for point in range(points_per_triangle):
            q, b = entry_point(vertex_entries[e], point, entry_triangle, patch_start, triangle_type, basis,
                               points_per_triangle)  # fmt: skip
            f -= b[0] * jets[q, 0] + b[1] * jets[q, 1] + b[2] * jets[q, 2]
            f -= b[3] * jets[q, 3] + b[4] * jets[q, 4] + b[5] * jets[q, 5]
    forces[i] = f


@wp.kernel
def negate_kernel(a: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    """out = -a (autodiff forces from the energy gradient)."""
    i = wp.tid()
    out[i] = -a[i]


_PATCH = dict(basis="vec6[,]")
_REFERENCE = dict(ref_metric="mat22[]", ref_metric_inv="mat22[]", ref_curvature="mat22[]", ref_weight="scalar[]")
_MODULI = dict(stretching_modulus="scalar[]", bending_modulus="scalar[]", nu="scalar")
declare_overloads(koiter_reference_kernel, c="scalar[]", weights="scalar[]", rest_metric="mat22[]",
                  rest_curvature="mat22[]", AC="scalar[]", AI="scalar[]", **_PATCH, **_REFERENCE)  # fmt: skip
declare_overloads(bilayer_reference_kernel, c="scalar[]", weights="scalar[]", rest_metric="mat22[]",
                  rest_curvature="mat22[]", AC="scalar[]", bilayer_A="scalar[]", **_PATCH, **_REFERENCE)  # fmt: skip
declare_overloads(koiter_energy_kernel, x="vec3[]", **_PATCH, **_REFERENCE, **_MODULI)
declare_overloads(shell_forces_kernel, x="vec3[]", weights="scalar[]", forces="vec3[]", **_PATCH, **_REFERENCE, **_MODULI)
FORCE_BLOCK = 64  # threads a block of the force kernel's launch: its module's default, what it compiles for
wp.set_module_options({"block_dim": FORCE_BLOCK}, shell_forces_kernel.module)
declare_overloads(shell_force_jets_kernel, x="vec3[]", weights="scalar[]", jets="vec3[,]", **_PATCH, **_REFERENCE,
                  **_MODULI)  # fmt: skip
declare_overloads(volume_terms_kernel, x="vec3[]", weights="scalar[]", **_PATCH)
declare_overloads(volume_kernel, x="vec3[]", weights="scalar[]", **_PATCH)
declare_overloads(volume_centroid_forces_kernel, forces="vec3[]")
declare_overloads(gather_forces_kernel, jets="vec3[,]", forces="vec3[]", **_PATCH)
declare_overloads(negate_kernel, a="vec3[]", out="vec3[]")
wp.overload(sum_kernel, {"values": wp.array(dtype=wp.float64), "total": wp.array(dtype=wp.float64)})
wp.overload(sum_kernel, {"values": wp.array(dtype=VolumeMoments), "total": wp.array(dtype=VolumeMoments)})
