"""Loop refinement and the limit mask as sparse matrices, for baked USD surfaces (docs/theory/scenes.md).

`loop_step_matrix` is one step of `subdivision.loop_subdivide` as a matrix S (refined = S @ control,
same numbering, same child triangles); `limit_matrix` is Loop's limit-position mask L. `BakedSurface`
composes k steps and the mask once, so that a frame costs one sparse product: the refined vertices
placed on the limit surface (which the refined net shares with the original) are L_k S_k ... S_1 @ x,
and the same map takes per-vertex control values to the field's limit values there.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from .subdivision import limit_weight, loop_beta, loop_subdivide
from .topology import unique_keys


def _edges(triangles: np.ndarray, n_vertices: int):
    """(edge_lo, edge_hi, half_to_edge, opposite): the sorted undirected edges as `loop_subdivide`
    numbers them, the edge of each half-edge (row-major over the triangles) and the vertex opposite it."""
    tails = triangles.reshape(-1)
    heads = np.roll(triangles, -1, axis=1).reshape(-1)
    opposite = np.roll(triangles, -2, axis=1).reshape(-1)
    half_keys = np.minimum(tails, heads) * n_vertices + np.maximum(tails, heads)
    keys = unique_keys(half_keys)
    return keys // n_vertices, keys % n_vertices, np.searchsorted(keys, half_keys), opposite


def _ring_rows(edge_lo, edge_hi, n_vertices: int, centre_weight, neighbour_weight):
    """(rows, cols, vals) of a one-ring mask: vertex i keeps centre_weight[i], each neighbour j gets
    neighbour_weight[i]."""
    rows = np.concatenate([np.arange(n_vertices), edge_lo, edge_hi])
    cols = np.concatenate([np.arange(n_vertices), edge_hi, edge_lo])
    vals = np.concatenate([centre_weight, neighbour_weight[edge_lo], neighbour_weight[edge_hi]])
    return rows, cols, vals


def loop_step_matrix(triangles, n_vertices: int):
    """(S, children): one Loop step of a closed mesh as a sparse (V + E, V) matrix and the (4T, 3)
    child triangles, numbered as `loop_subdivide` numbers them (old vertices first, then edge points)."""
    tri = np.asarray(triangles, dtype=np.int64)
    edge_lo, edge_hi, half_to_edge, opposite = _edges(tri, n_vertices)
    n_edges = len(edge_lo)
    valence = np.bincount(np.concatenate([edge_lo, edge_hi]), minlength=n_vertices).astype(np.float64)
    beta = loop_beta(valence)
    rows, cols, vals = _ring_rows(edge_lo, edge_hi, n_vertices, 1.0 - valence * beta, beta)
    edge_rows = n_vertices + np.arange(n_edges)
    rows = np.concatenate([rows, edge_rows, edge_rows, n_vertices + half_to_edge])
    cols = np.concatenate([cols, edge_lo, edge_hi, opposite])
    vals = np.concatenate([vals, np.full(2 * n_edges, 0.375), np.full(len(opposite), 0.125)])
    step = scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(n_vertices + n_edges, n_vertices))
    _, children = loop_subdivide(np.zeros(n_vertices), tri)
    return step, children


def limit_matrix(triangles, n_vertices: int) -> scipy.sparse.csr_matrix:
    """Loop's limit-position mask as a sparse (V, V) matrix: limit points = L @ control points."""
    edge_lo, edge_hi, _, _ = _edges(np.asarray(triangles, dtype=np.int64), n_vertices)
    valence = np.bincount(np.concatenate([edge_lo, edge_hi]), minlength=n_vertices).astype(np.float64)
    chi = limit_weight(valence)
    rows, cols, vals = _ring_rows(edge_lo, edge_hi, n_vertices, 1.0 - valence * chi, chi)
    return scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(n_vertices, n_vertices))


class BakedSurface:
    """A closed control mesh refined `levels` times by Loop subdivision, its vertices on the limit surface.

    `triangles` (4^levels T, 3) is the refined topology; `values(x)` maps per-vertex control data
    (V, ...) (positions, or a field's control values) to the refined vertices' limit values.
    """

    def __init__(self, triangles, levels: int):
        tri = np.asarray(triangles, dtype=np.int64)
        n_vertices = int(tri.max()) + 1
        refine = scipy.sparse.identity(n_vertices, format="csr")
        for _ in range(levels):
            step, tri = loop_step_matrix(tri, n_vertices)
            refine = step @ refine
            n_vertices = step.shape[0]
        self.levels = levels
        self.triangles = tri.astype(np.int32)
        self.matrix = (limit_matrix(tri, n_vertices) @ refine).tocsr()

    @property
    def n_vertices(self) -> int:
        return self.matrix.shape[0]

    def values(self, control) -> np.ndarray:
        """Limit values at the refined vertices of per-vertex control data (V, ...)."""
        return self.matrix @ np.asarray(control, dtype=np.float64)
