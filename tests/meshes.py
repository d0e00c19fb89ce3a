"""Test meshes built independently of the library's generators."""

import numpy as np
from scipy.spatial import ConvexHull

from wavewarp.mesh import Mesh


def random_genus0(n_points: int, seed: int) -> Mesh:
    """Irregular closed mesh: convex hull of random sphere points, then stretched and dented."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n_points, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    triangles = ConvexHull(p).simplices.copy()
    normal = np.cross(p[triangles[:, 1]] - p[triangles[:, 0]], p[triangles[:, 2]] - p[triangles[:, 0]])
    inward = np.einsum("ij,ij->i", normal, p[triangles].mean(axis=1)) < 0
    triangles[inward] = triangles[inward][:, ::-1]
    p = p * [1.0, 0.8, 1.3] * (1.0 + 0.1 * rng.random((n_points, 1)))
    return Mesh(p, triangles)


def torus(major: float, minor: float, n_major: int, n_minor: int) -> Mesh:
    """Regular (all valence 6) torus control mesh."""
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    u, v = 2 * np.pi * i / n_major, 2 * np.pi * j / n_minor
    ring = major + minor * np.cos(v)
    points = np.stack([ring * np.cos(u), ring * np.sin(u), minor * np.sin(v)], -1).reshape(-1, 3)
    index = lambda a, b: (a % n_major) * n_minor + (b % n_minor)  # noqa: E731
    triangles = []
    for a in range(n_major):
        for b in range(n_minor):
            triangles += [
                (index(a, b), index(a + 1, b), index(a + 1, b + 1)),
                (index(a, b), index(a + 1, b + 1), index(a, b + 1)),
            ]
    return Mesh(points, np.array(triangles))


def tetrahedron() -> Mesh:
    p = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    return Mesh(p, [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])


def octahedron() -> Mesh:
    p = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    t = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    return Mesh(p, t)


def loop_reference(vertices, triangles):
    """One step of Loop subdivision written plainly (Loop 1987, original β), for comparison.

    Returns new vertices, new triangles, and for each old triangle (a, b, c) its children
    (a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca) as rows 4t..4t+3, and the map
    edge (i, j) -> new vertex index.
    """
    vertices = np.asarray(vertices, dtype=float)
    n = len(vertices)
    neighbours = [set() for _ in range(n)]
    opposite = {}
    for a, b, c in triangles:
        for i, j, k in ((a, b, c), (b, c, a), (c, a, b)):
            neighbours[i].update((j, k))
            opposite.setdefault(frozenset((i, j)), []).append(k)
    new = []
    for i in range(n):
        k = len(neighbours[i])
        beta = (5 / 8 - (3 / 8 + np.cos(2 * np.pi / k) / 4) ** 2) / k
        new.append((1 - k * beta) * vertices[i] + beta * sum(vertices[j] for j in neighbours[i]))
    edge_vertex = {}
    for edge, (k0, k1) in opposite.items():
        i, j = tuple(edge)
        edge_vertex[edge] = len(new)
        new.append(3 / 8 * (vertices[i] + vertices[j]) + 1 / 8 * (vertices[k0] + vertices[k1]))
    children = []
    for a, b, c in triangles:
        ab, bc, ca = (edge_vertex[frozenset(e)] for e in ((a, b), (b, c), (c, a)))
        children += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    return np.array(new), np.array(children)


def bipyramid(n: int) -> Mesh:
    """Two apexes of valence n over an n-gon; triangle i starts at corner i % 3."""
    angles = 2 * np.pi * np.arange(n) / n
    ring = np.stack([np.cos(angles), np.sin(angles), np.zeros(n)], 1)
    points = np.concatenate([ring, [[0, 0, 1.2], [0, 0, -0.9]]])
    triangles = []
    for i in range(n):
        j = (i + 1) % n
        triangles += [(i, j, n), (j, i, n + 1)]
    triangles = [np.roll(t, -(k % 3)) for k, t in enumerate(triangles)]
    return Mesh(points, np.array(triangles))


def limit_mask_reference(vertices, triangles):
    """Limit points by Loop's closed-form mask: (1 - Nχ) x + χ Σ ring, χ = 1/(N + 3/(8β))."""
    neighbours = [set() for _ in range(len(vertices))]
    for a, b, c in triangles:
        neighbours[a].update((b, c))
        neighbours[b].update((c, a))
        neighbours[c].update((a, b))
    out = np.empty((len(vertices), 3))
    for i, ring in enumerate(neighbours):
        k = len(ring)
        beta = (5 / 8 - (3 / 8 + np.cos(2 * np.pi / k) / 4) ** 2) / k
        chi = 1 / (k + 3 / (8 * beta))
        out[i] = (1 - k * chi) * vertices[i] + chi * sum(vertices[j] for j in ring)
    return out
