"""Half-edge connectivity of an oriented triangle mesh, built once in NumPy.

`third(a, b)` answers "which vertex completes the triangle that traverses the directed
edge a -> b counter-clockwise", the one query the patch extraction of docs/theory/geometry.md needs.
Meshes with boundary are allowed here (the synthetic patches of `subdivision` have one);
a missing half-edge returns -1.
"""

from __future__ import annotations

import numpy as np


def unique_keys(keys: np.ndarray) -> np.ndarray:
    """Sorted distinct integers of `keys` (np.unique without return options hashes, which is
    ~100x slower than a sort for millions of keys in NumPy 2.4)."""
    ordered = np.sort(keys)
    return ordered[np.r_[True, ordered[1:] != ordered[:-1]]] if len(ordered) else ordered


class Topology:
    """Directed-edge lookup tables of a triangle mesh with `n_vertices` vertices."""

    def __init__(self, triangles: np.ndarray, n_vertices: int):
        tri = np.ascontiguousarray(triangles, dtype=np.int64)
        self.triangles = tri
        self.n_vertices = int(n_vertices)
        tails = tri.reshape(-1)
        heads = np.roll(tri, -1, axis=1).reshape(-1)
        opposite = np.roll(tri, -2, axis=1).reshape(-1)
        keys = tails * self.n_vertices + heads
        order = np.argsort(keys, kind="stable")
        self._keys = keys[order]
        self._third = opposite[order]
        self._triangle = order // 3
        edges = unique_keys(np.minimum(tails, heads) * self.n_vertices + np.maximum(tails, heads))
        self.valence = np.bincount(np.concatenate([edges // self.n_vertices, edges % self.n_vertices]),
                                   minlength=self.n_vertices)  # fmt: skip

    def third(self, a, b) -> np.ndarray:
        """Vertex c with (a, b, c) a triangle in counter-clockwise order; -1 where none."""
        a = np.asarray(a, dtype=np.int64)
        b = np.asarray(b, dtype=np.int64)
        valid = (a >= 0) & (b >= 0)
        keys = np.where(valid, a * self.n_vertices + b, -1)
        pos = np.clip(np.searchsorted(self._keys, keys), 0, len(self._keys) - 1)
        found = valid & (self._keys[pos] == keys)
        return np.where(found, self._third[pos], -1)

    def ordered_rings(self, vertices: np.ndarray, valence: int) -> np.ndarray:
        """(n, valence) neighbours of each vertex, counter-clockwise around the outward normal.

        Every vertex passed must be interior and have exactly `valence` neighbours.
        """
        vertices = np.asarray(vertices, dtype=np.int64)
        first = self._first_neighbour(vertices)
        ring = np.empty((len(vertices), valence), dtype=np.int64)
        ring[:, 0] = first
        for i in range(1, valence):
            ring[:, i] = self.third(vertices, ring[:, i - 1])
        if np.any(ring < 0) or np.any(self.third(vertices, ring[:, -1]) != first):
            raise ValueError("one-ring walk did not close: vertex is on a boundary or non-manifold")
        return ring

    def _first_neighbour(self, vertices: np.ndarray) -> np.ndarray:
        tails = self._keys // self.n_vertices
        pos = np.searchsorted(tails, vertices)
        return self._keys[np.clip(pos, 0, len(self._keys) - 1)] % self.n_vertices
