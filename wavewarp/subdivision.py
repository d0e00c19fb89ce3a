"""Loop subdivision (docs/theory/geometry.md): the scheme's rules, the exact patch basis and patch extraction.

* `loop_beta`, `limit_weight`: Loop's original vertex weight and the limit-position mask.
* `loop_subdivide`: one step of Loop subdivision applied to any per-vertex data.
* `regular_basis`: the 12 quartic box splines of a regular patch (Stam 1998, Cirak, Ortiz &
  Schröder 2000, Eq. 17), with first and second parameter derivatives.
* `patch_basis`: exact evaluation on a patch with one extraordinary corner of valence N by
  repeated local subdivision: the point is mapped into a regular sub-patch at level n and the
  box splines there are pulled back through the subdivision matrices. Those matrices are not
  typed in; they are derived for each N by subdividing a small synthetic patch with
  `loop_subdivide` and reading its rings with the same extraction the meshes use.

Basis arrays hold, per control vertex, the six columns [N, N,1, N,2, N,11, N,12, N,22] with
parameters (θ1, θ2) = (v, w): barycentric coordinates of the triangle's 2nd and 3rd vertex.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .topology import Topology

MIN_VALENCE = 3
MAX_VALENCE = 16
N_BASIS_COLUMNS = 6  # value, two first and three second derivatives


def loop_beta(valence):
    """Loop's original vertex weight β(N) = (5/8 - (3/8 + cos(2π/N)/4)²) / N."""
    n = np.asarray(valence, dtype=np.float64)
    return (0.625 - (0.375 + 0.25 * np.cos(2.0 * np.pi / n)) ** 2) / n


def limit_weight(valence):
    """Weight χ of each neighbour in the limit-position mask; the vertex keeps 1 - Nχ."""
    n = np.asarray(valence, dtype=np.float64)
    return 1.0 / (3.0 / (8.0 * loop_beta(n)) + n)


# ---------------------------------------------------------------------------------------------
# One step of Loop subdivision


def loop_subdivide(data: np.ndarray, triangles: np.ndarray):
    """One Loop step on per-vertex `data` (V, ...) over `triangles` (T, 3).

    Returns (new_data (V+E, ...), new_triangles (4T, 3)). Old vertices keep their index, edge
    points follow in the order of the sorted undirected edges. Children of triangle t are
    4t + (corner at its 1st, 2nd, 3rd vertex, middle), each keeping the parent's orientation.
    Rows whose stencil is incomplete (on a boundary) are NaN.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    data = np.asarray(data, dtype=np.float64)
    n_vertices = data.shape[0]
    tails = tri.reshape(-1)
    heads = np.roll(tri, -1, axis=1).reshape(-1)
    opposite = np.roll(tri, -2, axis=1).reshape(-1)
    lo, hi = np.minimum(tails, heads), np.maximum(tails, heads)
    keys, half_to_edge, uses = np.unique(lo * n_vertices + hi, return_inverse=True, return_counts=True)
    edge_lo, edge_hi = keys // n_vertices, keys % n_vertices
    opposite_sum = np.zeros((len(keys),) + data.shape[1:])
    np.add.at(opposite_sum, half_to_edge, data[opposite])
    edge_points = 0.375 * (data[edge_lo] + data[edge_hi]) + 0.125 * opposite_sum
    edge_points[uses != 2] = np.nan

    valence = np.bincount(np.concatenate([edge_lo, edge_hi]), minlength=n_vertices)
    neighbour_sum = np.zeros_like(data)
    np.add.at(neighbour_sum, edge_lo, data[edge_hi])
    np.add.at(neighbour_sum, edge_hi, data[edge_lo])
    beta = loop_beta(np.maximum(valence, 3)).reshape((-1,) + (1,) * (data.ndim - 1))
    n = valence.reshape(beta.shape)
    vertex_points = (1.0 - n * beta) * data + beta * neighbour_sum
    on_boundary = np.zeros(n_vertices, dtype=bool)
    on_boundary[edge_lo[uses != 2]] = True
    on_boundary[edge_hi[uses != 2]] = True
    vertex_points[on_boundary] = np.nan

    mid = (n_vertices + half_to_edge).reshape(-1, 3)  # midpoints of edges (0,1), (1,2), (2,0)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    m_ab, m_bc, m_ca = mid[:, 0], mid[:, 1], mid[:, 2]
    children = np.stack(
        [
            np.stack([a, m_ab, m_ca], 1),
            np.stack([b, m_bc, m_ab], 1),
            np.stack([c, m_ca, m_bc], 1),
            np.stack([m_ab, m_bc, m_ca], 1),
        ],
        axis=1,
    ).reshape(-1, 3)
    return np.concatenate([vertex_points, edge_points]), children


# ---------------------------------------------------------------------------------------------
# Regular patch: 12 quartic box splines


def _box_spline_terms():
    """Coefficients (×1/12) of the 12 box splines over monomials u^i v^j w^k, i+j+k = 4."""
    polys = [
        "1 400 + 2 310",
        "1 400 + 2 301",
        "1 400 + 2 301 + 6 310 + 6 211 + 12 220 + 6 121 + 6 130 + 2 031 + 1 040",
        "6 400 + 24 301 + 24 202 + 8 103 + 1 004 + 24 310 + 60 211 + 36 112 + 6 013"
        " + 24 220 + 36 121 + 12 022 + 8 130 + 6 031 + 1 040",
        "1 400 + 6 301 + 12 202 + 6 103 + 1 004 + 2 310 + 6 211 + 6 112 + 2 013",
        "2 130 + 1 040",
        "1 400 + 6 301 + 12 202 + 6 103 + 1 004 + 8 310 + 36 211 + 36 112 + 8 013"
        " + 24 220 + 60 121 + 24 022 + 24 130 + 24 031 + 6 040",
        "1 400 + 8 301 + 24 202 + 24 103 + 6 004 + 6 310 + 36 211 + 60 112 + 24 013"
        " + 12 220 + 36 121 + 24 022 + 6 130 + 8 031 + 1 040",
        "2 103 + 1 004",
        "2 031 + 1 040",
        "2 103 + 1 004 + 6 112 + 6 013 + 6 121 + 12 022 + 2 130 + 6 031 + 1 040",
        "1 004 + 2 013",
    ]
    terms = []
    for index, poly in enumerate(polys):
        for term in poly.split("+"):
            coefficient, powers = term.split()
            terms.append((index, float(coefficient) / 12.0, *(int(p) for p in powers)))
    return terms


_BOX_SPLINE_TERMS = _box_spline_terms()
# derivatives along θ1 = v and θ2 = w with u = 1 - v - w: d/dθ1 = ∂v - ∂u, d/dθ2 = ∂w - ∂u
_DIRECTIONS = (
    [((0, 0, 0), 1.0)],  # value
    [((0, 1, 0), 1.0), ((1, 0, 0), -1.0)],  # d/dθ1
    [((0, 0, 1), 1.0), ((1, 0, 0), -1.0)],  # d/dθ2
    [((0, 2, 0), 1.0), ((1, 1, 0), -2.0), ((2, 0, 0), 1.0)],  # d²/dθ1²
    [((0, 1, 1), 1.0), ((1, 1, 0), -1.0), ((1, 0, 1), -1.0), ((2, 0, 0), 1.0)],  # d²/dθ1dθ2
    [((0, 0, 2), 1.0), ((1, 0, 1), -2.0), ((2, 0, 0), 1.0)],  # d²/dθ2²
)


def _falling_factorial(power: int, order: int) -> float:
    """d^order/dx^order x^power = this × x^(power - order) (0 where order > power)."""
    return float(math.prod(range(power - order + 1, power + 1))) if order <= power else 0.0


def _basis_tensor() -> tuple:
    """(exponents (M, 3), tensor (M, 12, 6)): the box splines and their derivatives as sums over the
    monomials u^a v^b w^c of degree <= 4, so that a basis is one product with the monomials' values."""
    exponents = [(a, b, c) for a in range(5) for b in range(5) for c in range(5) if a + b + c <= 4]
    position = {e: n for n, e in enumerate(exponents)}
    tensor = np.zeros((len(exponents), 12, N_BASIS_COLUMNS))
    for column, combination in enumerate(_DIRECTIONS):
        for index, coefficient, i, j, k in _BOX_SPLINE_TERMS:
            for (du, dv, dw), sign in combination:
                if du <= i and dv <= j and dw <= k:
                    factor = _falling_factorial(i, du) * _falling_factorial(j, dv) * _falling_factorial(k, dw)
                    tensor[position[(i - du, j - dv, k - dw)], index, column] += sign * coefficient * factor
    return np.array(exponents), tensor


_EXPONENTS, _BASIS_TENSOR = _basis_tensor()


def regular_basis(v, w) -> np.ndarray:
    """Box-spline basis (P, 12, 6) at parameter points (v, w) of a regular patch.

    Vertex order (Stam 1998): the triangle is (p1, p2, p3) = ring[3], ring[6], ring[7];
    the 0-based ring is built by `regular_rings`.
    """
    v = np.atleast_1d(np.asarray(v, dtype=np.float64))
    w = np.atleast_1d(np.asarray(w, dtype=np.float64))
    u = 1.0 - v - w
    a, b, c = _EXPONENTS.T
    monomials = u[:, None] ** a * v[:, None] ** b * w[:, None] ** c
    return np.einsum("pm,mkc->pkc", monomials, _BASIS_TENSOR)


# ---------------------------------------------------------------------------------------------
# Patch extraction (canonical control-vertex order)


def regular_rings(topology: Topology, triangles: np.ndarray) -> np.ndarray:
    """(n, 12) control vertices of regular patches, in the order `regular_basis` expects."""
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    third = topology.third
    p1, p2, p3 = tri[:, 0], tri[:, 1], tri[:, 2]
    r = np.empty((len(tri), 12), dtype=np.int64)
    r[:, 3], r[:, 6], r[:, 7] = p1, p2, p3
    r[:, 2] = third(p2, p1)
    r[:, 10] = third(p3, p2)
    r[:, 4] = third(p1, p3)
    r[:, 0] = third(r[:, 2], p1)
    r[:, 1] = third(r[:, 0], p1)
    r[:, 5] = third(p2, r[:, 2])
    r[:, 9] = third(p2, r[:, 5])
    r[:, 11] = third(p3, r[:, 10])
    r[:, 8] = third(p3, r[:, 11])
    closes = (
        (third(r[:, 1], p1) == r[:, 4])
        & (third(p2, r[:, 9]) == r[:, 10])
        & (third(p3, r[:, 8]) == r[:, 4])
    )
    _check_rings(r, closes)
    return r


def extraordinary_rings(topology: Topology, triangles: np.ndarray, valence: int) -> np.ndarray:
    """(n, N+6) control vertices of patches whose 1st vertex has valence N, the others 6.

    Order: the extraordinary vertex e, its neighbours r_0..r_{N-1} counter-clockwise from
    r_0 = 2nd vertex (r_1 = 3rd), then q across edge r_0 r_1, the two remaining neighbours
    c0, c1 of r_0 and b0, b1 of r_1.
    """
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    third = topology.third
    n = valence
    r = np.empty((len(tri), n + 6), dtype=np.int64)
    e = tri[:, 0]
    r[:, 0], r[:, 1], r[:, 2] = e, tri[:, 1], tri[:, 2]
    for i in range(3, n + 1):
        r[:, i] = third(e, r[:, i - 1])
    r0, r1 = r[:, 1], r[:, 2]
    q = third(r1, r0)
    c0 = third(r0, r[:, n])
    c1 = third(r0, c0)
    b0 = third(r1, q)
    b1 = third(r1, b0)
    r[:, n + 1], r[:, n + 2], r[:, n + 3], r[:, n + 4], r[:, n + 5] = q, c0, c1, b0, b1
    closes = (third(e, r[:, n]) == r0) & (third(r0, c1) == q) & (third(r1, b1) == r[:, 3])
    _check_rings(r, closes)
    return r


def _check_rings(rings: np.ndarray, closes: np.ndarray) -> None:
    # Each corner's one-ring must close; repeated entries (e.g. around a valence-3 vertex
    # in the ring) are fine, since the stencils only read the corners' one-rings.
    bad = np.flatnonzero(~(closes & np.all(rings >= 0, axis=1)))
    if len(bad):
        raise ValueError(
            f"patch {bad[0]} has no closed one-ring around its corners: the mesh is not a "
            "closed 2-manifold there"
        )


# ---------------------------------------------------------------------------------------------
# Extraordinary patches: subdivision matrices derived from a synthetic patch


def _synthetic_disk(valence: int) -> np.ndarray:
    """Triangles of a disk around vertex 0 (valence N) whose N neighbours are all regular."""
    n = valence
    r = lambda i: 1 + i % n  # noqa: E731  (ring 1)
    q = lambda i: 1 + n + i % n  # noqa: E731  (ring 2, across edge r_i r_{i+1})
    p = lambda i: 1 + 2 * n + i % n  # noqa: E731  (ring 2, between q_{i-1} and q_i)
    triangles = []
    for i in range(n):
        triangles += [
            (0, r(i), r(i + 1)),
            (r(i + 1), r(i), q(i)),
            (q(i), r(i), p(i)),
            (p(i), r(i), q(i - 1)),
        ]
    return np.array(triangles, dtype=np.int64)


@functools.lru_cache(maxsize=None)
def subdivision_matrices(valence: int):
    """(A, C) for an extraordinary patch of valence N.

    A (K, K): level-(n+1) patch control vertices from level-n ones, K = N + 6.
    C (3, 12, K): the regular sub-patches (corner at r_0, corner at r_1, middle) of the
    level-(n+1) subdivision, as `regular_rings` orders them.
    """
    if not MIN_VALENCE <= valence <= MAX_VALENCE:
        raise ValueError(f"valence {valence} is outside the supported {MIN_VALENCE}..{MAX_VALENCE}")
    triangles = _synthetic_disk(valence)
    n_vertices = 1 + 3 * valence
    topology = Topology(triangles, n_vertices)
    ring = extraordinary_rings(topology, triangles[:1], valence)[0]
    weights, children = loop_subdivide(np.eye(n_vertices), triangles)
    fine = Topology(children, len(weights))
    e_child, r0_child, r1_child, middle = children[0:4]
    m_er0, m_r0r1, m_r1e = middle  # middle child is (m_ab, m_bc, m_ca) of (e, r_0, r_1)
    fine_ring = extraordinary_rings(fine, e_child[None], valence)[0]
    regular = regular_rings(
        fine,
        np.array(
            [
                (m_er0, r0_child[0], m_r0r1),  # corner at r_0
                (m_r1e, m_r0r1, r1_child[0]),  # corner at r_1
                (m_r0r1, m_r1e, m_er0),  # middle, turned half a revolution
            ]
        ),
    )

    def restrict(rows):
        block = weights[rows]
        outside = np.delete(block, ring, axis=1)
        if not np.all(np.isfinite(block)) or np.any(outside != 0.0):
            raise AssertionError("synthetic patch is too small for its subdivision stencils")
        return block[:, ring]

    return restrict(fine_ring), np.stack([restrict(rows) for rows in regular])


@functools.lru_cache(maxsize=None)
def corner_limit_mask(valence: int) -> np.ndarray:
    """(K,) weights of the limit point at the extraordinary vertex: row 0 of lim A^n."""
    a, _ = subdivision_matrices(valence)
    row = np.zeros(len(a))
    row[0] = 1.0
    for _ in range(10000):  # left power iteration; rate = subdominant eigenvalue < 0.61
        following = row @ a
        if np.max(np.abs(following - row)) < 1e-17:
            return following
        row = following
    raise AssertionError("limit mask did not converge")


def _rotation(corner: int):
    """Barycentric permutation and parameter Jacobian putting vertex `corner` first.

    Rotated barycentrics are (b[corner], b[corner+1], b[corner+2]); `jacobian[a, b]` is
    ∂θ'_a/∂θ_b, with θ = (v, w) of the triangle and θ' those of the rotated triangle.
    """
    order = [(corner + k) % 3 for k in range(3)]
    # θ'_1 = bary[order[1]], θ'_2 = bary[order[2]], bary = (1 - v - w, v, w)
    d_bary = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    return order, d_bary[[order[1], order[2]]]


def patch_basis(valence: int, corner: int, v, w) -> np.ndarray:
    """Exact basis (P, K, 6) of a patch whose vertex `corner` (0, 1, 2) has valence N.

    Control vertices are ordered as `extraordinary_rings` orders them for the triangle
    rotated to start at that corner (`regular_rings` when N = 6 and corner = 0).
    Derivatives are with respect to the unrotated (v, w). At the extraordinary vertex itself
    the value is the limit mask and the derivatives are NaN (the parametrisation is singular).
    """
    v = np.atleast_1d(np.asarray(v, dtype=np.float64))
    w = np.atleast_1d(np.asarray(w, dtype=np.float64))
    if valence == 6 and corner == 0:
        return regular_basis(v, w)
    order, jac = _rotation(corner)
    bary = np.stack([1.0 - v - w, v, w])
    rotated = _extraordinary_basis(valence, bary[order[1]], bary[order[2]])
    out = np.empty_like(rotated)
    out[..., 0] = rotated[..., 0]
    out[..., 1:3] = rotated[..., 1:3] @ jac
    hessian = rotated[..., [3, 4, 4, 5]].reshape(rotated.shape[:-1] + (2, 2))
    hessian = np.einsum("ab,...ac,cd->...bd", jac, hessian, jac)
    out[..., 3], out[..., 4], out[..., 5] = hessian[..., 0, 0], hessian[..., 0, 1], hessian[..., 1, 1]
    return out


def _extraordinary_basis(valence: int, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    a, sub_patches = subdivision_matrices(valence)
    k = valence + 6
    out = np.empty((len(v), k, N_BASIS_COLUMNS))
    for p, (vp, wp) in enumerate(zip(v, w)):
        if vp < 0 or wp < 0 or vp + wp > 1:
            raise ValueError(f"parameter point ({vp}, {wp}) lies outside the triangle")
        if vp + wp == 0.0:
            out[p, :, 0] = corner_limit_mask(valence)
            out[p, :, 1:] = np.nan
            continue
        level = 0
        while vp + wp < 0.5:  # exact: scaling by 2 is exact in binary floating point
            vp, wp, level = 2.0 * vp, 2.0 * wp, level + 1
        if vp >= 0.5:
            child, vc, wc, scale = 0, 2.0 * vp - 1.0, 2.0 * wp, 2.0
        elif wp >= 0.5:
            child, vc, wc, scale = 1, 2.0 * vp, 2.0 * wp - 1.0, 2.0
        else:
            child, vc, wc, scale = 2, 1.0 - 2.0 * vp, 1.0 - 2.0 * wp, -2.0
        pull_back = sub_patches[child] @ np.linalg.matrix_power(a, level)  # (12, K)
        local = regular_basis(vc, wc)[0]  # (12, 6)
        scale *= 2.0**level
        factors = np.array([1.0, scale, scale, scale**2, scale**2, scale**2])
        out[p] = (pull_back.T @ local) * factors
    return out
