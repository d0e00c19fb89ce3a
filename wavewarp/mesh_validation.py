"""Mesh validation: a bad control mesh raises ValueError naming the first offending vertex, edge or
triangle in the numbering of the file it came from (`Numbering`), and the fix."""

from __future__ import annotations

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from .topology import Topology, unique_keys


class Numbering:
    """How validation errors name vertices and triangles: `vertex_ids[i]` and `triangle_ids[t]` (the
    numbers a file gave them; default the arrays' own indices) counted from `base` (1 for OBJ),
    with `source` ("in ball.obj, counted from 1") saying whose numbers they are."""

    def __init__(self, vertex_ids=None, triangle_ids=None, base: int = 0, source: str = "", points=None):
        self.vertex_ids, self.triangle_ids, self.base, self.source = vertex_ids, triangle_ids, int(base), source
        self.points = points  # name vertices by their coordinates (files without vertex numbers: STL)

    def vertex(self, i):
        if self.points is not None:
            return "(" + ", ".join(f"{float(value):g}" for value in self.points[int(i)]) + ")"
        return int(i if self.vertex_ids is None else self.vertex_ids[int(i)]) + self.base

    def triangle(self, t) -> int:
        return int(t if self.triangle_ids is None else self.triangle_ids[int(t)]) + self.base

    def vertices(self, indices) -> tuple:
        return tuple(self.vertex(i) for i in indices)

    def where(self) -> str:
        return f" (numbered as {self.source})" if self.source else ""


def undirected_edges(triangles: np.ndarray) -> np.ndarray:
    """Sorted (lo, hi) vertex pairs of the edges, each once (integer keys: far faster than
    np.unique over rows)."""
    tails, heads = triangles.reshape(-1), np.roll(triangles, -1, axis=1).reshape(-1)
    n = int(triangles.max()) + 1
    keys = unique_keys(np.minimum(tails, heads) * n + np.maximum(tails, heads))
    return np.stack([keys // n, keys % n], axis=1)


def validate_mesh(vertices: np.ndarray, triangles: np.ndarray, names: Numbering) -> None:
    """ValueError naming the first defect and its fix, in `names`' numbering."""
    where = names.where()
    n_vertices, n_triangles = len(vertices), len(triangles)
    if n_triangles < 4:
        raise ValueError(f"a closed mesh needs at least 4 triangles, got {n_triangles}")
    finite = np.all(np.isfinite(vertices), axis=1)
    if not np.all(finite):
        i = int(np.flatnonzero(~finite)[0])
        coordinates = ", ".join(f"{float(value):g}" for value in vertices[i])
        raise ValueError(f"vertex {names.vertex(i)}{where} has a non-finite coordinate ({coordinates}): fix or remove it")
    out_of_range = (triangles < 0) | (triangles >= n_vertices)
    if np.any(out_of_range):
        t = int(np.argwhere(out_of_range)[0, 0])
        raise ValueError(
            f"triangle {names.triangle(t)}{where} refers to vertices {names.vertices(triangles[t])}, but "
            f"vertex numbers must lie in {names.base}..{n_vertices - 1 + names.base}"
        )
    repeated = (
        (triangles[:, 0] == triangles[:, 1])
        | (triangles[:, 1] == triangles[:, 2])
        | (triangles[:, 2] == triangles[:, 0])
    )
    if np.any(repeated):
        t = int(np.flatnonzero(repeated)[0])
        raise ValueError(
            f"triangle {names.triangle(t)}{where} is degenerate: it repeats a vertex "
            f"{names.vertices(triangles[t])}; remove it"
        )
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    double_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    edge_scale = np.max(np.linalg.norm(np.stack([b - a, c - b, a - c]), axis=2), axis=0)
    flat = double_area <= 1e-12 * edge_scale**2
    if np.any(flat):
        t = int(np.flatnonzero(flat)[0])
        raise ValueError(
            f"triangle {names.triangle(t)} (vertices {names.vertices(triangles[t])}){where} is degenerate: "
            "its corners are collinear (zero area); remove it or move its vertices apart"
        )
    sorted_tri = np.sort(triangles, axis=1)
    order = np.lexsort(sorted_tri.T[::-1])
    repeats = np.flatnonzero(np.all(sorted_tri[order[1:]] == sorted_tri[order[:-1]], axis=1))
    if len(repeats):
        same = np.sort(order[repeats[0] : repeats[0] + 2])
        raise ValueError(
            f"triangles {names.triangle(same[0])} and {names.triangle(same[1])}{where} are duplicates (both use "
            f"vertices {names.vertices(sorted_tri[same[0]])}): remove one of them"
        )
    used = np.zeros(n_vertices, dtype=bool)
    used[triangles.reshape(-1)] = True
    if not np.all(used):
        i = int(np.flatnonzero(~used)[0])
        raise ValueError(f"vertex {names.vertex(i)}{where} belongs to no triangle: remove unused vertices")

    tails = triangles.reshape(-1)
    heads = np.roll(triangles, -1, axis=1).reshape(-1)
    owner = np.repeat(np.arange(n_triangles), 3)
    undirected = np.minimum(tails, heads) * n_vertices + np.maximum(tails, heads)
    keys, inverse, uses = np.unique(undirected, return_inverse=True, return_counts=True)
    if np.any(uses == 1):
        h = int(np.flatnonzero(uses[inverse] == 1)[0])
        raise ValueError(
            f"edge ({names.vertex(tails[h])}, {names.vertex(heads[h])}) belongs only to triangle "
            f"{names.triangle(owner[h])}{where}: the mesh is open; close the hole (a shell must be a closed surface)"
        )
    if np.any(uses > 2):
        h = int(np.flatnonzero(uses[inverse] > 2)[0])
        sharing = owner[inverse == inverse[h]]
        raise ValueError(
            f"edge ({names.vertex(tails[h])}, {names.vertex(heads[h])}) is shared by {len(sharing)} triangles "
            f"{tuple(names.triangle(t) for t in sharing)}{where}: the mesh is non-manifold there; remove the "
            "extra sheet"
        )
    directed = tails * n_vertices + heads
    order = np.argsort(directed, kind="stable")
    same_direction = np.flatnonzero(directed[order][1:] == directed[order][:-1])
    if len(same_direction):
        h0, h1 = order[same_direction[0]], order[same_direction[0] + 1]
        raise ValueError(
            f"triangles {names.triangle(owner[h0])} and {names.triangle(owner[h1])} both run along edge "
            f"{names.vertex(tails[h0])} -> {names.vertex(heads[h0])}{where}: their orientations are inconsistent; "
            "reverse the vertex order of one of them (and of every triangle oriented like it)"
        )

    topology = Topology(triangles, n_vertices)
    fan = _fan_sizes(topology, n_vertices)
    incident = np.bincount(triangles.reshape(-1), minlength=n_vertices)
    pinched = fan != incident
    if np.any(pinched):
        i = int(np.flatnonzero(pinched)[0])
        raise ValueError(
            f"vertex {names.vertex(i)}{where} joins separate fans of triangles (a pinch point): the mesh is "
            "non-manifold there; give each sheet its own copy of the vertex"
        )
    component = _components(n_vertices, keys // n_vertices, keys % n_vertices)
    if component.max() > 0:
        other = int(np.flatnonzero(component != component[0])[0])
        raise ValueError(
            f"the mesh has {component.max() + 1} separate components (vertices {names.vertex(0)} and "
            f"{names.vertex(other)}{where} are not connected): make one Mesh per closed shell"
        )
    volume = float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)
    if volume <= 0.0:
        raise ValueError(
            f"the triangles are oriented inward (enclosed volume {volume:.6g} <= 0): reverse the "
            "vertex order of every triangle, e.g. Mesh(vertices, triangles[:, ::-1])"
        )


def _fan_sizes(topology: Topology, n_vertices: int) -> np.ndarray:
    """Triangles met walking once around each vertex from one of its edges."""
    vertices = np.arange(n_vertices)
    first = topology._first_neighbour(vertices)
    current = first.copy()
    size = np.zeros(n_vertices, dtype=np.int64)
    open_walk = np.ones(n_vertices, dtype=bool)
    for _ in range(int(topology.valence.max()) + 1):
        current = np.where(open_walk, topology.third(vertices, current), current)
        size += open_walk
        open_walk &= current != first
        if not open_walk.any():
            break
    return size


def _components(n_vertices: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected-component label of each vertex, from the edges (a, b)."""
    graph = scipy.sparse.coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n_vertices, n_vertices))
    return scipy.sparse.csgraph.connected_components(graph, directed=False)[1]
