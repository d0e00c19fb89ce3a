"""Per-mesh subdivision tables (docs/theory/geometry.md), built once in NumPy.

A triangle's limit surface is `x(θ) = Σ_k N_k(θ) x[patch_vertices[start + k]]`. The basis
values depend only on the patch *type* — (valence of the extraordinary corner, which corner)
or regular — and the quadrature point, so all triangles of a type share one table: a mesh
stores per triangle only its control-vertex list and its type. Every triangle uses the same
quadrature rule, so quadrature point q belongs to triangle q // P and uses table row
type * P + q % P (P points per triangle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .quadrature import triangle_rule
from .subdivision import (
    MAX_VALENCE,
    MIN_VALENCE,
    N_BASIS_COLUMNS,
    extraordinary_rings,
    patch_basis,
    regular_rings,
)
from .topology import Topology, unique_keys


@dataclass(frozen=True)
class PatchTables:
    """Connectivity and shared basis tables of one mesh for one quadrature rule."""

    patch_start: np.ndarray  # (T+1,) int32: first entry of each triangle in patch_vertices
    patch_vertices: np.ndarray  # (sum K,) int32: control vertices, canonical patch order
    triangle_type: np.ndarray  # (T,) int32: index into `types`
    types: tuple  # (valence, corner) of each type; (6, 0) is the regular patch
    basis: np.ndarray  # (n_types * P, K_max, 6) float64: [N, N,1, N,2, N,11, N,12, N,22]
    points: np.ndarray  # (P, 2) quadrature points (v, w)
    weights: np.ndarray  # (P,) quadrature weights on the parameter triangle (sum 1/2)
    rule: str

    @property
    def n_triangles(self) -> int:
        return len(self.triangle_type)

    @property
    def points_per_triangle(self) -> int:
        return len(self.weights)

    @property
    def n_quadrature_points(self) -> int:
        return self.n_triangles * self.points_per_triangle

    @property
    def max_patch_size(self) -> int:
        return self.basis.shape[1]

    def nbytes_per_triangle(self, scalar_bytes: int = 4) -> float:
        """Bytes a kernel reads per triangle from these tables (shared basis amortised)."""
        per_triangle = 4 * (len(self.patch_vertices) + 1 + self.n_triangles) / self.n_triangles
        shared = scalar_bytes * self.basis.size / self.n_triangles
        return per_triangle + shared

    def locality(self, vertex_bytes: int = 12, warp: int = 32, block: int = 256, sector: int = 32) -> dict:
        """How scattered the patch gathers are in a per-vertex array of `vertex_bytes` per vertex
        (float32 vec3: 12), one thread per triangle (docs/theory/geometry.md#numbering-for-memory-locality):

        * `span`: mean over triangles of the largest minus the smallest control-vertex index;
        * `warp_sectors`: distinct `sector`-byte sectors that the warp-wide reads of the k-th patch
          vertex touch (`warp` consecutive triangles), summed over k, per triangle: the L1-to-L2
          traffic of one patch gather, or of one scatter of atomics, in sectors;
        * `block_sectors`: distinct sectors of the union of `block` consecutive triangles' patches,
          per triangle: what a thread block must read at least.
        """
        sizes = np.diff(self.patch_start)
        k = np.arange(sizes.max())
        valid = k[None, :] < sizes[:, None]
        patches = np.zeros(valid.shape, dtype=np.int64)
        patches[valid] = self.patch_vertices
        span = np.where(valid, patches, -1).max(axis=1) - np.where(valid, patches, patches.max() + 1).min(axis=1)
        first = patches * vertex_bytes // sector
        last = (patches * vertex_bytes + vertex_bytes - 1) // sector
        n_sectors = int(last.max()) + 1

        def distinct(group):  # distinct (group, sector) pairs over the valid entries
            groups = np.broadcast_to(group, valid.shape)[valid]
            keys = np.concatenate([groups * n_sectors + first[valid], groups * n_sectors + last[valid]])
            return len(unique_keys(keys))

        triangle = np.arange(self.n_triangles)[:, None]
        return {
            "span": float(span.mean()),
            "warp_sectors": distinct(triangle // warp * len(k) + k[None, :]) / self.n_triangles,
            "block_sectors": distinct(triangle // block) / self.n_triangles,
        }


@dataclass(frozen=True)
class BlockUnions:
    """The patch vertices of `block` consecutive triangles gathered once per block (a thread block stages
    them in shared memory, docs/theory/geometry.md#staging-patches-in-shared-memory)."""

    block: int  # triangles per block
    capacity: int  # vertices per block's row, padded with the row's first vertex
    block_vertices: np.ndarray  # (n_blocks, capacity) int32: the union of the block's patches, sorted
    patch_local: np.ndarray  # like patch_vertices: each entry's position in its block's row


def block_unions(tables: PatchTables, block: int, multiple: int = 32) -> BlockUnions:
    """Each `block` consecutive triangles' union of patch vertices, its row padded to a common capacity
    (the largest union rounded up to `multiple`), and every patch entry's position in its row."""
    if block < 1:
        raise ValueError(f"block = {block}: the triangles per block must be at least 1")
    block_of_entry = np.repeat(np.arange(tables.n_triangles) // block, np.diff(tables.patch_start))
    n_vertices = int(tables.patch_vertices.max()) + 1
    keys = block_of_entry.astype(np.int64) * n_vertices + tables.patch_vertices
    union, local_key = np.unique(keys, return_inverse=True)
    union_block = union // n_vertices
    n_blocks = (tables.n_triangles + block - 1) // block
    counts = np.bincount(union_block, minlength=n_blocks)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    capacity = int(-(-counts.max() // multiple) * multiple)
    rows = np.repeat((union % n_vertices)[first], capacity).reshape(n_blocks, capacity)
    rows[union_block, np.arange(len(union)) - first[union_block]] = union % n_vertices
    local = np.arange(len(union)) - first[union_block]
    return BlockUnions(block=block, capacity=capacity, block_vertices=rows.astype(np.int32),
                       patch_local=local[local_key].astype(np.int32))  # fmt: skip


def regular_patch_basis(rule: str = "3") -> tuple:
    """The regular patch's basis at `rule`'s quadrature points and the rule's weights, as nested tuples (the
    compile-time constants of kernels/regular.py): P rows of 12 entries [N, N,1, N,2, N,11, N,12, N,22]."""
    points, weights = triangle_rule(rule)
    table = patch_basis(6, 0, points[:, 0], points[:, 1])
    return tuple(tuple(map(tuple, row)) for row in table.tolist()), tuple(weights.tolist())


def build_patch_tables(triangles: np.ndarray, n_vertices: int, rule: str = "3") -> PatchTables:
    """Tables for a closed mesh; each triangle may touch at most one extraordinary vertex."""
    tri = np.asarray(triangles, dtype=np.int64)
    topology = Topology(tri, n_vertices)
    corner_valence = topology.valence[tri]
    extraordinary = corner_valence != 6
    counts = extraordinary.sum(axis=1)
    if np.any(counts > 1):
        t = int(np.flatnonzero(counts > 1)[0])
        raise ValueError(
            f"triangle {t} (vertices {tuple(int(i) for i in tri[t])}, valences "
            f"{tuple(int(i) for i in corner_valence[t])}) touches {int(counts[t])} extraordinary "
            "vertices (valence != 6); Loop patches allow one. Refine the mesh once with "
            "Mesh.subdivided() first"
        )
    bad = (corner_valence < MIN_VALENCE) | (corner_valence > MAX_VALENCE)
    if np.any(bad):
        t, c = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"vertex {int(tri[t, c])} has valence {int(corner_valence[t, c])}; supported "
            f"valences are {MIN_VALENCE}..{MAX_VALENCE}: remesh around it"
        )

    corner = np.where(counts == 1, np.argmax(extraordinary, axis=1), 0)
    valence = np.where(counts == 1, corner_valence[np.arange(len(tri)), corner], 6)
    keys = sorted(set(zip(valence.tolist(), corner.tolist())) | {(6, 0)}, key=lambda k: k != (6, 0))
    key_index = {key: i for i, key in enumerate(keys)}
    triangle_type = np.array([key_index[k] for k in zip(valence.tolist(), corner.tolist())], np.int32)

    rings = [None] * len(tri)
    for (n, c), type_id in key_index.items():
        members = np.flatnonzero(triangle_type == type_id)
        if len(members) == 0:
            continue
        rotated = np.roll(tri[members], -c, axis=1)  # extraordinary vertex first
        found = regular_rings(topology, rotated) if n == 6 else extraordinary_rings(topology, rotated, n)
        for t, ring in zip(members, found):
            rings[t] = ring
    sizes = np.array([len(r) for r in rings])
    patch_start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int32)
    patch_vertices = np.concatenate(rings).astype(np.int32)

    points, weights = triangle_rule(rule)
    k_max = max(n for n, _ in keys) + 6
    basis = np.zeros((len(keys) * len(points), k_max, N_BASIS_COLUMNS))
    for i, (n, c) in enumerate(keys):
        table = patch_basis(n, c, points[:, 0], points[:, 1])
        basis[i * len(points) : (i + 1) * len(points), : table.shape[1]] = table
    return PatchTables(
        patch_start=patch_start,
        patch_vertices=patch_vertices,
        triangle_type=triangle_type,
        types=tuple(keys),
        basis=basis,
        points=points,
        weights=weights,
        rule=str(rule),
    )
