"""Laplace–Beltrami mass and stiffness (docs/theory/chemistry.md, docs/theory/scenes.md): Galerkin on the Loop basis, and P1.

Subdivision (one thread per quadrature point q of triangle t, patch vertices k):

    M_I = Σ_q N_I j w_q                       (lumped mass, ∫ N_I dω)
    (K c)_I = Σ_q N_I,α D^{αβ} c,β           D = a^{-1} j w_q = adj(a) w_q / max(j, j_floor)

j_floor (a hundredth of the rest j) only acts where the limit surface is singular: a fold sharper
than the mesh, where the tangents turn parallel and D would grow as 1/j (docs/theory/chemistry.md).

`surface_metric_kernel` computes D and M whenever the positions change; `stiffness_kernel`
then only gathers c,β over the patch and scatters N_I,α D^{αβ} c,β with atomics.

Deterministic (a fixed summation order, bitwise-reproducible on a GPU): each point writes its
factors (s₀, s₁, s₂) — dω for M, c dω for the consistent mass, D^{αβ} c,β for K — and
`gather_point_factors_kernel` sums out_I = Σ N_I s₀ + N_I,1 s₁ + N_I,2 s₂ over vertex I's
patch entries in table order, one thread per vertex, no atomics.

Assembled (`assembled=True`): the same K_IJ, J ≠ I, summed once per surface into CSR rows
(`assemble_stiffness_kernel`, binary search for the slot), then applied by one gather-only
thread per vertex, `(K c)_I = Σ_J K_IJ (c_J - c_I)`: no atomics, K·1 = 0 exactly.

P1 (cotangent) on the control connectivity with vertices at positions p, one thread per
triangle: `p1_geometry_kernel` stores ½ cot of each corner's angle (the weight of the opposite
edge) and scatters a third of the area to each corner; `p1_stiffness_kernel` scatters
w (c_i - c_j) along the three edges.

The consistent mass actions (`∫ N_I N_J dω c_J`) serve the mass-corrected steppers
(docs/theory/chemistry.md); the vector kernels below serve power iteration and conjugate gradients.

Generic over float32/float64 (`Any`); typed constants as `type(v)(...)`.
"""

from typing import Any

import warp as wp

from . import declare_overloads
from .limit_surface import basis_row, entry_point, patch_scalar


@wp.func
def patch_tangents(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    t: int,
    row: int,
):
    """a_1 = x,1 and a_2 = x,2 of triangle t's patch at basis row `row` (relative sums, as patch_jet)."""
    start = patch_start[t]
    origin = x[patch_vertices[start]]
    b = basis[row, 0]
    a1 = b[1] * (origin - origin)
    a2 = a1
    for k in range(1, patch_start[t + 1] - start):
        v = x[patch_vertices[start + k]] - origin
        b = basis[row, k]
        a1 += b[1] * v
        a2 += b[2] * v
    return a1, a2


@wp.func
def surface_metric(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    w: Any,
    j_floor: Any,
    t: int,
    row: int,
):
    """D = adj(a) w / max(j, j_floor) and dω = j w at a point of triangle t (basis row `row`)."""
    a1, a2 = patch_tangents(x, patch_start, patch_vertices, basis, t, row)
    a11 = wp.dot(a1, a1)
    a12 = wp.dot(a1, a2)
    a22 = wp.dot(a2, a2)
    j = wp.length(wp.cross(a1, a2))
    s = w / wp.max(j, j_floor)
    return wp.matrix(a22 * s, -a12 * s, -a12 * s, a11 * s, shape=(2, 2)), j * w


@wp.kernel
def surface_metric_kernel(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    j_floor: wp.array(dtype=Any),
    flux_metric: wp.array(dtype=Any),
    area: wp.array(dtype=Any),
    mass: wp.array(dtype=Any),
):
    """D and dω at q (`surface_metric`); M_I += N_I dω (mass zeroed by the caller)."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    D, dw = surface_metric(x, patch_start, patch_vertices, basis, weights[q % points_per_triangle], j_floor[q], t, row)
    flux_metric[q] = D
    area[q] = dw
    start = patch_start[t]
    for k in range(patch_start[t + 1] - start):
        wp.atomic_add(mass, patch_vertices[start + k], basis[row, k][0] * dw)


@wp.kernel
def surface_metric_factors_kernel(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    j_floor: wp.array(dtype=Any),
    flux_metric: wp.array(dtype=Any),
    area: wp.array(dtype=Any),
    factors: wp.array(dtype=Any),
):
    """D and dω at q, and factors_q = (dω, 0, 0): the lumped mass's, for the gather (no atomics)."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    D, dw = surface_metric(x, patch_start, patch_vertices, basis, weights[q % points_per_triangle], j_floor[q], t, row)
    flux_metric[q] = D
    area[q] = dw
    zero = type(dw)(0.0)
    factors[q] = type(factors[q])(dw, zero, zero)


@wp.kernel
def consistent_mass_kernel(
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    area: wp.array(dtype=Any),
    out: wp.array(dtype=Any),
):
    """out_I += N_I c_q dω at q: the consistent Galerkin mass ∫ N_I N_J dω c_J (out zeroed by the caller)."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    value = patch_scalar(c, patch_start, patch_vertices, basis, t, row) * area[q]
    start = patch_start[t]
    for k in range(patch_start[t + 1] - start):
        wp.atomic_add(out, patch_vertices[start + k], basis[row, k][0] * value)


@wp.kernel
def stiffness_kernel(
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    flux_metric: wp.array(dtype=Any),
    out: wp.array(dtype=Any),
):
    """out_I += Σ N_I,α D^{αβ} c,β at q (out zeroed by the caller).

    c,β sums c_k - c_0 (partition of unity), so K annihilates constants exactly.
    """
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    start = patch_start[t]
    size = patch_start[t + 1] - start
    c0 = c[patch_vertices[start]]
    g1 = c0 - c0
    g2 = g1
    for k in range(1, size):
        d = c[patch_vertices[start + k]] - c0
        b = basis[row, k]
        g1 += b[1] * d
        g2 += b[2] * d
    D = flux_metric[q]
    f1 = D[0, 0] * g1 + D[0, 1] * g2
    f2 = D[1, 0] * g1 + D[1, 1] * g2
    for k in range(size):
        b = basis[row, k]
        wp.atomic_add(out, patch_vertices[start + k], b[1] * f1 + b[2] * f2)


@wp.kernel
def stiffness_diagonal_kernel(
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    flux_metric: wp.array(dtype=Any),
    diagonal: wp.array(dtype=Any),
):
    """K_II += N_k,α D^{αβ} N_l,β at q over patch slots k, l holding vertex I (diagonal zeroed by the caller)."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    start = patch_start[t]
    size = patch_start[t + 1] - start
    D = flux_metric[q]
    for k in range(size):
        i = patch_vertices[start + k]
        bk = basis[row, k]
        for l in range(size):
            if patch_vertices[start + l] == i:  # l = k, or the same vertex twice in a small patch
                bl = basis[row, l]
                value = bk[1] * (D[0, 0] * bl[1] + D[0, 1] * bl[2]) + bk[2] * (D[1, 0] * bl[1] + D[1, 1] * bl[2])
                wp.atomic_add(diagonal, i, value)


@wp.kernel
def mass_factors_kernel(
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    area: wp.array(dtype=Any),
    factors: wp.array(dtype=Any),
):
    """factors_q = (c_q dω, 0, 0): the consistent mass action's, for the gather."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    value = patch_scalar(c, patch_start, patch_vertices, basis, t, row) * area[q]
    zero = type(value)(0.0)
    factors[q] = type(factors[q])(value, zero, zero)


@wp.kernel
def flux_factors_kernel(
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    flux_metric: wp.array(dtype=Any),
    factors: wp.array(dtype=Any),
):
    """factors_q = (0, D^{1β} c,β, D^{2β} c,β): the stiffness action's, for the gather (c,β by `patch_tangents`)."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    g1, g2 = patch_tangents(c, patch_start, patch_vertices, basis, t, row)
    D = flux_metric[q]
    factors[q] = type(factors[q])(type(g1)(0.0), D[0, 0] * g1 + D[0, 1] * g2, D[1, 0] * g1 + D[1, 1] * g2)


@wp.kernel
def gather_point_factors_kernel(
    factors: wp.array(dtype=Any),
    vertex_entry_start: wp.array(dtype=wp.int32),
    vertex_entries: wp.array(dtype=wp.int32),
    entry_triangle: wp.array(dtype=wp.int32),
    patch_start: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    out: wp.array(dtype=Any),
):
    """out_I = Σ N_I s₀ + N_I,1 s₁ + N_I,2 s₂ over the points of every patch holding I, in table
    order (overwritten; no atomics, bitwise-reproducible)."""
    i = wp.tid()
    total = type(out[i])(0.0)
    for e in range(vertex_entry_start[i], vertex_entry_start[i + 1]):
        for point in range(points_per_triangle):
            q, b = entry_point(vertex_entries[e], point, entry_triangle, patch_start, triangle_type, basis,
                               points_per_triangle)  # fmt: skip
            s = factors[q]
            total += b[0] * s[0] + b[1] * s[1] + b[2] * s[2]
    out[i] = total


@wp.kernel
def p1_geometry_kernel(
    p: wp.array(dtype=Any),
    triangles: wp.array2d(dtype=wp.int32),
    cot_weight: wp.array(dtype=Any),
    area: wp.array(dtype=Any),
    mass: wp.array(dtype=Any),
):
    """½ cot of each corner's angle (weight of the opposite edge), the area; M_i += area / 3."""
    t = wp.tid()
    i = triangles[t, 0]
    j = triangles[t, 1]
    k = triangles[t, 2]
    pi = p[i]
    pj = p[j]
    pk = p[k]
    twice_area = wp.length(wp.cross(pj - pi, pk - pi))
    half = type(twice_area)(0.5)
    s = half / twice_area
    cot_weight[t] = type(pi)(
        wp.dot(pj - pi, pk - pi) * s, wp.dot(pk - pj, pi - pj) * s, wp.dot(pi - pk, pj - pk) * s
    )
    area[t] = twice_area * half
    third = twice_area / type(twice_area)(6.0)
    wp.atomic_add(mass, i, third)
    wp.atomic_add(mass, j, third)
    wp.atomic_add(mass, k, third)


@wp.func
def edge_flux(out: wp.array(dtype=Any), c: wp.array(dtype=Any), weight: Any, i: int, j: int):
    f = weight * (c[i] - c[j])
    wp.atomic_add(out, i, f)
    wp.atomic_sub(out, j, f)


@wp.kernel
def p1_stiffness_kernel(
    c: wp.array(dtype=Any),
    triangles: wp.array2d(dtype=wp.int32),
    cot_weight: wp.array(dtype=Any),
    out: wp.array(dtype=Any),
):
    """out_i += Σ_j w_ij (c_i - c_j) over the triangle's edges (out zeroed by the caller)."""
    t = wp.tid()
    i = triangles[t, 0]
    j = triangles[t, 1]
    k = triangles[t, 2]
    w = cot_weight[t]
    edge_flux(out, c, w[0], j, k)
    edge_flux(out, c, w[1], k, i)
    edge_flux(out, c, w[2], i, j)


@wp.kernel
def p1_consistent_mass_kernel(c: wp.array(dtype=Any), triangles: wp.array2d(dtype=wp.int32), area: wp.array(dtype=Any),
                              out: wp.array(dtype=Any)):  # fmt: skip
    """out_i += A/12 (2 c_i + c_j + c_k): the consistent P1 mass (out zeroed by the caller)."""
    t = wp.tid()
    i = triangles[t, 0]
    j = triangles[t, 1]
    k = triangles[t, 2]
    s = area[t] / type(area[t])(12.0)
    total = c[i] + c[j] + c[k]
    wp.atomic_add(out, i, s * (total + c[i]))
    wp.atomic_add(out, j, s * (total + c[j]))
    wp.atomic_add(out, k, s * (total + c[k]))


@wp.kernel
def p1_diagonal_kernel(triangles: wp.array2d(dtype=wp.int32), cot_weight: wp.array(dtype=Any), diagonal: wp.array(dtype=Any)):
    """K_ii += w of each edge at i (diagonal zeroed by the caller)."""
    t = wp.tid()
    i = triangles[t, 0]
    j = triangles[t, 1]
    k = triangles[t, 2]
    w = cot_weight[t]
    wp.atomic_add(diagonal, i, w[1] + w[2])
    wp.atomic_add(diagonal, j, w[2] + w[0])
    wp.atomic_add(diagonal, k, w[0] + w[1])


@wp.func
def find_slot(columns: wp.array(dtype=wp.int32), begin: int, end: int, j: int):
    """Index of column j in the sorted columns[begin:end] (binary search; j is present)."""
    low = begin
    high = end - 1
    while low < high:
        middle = (low + high) // 2
        if columns[middle] < j:
            low = middle + 1
        else:
            high = middle
    return low


@wp.kernel
def assemble_stiffness_kernel(
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    flux_metric: wp.array(dtype=Any),
    row_start: wp.array(dtype=wp.int32),
    columns: wp.array(dtype=wp.int32),
    values: wp.array(dtype=Any),
):
    """Off-diagonal K_IJ += Σ_q N_I,α D^{αβ} N_J,β of triangle t into CSR (values zeroed by the caller)."""
    t = wp.tid()
    start = patch_start[t]
    size = patch_start[t + 1] - start
    row0 = triangle_type[t] * points_per_triangle
    q0 = t * points_per_triangle
    for k in range(size):
        i = patch_vertices[start + k]
        for l in range(size):
            j = patch_vertices[start + l]
            if j != i:  # (a small patch may hold a vertex twice: compare vertices, not slots)
                value = flux_metric[q0][0, 0] - flux_metric[q0][0, 0]
                for p in range(points_per_triangle):
                    bk = basis[row0 + p, k]
                    bl = basis[row0 + p, l]
                    D = flux_metric[q0 + p]
                    value += bk[1] * (D[0, 0] * bl[1] + D[0, 1] * bl[2]) + bk[2] * (D[1, 0] * bl[1] + D[1, 1] * bl[2])
                wp.atomic_add(values, find_slot(columns, row_start[i], row_start[i + 1], j), value)


@wp.kernel
def assemble_mass_kernel(
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
    area: wp.array(dtype=Any),
    row_start: wp.array(dtype=wp.int32),
    columns: wp.array(dtype=wp.int32),
    values: wp.array(dtype=Any),
    diagonal: wp.array(dtype=Any),
):
    """Consistent mass ∫ N_I N_J dω of triangle t into CSR (off-diagonal) and `diagonal` (both zeroed by the caller)."""
    t = wp.tid()
    start = patch_start[t]
    size = patch_start[t + 1] - start
    row0 = triangle_type[t] * points_per_triangle
    q0 = t * points_per_triangle
    for k in range(size):
        i = patch_vertices[start + k]
        for l in range(size):
            value = area[q0] - area[q0]
            for p in range(points_per_triangle):
                value += basis[row0 + p, k][0] * basis[row0 + p, l][0] * area[q0 + p]
            j = patch_vertices[start + l]
            if j == i:
                wp.atomic_add(diagonal, i, value)
            else:
                wp.atomic_add(values, find_slot(columns, row_start[i], row_start[i + 1], j), value)


@wp.kernel
def p1_assemble_mass_kernel(triangles: wp.array2d(dtype=wp.int32), area: wp.array(dtype=Any), row_start: wp.array(dtype=wp.int32),
                            columns: wp.array(dtype=wp.int32), values: wp.array(dtype=Any), diagonal: wp.array(dtype=Any)):  # fmt: skip
    """Consistent P1 mass: A/6 on the diagonal, A/12 off it (both zeroed by the caller)."""
    t = wp.tid()
    off = area[t] / type(area[t])(12.0)
    for a in range(3):
        i = triangles[t, a]
        wp.atomic_add(diagonal, i, off + off)
        for b in range(3):
            if b != a:
                j = triangles[t, b]
                wp.atomic_add(values, find_slot(columns, row_start[i], row_start[i + 1], j), off)


@wp.kernel
def assembled_mass_kernel(c: wp.array(dtype=Any), row_start: wp.array(dtype=wp.int32), columns: wp.array(dtype=wp.int32),
                          values: wp.array(dtype=Any), diagonal: wp.array(dtype=Any), out: wp.array(dtype=Any)):  # fmt: skip
    """out_I = M_II c_I + Σ_{J≠I} M_IJ c_J."""
    i = wp.tid()
    s = diagonal[i] * c[i]
    for slot in range(row_start[i], row_start[i + 1]):
        s += values[slot] * c[columns[slot]]
    out[i] = s


@wp.func
def add_edge(row_start: wp.array(dtype=wp.int32), columns: wp.array(dtype=wp.int32), values: wp.array(dtype=Any),
             weight: Any, i: int, j: int):  # fmt: skip
    wp.atomic_sub(values, find_slot(columns, row_start[i], row_start[i + 1], j), weight)
    wp.atomic_sub(values, find_slot(columns, row_start[j], row_start[j + 1], i), weight)


@wp.kernel
def p1_assemble_kernel(triangles: wp.array2d(dtype=wp.int32), cot_weight: wp.array(dtype=Any),
                       row_start: wp.array(dtype=wp.int32), columns: wp.array(dtype=wp.int32), values: wp.array(dtype=Any)):  # fmt: skip
    """Off-diagonal K_ij -= w_ij along the triangle's edges into CSR (values zeroed by the caller)."""
    t = wp.tid()
    i = triangles[t, 0]
    j = triangles[t, 1]
    k = triangles[t, 2]
    w = cot_weight[t]
    add_edge(row_start, columns, values, w[0], j, k)
    add_edge(row_start, columns, values, w[1], k, i)
    add_edge(row_start, columns, values, w[2], i, j)


@wp.kernel
def assembled_stiffness_kernel(c: wp.array(dtype=Any), row_start: wp.array(dtype=wp.int32), columns: wp.array(dtype=wp.int32),
                               values: wp.array(dtype=Any), out: wp.array(dtype=Any)):  # fmt: skip
    """out_I = Σ_{J≠I} K_IJ (c_J - c_I): K c with K·1 = 0 exactly (the diagonal is -Σ_J K_IJ)."""
    i = wp.tid()
    ci = c[i]
    s = ci - ci
    for slot in range(row_start[i], row_start[i + 1]):
        s += values[slot] * (c[columns[slot]] - ci)
    out[i] = s


@wp.kernel
def assembled_diagonal_kernel(row_start: wp.array(dtype=wp.int32), values: wp.array(dtype=Any), diagonal: wp.array(dtype=Any)):
    """K_II = -Σ_{J≠I} K_IJ."""
    i = wp.tid()
    s = values[row_start[i]] - values[row_start[i]]
    for slot in range(row_start[i], row_start[i + 1]):
        s -= values[slot]
    diagonal[i] = s


_PATCH = dict(basis="vec6[,]")
declare_overloads(surface_metric_kernel, x="vec3[]", weights="scalar[]", j_floor="scalar[]", flux_metric="mat22[]",
                  area="scalar[]", mass="scalar[]", **_PATCH)  # fmt: skip
declare_overloads(surface_metric_factors_kernel, x="vec3[]", weights="scalar[]", j_floor="scalar[]",
                  flux_metric="mat22[]", area="scalar[]", factors="vec3[]", **_PATCH)  # fmt: skip
declare_overloads(consistent_mass_kernel, c="scalar[]", area="scalar[]", out="scalar[]", **_PATCH)
declare_overloads(stiffness_kernel, c="scalar[]", flux_metric="mat22[]", out="scalar[]", **_PATCH)
declare_overloads(stiffness_diagonal_kernel, flux_metric="mat22[]", diagonal="scalar[]", **_PATCH)
declare_overloads(mass_factors_kernel, c="scalar[]", area="scalar[]", factors="vec3[]", **_PATCH)
declare_overloads(flux_factors_kernel, c="scalar[]", flux_metric="mat22[]", factors="vec3[]", **_PATCH)
declare_overloads(gather_point_factors_kernel, factors="vec3[]", out="scalar[]", **_PATCH)
declare_overloads(p1_geometry_kernel, p="vec3[]", cot_weight="vec3[]", area="scalar[]", mass="scalar[]")
declare_overloads(p1_consistent_mass_kernel, c="scalar[]", area="scalar[]", out="scalar[]")
declare_overloads(p1_stiffness_kernel, c="scalar[]", cot_weight="vec3[]", out="scalar[]")
declare_overloads(p1_diagonal_kernel, cot_weight="vec3[]", diagonal="scalar[]")
declare_overloads(assemble_stiffness_kernel, flux_metric="mat22[]", values="scalar[]", **_PATCH)
declare_overloads(p1_assemble_kernel, cot_weight="vec3[]", values="scalar[]")
declare_overloads(assembled_stiffness_kernel, c="scalar[]", values="scalar[]", out="scalar[]")
declare_overloads(assembled_diagonal_kernel, values="scalar[]", diagonal="scalar[]")
declare_overloads(assemble_mass_kernel, area="scalar[]", values="scalar[]", diagonal="scalar[]", **_PATCH)
declare_overloads(p1_assemble_mass_kernel, area="scalar[]", values="scalar[]", diagonal="scalar[]")
declare_overloads(assembled_mass_kernel, c="scalar[]", values="scalar[]", diagonal="scalar[]", out="scalar[]")


# ---------------------------------------------------------------- vector operations


@wp.kernel
def normalize_kernel(y: wp.array(dtype=Any), norm_squared: wp.array(dtype=Any), u: wp.array(dtype=Any)):
    """u = y / sqrt(norm_squared)."""
    i = wp.tid()
    u[i] = y[i] / wp.sqrt(norm_squared[0])


@wp.kernel
def divide_kernel(f: wp.array(dtype=Any), mass: wp.array(dtype=Any), out: wp.array(dtype=Any)):
    """out = M⁻¹ f (lumped mass)."""
    i = wp.tid()
    out[i] = f[i] / mass[i]


@wp.kernel
def richardson_kernel(f: wp.array(dtype=Any), Mr: wp.array(dtype=Any), mass: wp.array(dtype=Any), r: wp.array(dtype=Any)):
    """r += M_L⁻¹ (f - M_c r): one preconditioned Richardson step towards M_c r = f."""
    i = wp.tid()
    r[i] = r[i] + (f[i] - Mr[i]) / mass[i]


@wp.kernel
def dot_kernel(a: wp.array(dtype=Any), b: wp.array(dtype=Any), stride: int, out: wp.array(dtype=Any)):
    """out[0] += Σ a_i b_i (out zeroed by the caller; launched with dim = stride ≤ len(a)):
    thread t sums entries t, t + stride, ..., then adds its partial sum atomically."""
    thread = wp.tid()
    s = a[thread] * b[thread]
    for k in range(thread + stride, a.shape[0], stride):
        s += a[k] * b[k]
    wp.atomic_add(out, 0, s)


@wp.kernel
def weighted_dot_kernel(a: wp.array(dtype=Any), b: wp.array(dtype=Any), weight: wp.array(dtype=Any), stride: int,
                        out: wp.array(dtype=Any)):  # fmt: skip
    """out[0] += Σ a_i weight_i b_i, as dot_kernel."""
    thread = wp.tid()
    s = a[thread] * weight[thread] * b[thread]
    for k in range(thread + stride, a.shape[0], stride):
        s += a[k] * weight[k] * b[k]
    wp.atomic_add(out, 0, s)


_S = "scalar[]"
declare_overloads(normalize_kernel, y=_S, norm_squared=_S, u=_S)
declare_overloads(divide_kernel, f=_S, mass=_S, out=_S)
declare_overloads(richardson_kernel, f=_S, Mr=_S, mass=_S, r=_S)
declare_overloads(dot_kernel, a=_S, b=_S, out=_S)
declare_overloads(weighted_dot_kernel, a=_S, b=_S, weight=_S, out=_S)
