"""Limit-surface evaluation at quadrature points (docs/theory/geometry.md): gather and sum, no per-step tables.

Generic over float32/float64 (`Any`). Symmetric 2x2 tensors (metric, curvature) are `mat22`.
Quadrature point q lies on triangle t = q // P and reads basis row `type[t] * P + q % P`.
"""

from typing import Any

import warp as wp

from . import declare_overloads


@wp.func
def basis_row(triangle_type: wp.array(dtype=wp.int32), points_per_triangle: int, q: int):
    t = q // points_per_triangle
    return t, triangle_type[t] * points_per_triangle + q % points_per_triangle


@wp.func
def patch_jet(
    x: Any,
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    t: int,
    row: int,
):
    """x, x,1, x,2, x,11, x,12, x,22 of triangle t's patch at basis row `row` (`x`: the positions, an array
    indexed by `patch_vertices`, or a block's staged positions, a shared tile indexed by its local table).

    Sums run over positions relative to the patch's first vertex (exact, since the basis is a
    partition of unity): derivatives then cancel at the patch's scale, not the shell's, which
    keeps float32 curvature accurate on large shells.
    """
    start = patch_start[t]
    size = patch_start[t + 1] - start
    origin = x[patch_vertices[start]]
    v = origin - origin
    b = basis[row, 0]
    p = b[0] * v
    x1 = b[1] * v
    x2 = b[2] * v
    x11 = b[3] * v
    x12 = b[4] * v
    x22 = b[5] * v
    for k in range(1, size):
        v = x[patch_vertices[start + k]] - origin
        b = basis[row, k]
        p += b[0] * v
        x1 += b[1] * v
        x2 += b[2] * v
        x11 += b[3] * v
        x12 += b[4] * v
        x22 += b[5] * v
    return p + origin, x1, x2, x11, x12, x22


@wp.func
def point_volume_moments(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    q: int,
):
    """Quadrature point q's terms of S = ⅓ ∫ n dω and V₀ = ⅓ ∫ x·n dω (float64), its jet from the table."""
    t, row = basis_row(triangle_type, points_per_triangle, q)
    p, x1, x2, x11, x12, x22 = patch_jet(x, patch_start, patch_vertices, basis, t, row)
    area_normal = wp.vec3d(wp.cross(x1, x2)) * (wp.float64(weights[q % points_per_triangle]) / wp.float64(3.0))
    return area_normal, wp.dot(wp.vec3d(p), area_normal)


@wp.func
def first_form(x1: Any, x2: Any):
    """Metric a_αβ = a_α·a_β."""
    a12 = wp.dot(x1, x2)
    return wp.matrix(wp.dot(x1, x1), a12, a12, wp.dot(x2, x2), shape=(2, 2))


@wp.func
def second_form(n: Any, x11: Any, x12: Any, x22: Any):
    """Curvature b_αβ = n·x,αβ (negative definite on a sphere with outward n)."""
    b12 = wp.dot(n, x12)
    return wp.matrix(wp.dot(n, x11), b12, b12, wp.dot(n, x22), shape=(2, 2))


@wp.func
def mean_curvature(a: Any, b: Any):
    """H = -½ a^{αβ} b_αβ: +1/R on a sphere with outward normals (docs/theory/scenes.md sign)."""
    trace = wp.trace(wp.inverse(a) * b)
    return -trace * type(trace)(0.5)


@wp.func
def gauss_curvature(a: Any, b: Any):
    """K = det b / det a."""
    return wp.determinant(b) / wp.determinant(a)


@wp.kernel
def limit_surface_kernel(
    x: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    weights: wp.array(dtype=Any),
    points_per_triangle: int,
    points: wp.array(dtype=Any),
    tangents: wp.array2d(dtype=Any),
    normals: wp.array(dtype=Any),
    metric: wp.array(dtype=Any),
    curvature: wp.array(dtype=Any),
    area: wp.array(dtype=Any),
    mean: wp.array(dtype=Any),
    gauss: wp.array(dtype=Any),
):
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    p, x1, x2, x11, x12, x22 = patch_jet(x, patch_start, patch_vertices, basis, t, row)
    cross = wp.cross(x1, x2)
    j = wp.length(cross)
    n = cross / j
    a = first_form(x1, x2)
    b = second_form(n, x11, x12, x22)
    points[q] = p
    tangents[q, 0] = x1
    tangents[q, 1] = x2
    normals[q] = n
    metric[q] = a
    curvature[q] = b
    area[q] = j * weights[q % points_per_triangle]
    mean[q] = mean_curvature(a, b)
    gauss[q] = gauss_curvature(a, b)


@wp.kernel
def limit_positions_kernel(
    x: wp.array(dtype=Any),
    ring_start: wp.array(dtype=wp.int32),
    ring: wp.array(dtype=wp.int32),
    centre_weight: wp.array(dtype=Any),
    ring_weight: wp.array(dtype=Any),
    limit: wp.array(dtype=Any),
):
    """Loop's limit mask: (1 - Nχ) x_i + χ Σ_ring x_j (docs/theory/scenes.md)."""
    i = wp.tid()
    s = x[i] * centre_weight[i]
    for k in range(ring_start[i], ring_start[i + 1]):
        s += ring_weight[i] * x[ring[k]]
    limit[i] = s


@wp.kernel
def limit_motion_kernel(
    x: wp.array(dtype=Any),
    v: wp.array(dtype=Any),
    ring_start: wp.array(dtype=wp.int32),
    ring: wp.array(dtype=wp.int32),
    centre_weight: wp.array(dtype=Any),
    ring_weight: wp.array(dtype=Any),
    p: wp.array(dtype=Any),
    u: wp.array(dtype=Any),
):
    """Limit points p = L x and their velocities u = L v in one pass over the rings (docs/theory/dynamics.md, docs/theory/scenes.md)."""
    i = wp.tid()
    sx = x[i] * centre_weight[i]
    sv = v[i] * centre_weight[i]
    for k in range(ring_start[i], ring_start[i + 1]):
        j = ring[k]
        sx += ring_weight[i] * x[j]
        sv += ring_weight[i] * v[j]
    p[i] = sx
    u[i] = sv


@wp.func
def patch_scalar(
    c: wp.array(dtype=Any),
    patch_start: wp.array(dtype=wp.int32),
    patch_vertices: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    t: int,
    row: int,
):
    """Σ N_k c_k of triangle t's patch at basis row `row`: a field on the surface (docs/theory/geometry.md), or with
    vec3 values the surface's points alone."""
    start = patch_start[t]
    value = basis[row, 0][0] * c[patch_vertices[start]]
    for k in range(1, patch_start[t + 1] - start):
        value += basis[row, k][0] * c[patch_vertices[start + k]]
    return value


@wp.func
def entry_point(
    entry: int,
    point: int,
    entry_triangle: wp.array(dtype=wp.int32),
    patch_start: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32),
    basis: wp.array2d(dtype=Any),
    points_per_triangle: int,
):
    """For a vertex's `entry` in the patch table (deterministic gathers): the quadrature point q of
    the entry's triangle at `point`, and the vertex's basis values there (N, N,1, …, N,22)."""
    t = entry_triangle[entry]
    q = t * points_per_triangle + point
    return q, basis[triangle_type[t] * points_per_triangle + point, entry - patch_start[t]]


@wp.kernel
def quadrature_points_kernel(
    x: wp.array(dtype=Any), patch_start: wp.array(dtype=wp.int32), patch_vertices: wp.array(dtype=wp.int32),
    triangle_type: wp.array(dtype=wp.int32), basis: wp.array2d(dtype=Any), points_per_triangle: int,
    points: wp.array(dtype=Any),
):  # fmt: skip
    """points_q = Σ N_I(q) x_I: the limit surface at every quadrature point, values only."""
    q = wp.tid()
    t, row = basis_row(triangle_type, points_per_triangle, q)
    points[q] = patch_scalar(x, patch_start, patch_vertices, basis, t, row)


_PATCH = dict(basis="vec6[,]")
declare_overloads(
    limit_surface_kernel, x="vec3[]", weights="scalar[]", points="vec3[]", tangents="vec3[,]", normals="vec3[]",
    metric="mat22[]", curvature="mat22[]", area="scalar[]", mean="scalar[]", gauss="scalar[]", **_PATCH,
)  # fmt: skip
declare_overloads(
    limit_positions_kernel, x="vec3[]", centre_weight="scalar[]", ring_weight="scalar[]", limit="vec3[]"
)  # fmt: skip
declare_overloads(
    limit_motion_kernel, x="vec3[]", v="vec3[]", centre_weight="scalar[]", ring_weight="scalar[]", p="vec3[]", u="vec3[]"
)  # fmt: skip
declare_overloads(quadrature_points_kernel, x="vec3[]", points="vec3[]", **_PATCH)
