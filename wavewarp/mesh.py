"""Closed triangle control meshes: generators, file I/O, Loop refinement, validated on construction (wavewarp/mesh_validation.py; docs/theory/geometry.md, docs/theory/scenes.md).

A `Mesh` is validated on construction; a bad mesh raises `ValueError` naming the first
offending element and the fix. Generators return meshes with well-shaped triangles and
outward normals; `icosphere` places its control points so that their *limit* points lie on
the requested sphere. Generators and `load` number vertices and triangles for memory locality
(`Mesh.reordered`, docs/theory/geometry.md#numbering-for-memory-locality): neighbouring triangles, and the control
vertices of one patch, lie close together in the device arrays.
"""

from __future__ import annotations

import os
from functools import cached_property

import numpy as np
import scipy.sparse

from .checks import plain, positive
from .io import atomic_path
from .subdivision import limit_weight, loop_subdivide
from .mesh_validation import Numbering, undirected_edges, validate_mesh
from .topology import Topology


class Mesh:
    """Closed, oriented 2-manifold triangle control mesh.

    `vertices` (V, 3) float64 and `triangles` (T, 3) int32, counter-clockwise seen from
    outside (outward normals). Both arrays are stored read-only. `numbering` names vertices and
    triangles in validation errors (default: these arrays' indices).
    """

    def __init__(self, vertices, triangles, *, numbering: Numbering | None = None):
        vertices = np.array(vertices, dtype=np.float64)
        triangles = np.asarray(triangles)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"vertices must have shape (V, 3), got {vertices.shape}")
        if triangles.ndim != 2 or triangles.shape[1] != 3:
            raise ValueError(
                f"triangles must have shape (T, 3), got {triangles.shape}: "
                "triangulate polygons with more than three corners first"
            )
        if not np.issubdtype(triangles.dtype, np.integer):
            if triangles.size and not np.all(np.mod(triangles, 1) == 0):
                raise ValueError("triangles must hold integer vertex indices")
        triangles = np.array(triangles, dtype=np.int64)
        validate_mesh(vertices, triangles, numbering or Numbering())
        vertices.setflags(write=False)
        self.vertices = vertices
        self.triangles = triangles.astype(np.int32)
        self.triangles.setflags(write=False)

    worlds = 1  # a `union` holds several

    @classmethod
    def union(cls, meshes) -> Mesh:
        """Batched worlds: the disjoint union of meshes of one topology (the same triangles; their
        vertices may differ), world w's vertices and triangles the w-th contiguous block. Each mesh was
        validated; the union is a Mesh with `worlds` components that never interact."""
        meshes = list(meshes)
        if not meshes or not all(isinstance(m, Mesh) and m.worlds == 1 for m in meshes):
            raise ValueError("Mesh.union takes a non-empty list of single-world wavewarp Meshes")
        first = meshes[0]
        for w, m in enumerate(meshes[1:], 1):
            if not np.array_equal(m.triangles, first.triangles):
                raise ValueError(f"batched worlds need one topology: world {w}'s triangles differ from world 0's "
                                 "(build every world from the same mesh, e.g. the same level or divisions)")  # fmt: skip
        union = cls.__new__(cls)
        vertices = np.concatenate([m.vertices for m in meshes])
        offsets = (np.arange(len(meshes)) * first.n_vertices).astype(np.int32)
        triangles = (first.triangles[None] + offsets[:, None, None]).reshape(-1, 3)
        vertices.setflags(write=False)
        triangles.setflags(write=False)
        union.vertices, union.triangles, union.worlds = vertices, triangles, len(meshes)
        return union

    @property
    def vertices_per_world(self) -> int:
        return self.n_vertices // self.worlds

    @property
    def triangles_per_world(self) -> int:
        return self.n_triangles // self.worlds

    def world(self, w: int) -> Mesh:
        """World w of a union (itself for a single world)."""
        if self.worlds == 1:
            return self
        nv, nt = self.vertices_per_world, self.triangles_per_world
        return Mesh(self.vertices[w * nv:(w + 1) * nv], self.triangles[w * nt:(w + 1) * nt] - w * nv)

    def __repr__(self) -> str:
        worlds = f", {self.worlds} worlds" if self.worlds > 1 else ""
        return f"Mesh({self.n_vertices} vertices, {self.n_triangles} triangles{worlds})"

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @cached_property
    def topology(self) -> Topology:
        return Topology(self.triangles, self.n_vertices)

    @property
    def valence(self) -> np.ndarray:
        return self.topology.valence

    @cached_property
    def edges(self) -> np.ndarray:
        """(E, 2) undirected edges, lower index first, sorted."""
        return undirected_edges(self.triangles.astype(np.int64))

    @property
    def needs_refinement(self) -> bool:
        """True where a triangle touches two or more extraordinary vertices (docs/theory/geometry.md)."""
        return bool(np.any((self.valence[self.triangles] != 6).sum(axis=1) > 1))

    def volume(self, x=None) -> float:
        """Volume enclosed by the control mesh (flat triangles) at positions `x`."""
        p = self.vertices if x is None else np.asarray(x, dtype=np.float64)
        a, b, c = (p[self.triangles[:, k]] for k in range(3))
        return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)

    def turned(self, direction, target) -> Mesh:
        """The mesh rotated rigidly about the origin so that `direction` points along `target`."""
        a, b = (np.asarray(v, dtype=np.float64) / np.linalg.norm(v) for v in (direction, target))
        if a @ b < -1 + 1e-12:  # opposite: a half turn about an axis perpendicular to a
            u = np.cross(a, np.eye(3)[np.argmin(np.abs(a))])
            rotation = 2 * np.outer(u, u) / (u @ u) - np.eye(3)
        else:  # Rodrigues' formula about a × b
            k = np.cross(a, b)
            K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            rotation = np.eye(3) + K + K @ K / (1 + a @ b)
        return Mesh(self.vertices @ rotation.T, self.triangles)

    def subdivided(self, levels: int = 1) -> Mesh:
        """Loop subdivision of the control mesh, `levels` times (Loop's original β)."""
        if int(levels) != levels or levels < 0:
            raise ValueError(f"levels must be a non-negative integer, got {plain(levels)!r}")
        vertices, triangles = self.vertices, self.triangles
        for _ in range(int(levels)):
            vertices, triangles = loop_subdivide(vertices, triangles)
        return Mesh(vertices, triangles)

    def refined_for_patches(self) -> Mesh:
        """This mesh, or its Loop refinement where two extraordinary vertices share a triangle
        (renumbered for locality: `reordered(keep_triangle_order=True)`)."""
        return self.subdivided(1).reordered(keep_triangle_order=True) if self.needs_refinement else self

    def reordering(self, keep_triangle_order: bool = False) -> tuple:
        """(vertex_order, triangle_order) of `reordered`: its vertex i is this mesh's vertex
        vertex_order[i], its triangle t this mesh's triangle triangle_order[t]."""
        if keep_triangle_order:
            triangle_order = np.arange(self.n_triangles)
        else:
            triangle_order = np.argsort(hilbert_keys(self.vertices[self.triangles].mean(axis=1)), kind="stable")
        corners = self.triangles[triangle_order].reshape(-1)
        _, first_use = np.unique(corners, return_index=True)  # every vertex is used (validated)
        return np.argsort(first_use, kind="stable"), triangle_order

    def reordered(self, keep_triangle_order: bool = False) -> Mesh:
        """The same mesh numbered for memory locality (docs/theory/geometry.md#numbering-for-memory-locality).

        Triangles follow a 3-D Hilbert curve through their centroids (or keep their order, for
        meshes already ordered locally such as Loop refinements: children 4t..4t+3 of triangle t);
        vertices are numbered in the order the triangles first use them. A pure permutation: the
        positions, and each triangle's corners in their order (orientation, patch types), are
        unchanged. Applying it twice gives the same mesh as once.
        """
        vertex_order, triangle_order = self.reordering(keep_triangle_order)
        return self.permuted(vertex_order, triangle_order)

    def permuted(self, vertex_order, triangle_order) -> Mesh:
        """The mesh renumbered: vertex i is this mesh's vertex vertex_order[i], triangle t this
        mesh's triangle triangle_order[t] (both permutations)."""
        vertex_order = np.asarray(vertex_order, dtype=np.int64)
        triangle_order = np.asarray(triangle_order, dtype=np.int64)
        for name, order, n in (("vertex_order", vertex_order, self.n_vertices),
                               ("triangle_order", triangle_order, self.n_triangles)):  # fmt: skip
            if order.shape != (n,) or not np.array_equal(np.sort(order), np.arange(n)):
                raise ValueError(f"{name} must be a permutation of 0..{n - 1}")
        new_index = np.empty(self.n_vertices, dtype=np.int64)
        new_index[vertex_order] = np.arange(self.n_vertices)
        # a renumbering of a valid mesh is valid: skip the validation (seconds at a million triangles)
        mesh = Mesh.__new__(Mesh)
        mesh.vertices = self.vertices[vertex_order]
        mesh.triangles = new_index[self.triangles[triangle_order]].astype(np.int32)
        mesh.vertices.setflags(write=False)
        mesh.triangles.setflags(write=False)
        return mesh

    def limit_mask_matrix(self):
        """Rows (i, j, weight) of the limit-position mask: limit = L @ control (docs/theory/scenes.md)."""
        n = self.valence.astype(np.float64)
        chi = limit_weight(n)
        e = self.edges
        rows = np.concatenate([np.arange(self.n_vertices), e[:, 0], e[:, 1]])
        cols = np.concatenate([np.arange(self.n_vertices), e[:, 1], e[:, 0]])
        vals = np.concatenate([1.0 - n * chi, chi[e[:, 0]], chi[e[:, 1]]])
        return rows, cols, vals


# ---------------------------------------------------------------------------------------------
# Numbering for locality (docs/theory/geometry.md#numbering-for-memory-locality)


def hilbert_keys(points, bits: int = 16) -> np.ndarray:
    """Position of each point (n, 3) along a 3-D Hilbert curve through the points' bounding cube,
    2^bits cells per side (Skilling 2004, "Programming the Hilbert curve", vectorised)."""
    points = np.asarray(points, dtype=np.float64)
    if not 1 <= bits <= 21:
        raise ValueError(f"bits must lie in 1..21 (a 63-bit key), got {plain(bits)!r}")
    lo = points.min(axis=0)
    side = float(np.max(points.max(axis=0) - lo)) or 1.0
    cells = np.uint64(2**bits - 1)
    x = np.minimum(np.floor((points - lo) / side * float(2**bits)), float(cells)).astype(np.uint64).T.copy()
    one = np.uint64(1)
    q = one << np.uint64(bits - 1)
    while q > one:  # Skilling's AxesToTranspose: undo the excess work, from the top bit down
        p = q - one
        for i in range(3):
            high = (x[i] & q) != 0
            x[0] = np.where(high, x[0] ^ p, x[0])
            swap = np.where(high, np.uint64(0), (x[0] ^ x[i]) & p)
            x[0] ^= swap
            x[i] ^= swap
        q >>= one
    for i in range(1, 3):  # Gray encode
        x[i] ^= x[i - 1]
    flip = np.zeros(x.shape[1], dtype=np.uint64)
    q = one << np.uint64(bits - 1)
    while q > one:
        flip = np.where((x[2] & q) != 0, flip ^ (q - one), flip)
        q >>= one
    x ^= flip
    keys = np.zeros(x.shape[1], dtype=np.uint64)
    for b in range(bits - 1, -1, -1):  # interleave: the transposed form to one integer
        for i in range(3):
            keys = (keys << one) | ((x[i] >> np.uint64(b)) & one)
    return keys


# ---------------------------------------------------------------------------------------------
# Generators


def icosphere(radius: float = 1.0, level: int = 3, *, limit: bool = True, reorder: bool = True) -> Mesh:
    """Sphere of `radius` from an icosahedron refined `level` times (20·4^level triangles).

    The icosahedron is refined by Loop subdivision and projected onto the sphere, which
    spaces the vertices smoothly (midpoint splitting leaves kinks in the spacing along the
    icosahedron's edges that cost an O(1) mean-curvature error there; docs/theory/geometry.md).
    With `limit=True` (default) the control points are then placed so that their Loop limit
    points lie on the sphere; otherwise the control points themselves do. The triangles stay in
    subdivision order (already local), the vertices are renumbered in the order the triangles
    first use them (`Mesh.reordered(keep_triangle_order=True)`; `reorder=False`: the subdivision's
    own numbering, edge points appended per level).
    """
    positive("radius", radius)
    if int(level) != level or level < 0:
        raise ValueError(f"level must be a non-negative integer, got {plain(level)!r}")
    phi = (1.0 + 5.0**0.5) / 2.0
    vertices = np.array(
        [
            [-1, phi, 0], [1, phi, 0], [-1, -phi, 0], [1, -phi, 0],
            [0, -1, phi], [0, 1, phi], [0, -1, -phi], [0, 1, -phi],
            [phi, 0, -1], [phi, 0, 1], [-phi, 0, -1], [-phi, 0, 1],
        ],
        dtype=np.float64,
    )  # fmt: skip
    triangles = np.array(
        [
            [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
            [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
            [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
            [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
        ],
        dtype=np.int64,
    )  # fmt: skip
    for _ in range(int(level)):
        vertices, triangles = loop_subdivide(vertices, triangles)
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    on_sphere = radius * vertices
    mesh = Mesh(on_sphere, triangles)
    if limit:
        mesh = Mesh(control_points_for_limit(mesh, on_sphere), triangles)
    return mesh.reordered(keep_triangle_order=True) if reorder else mesh


def control_points_for_limit(mesh: Mesh, targets, tol: float = 1e-14, max_iter: int = 1000):
    """Control points whose Loop limit points equal `targets` (V, 3): solves L X = targets.

    L = (1 - Nχ) I + χ A has its spectrum in (0, 1]; Richardson iteration converges.
    """
    targets = np.asarray(targets, dtype=np.float64)
    rows, cols, vals = mesh.limit_mask_matrix()
    limit = scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(len(targets), len(targets)))
    scale = np.max(np.abs(targets))
    x = targets.copy()
    for _ in range(max_iter):
        residual = targets - limit @ x
        x += residual
        if np.max(np.abs(residual)) <= tol * scale:
            return x
    raise RuntimeError("limit-position fit did not converge")


def _grid_face(origin, du, dv, n, toward_centre):
    """Square face split into n×n squares, each cut along the diagonal that points to the
    face centre (`toward_centre`) so that the face's pattern has its full symmetry."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    points = origin + (i[..., None] * du + j[..., None] * dv) / n
    index = lambda a, b: a * (n + 1) + b  # noqa: E731
    triangles = []
    for a in range(n):
        for b in range(n):
            p00, p10, p01, p11 = index(a, b), index(a + 1, b), index(a, b + 1), index(a + 1, b + 1)
            in_low_a, in_low_b = 2 * a + 1 < n, 2 * b + 1 < n
            main_diagonal = (in_low_a == in_low_b) if toward_centre else (in_low_a != in_low_b)
            if main_diagonal:
                triangles += [(p00, p10, p11), (p00, p11, p01)]
            else:
                triangles += [(p00, p10, p01), (p10, p11, p01)]
    return points.reshape(-1, 3), np.array(triangles)


def _merge(parts, with_first: bool = False):
    """Join (points, triangles) parts, welding coincident points (`with_first`: also the index of
    each welded point's first copy)."""
    points = np.concatenate([p for p, _ in parts])
    offset = np.cumsum([0] + [len(p) for p, _ in parts])
    triangles = np.concatenate([t + o for (_, t), o in zip(parts, offset)])
    scale = np.max(np.abs(points))
    keys = np.round(points / scale * 1e9).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    if with_first:
        return points[first], inverse.reshape(-1)[triangles], first
    return points[first], inverse.reshape(-1)[triangles]


def cube(edge: float = 1.0, divisions: int = 4, *, reorder: bool = True) -> Mesh:
    """Cube of control-mesh `edge` centred at the origin, each face cut into divisions² squares.

    `divisions` must be even; each square is split along the diagonal pointing to its face
    centre, so the mesh has the full symmetry of the cube: corners have valence 6, face
    centres 8 and the midpoints of the cube's edges 4. With divisions >= 4 no triangle
    touches two extraordinary vertices. The triangles run face by face, row by row (already
    local); the vertices are numbered in the order the triangles first use them
    (`Mesh.reordered(keep_triangle_order=True)`) unless `reorder=False`.
    """
    positive("edge", edge)
    _check_even_divisions(divisions)
    h = 0.5 * edge
    parts = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            du = np.zeros(3)
            du[(axis + 1) % 3] = edge
            dv = np.cross(normal, du)
            origin = h * normal - 0.5 * du - 0.5 * dv
            parts.append(_grid_face(origin, du, dv, divisions, toward_centre=True))
    mesh = Mesh(*_merge(parts))
    return mesh.reordered(keep_triangle_order=True) if reorder else mesh


def prism(edge: float = 1.0, divisions: int = 4, *, reorder: bool = True) -> Mesh:
    """Triangular prism with all edges of length `edge`, centred at the origin, axis along z.

    The equilateral caps are cut into divisions² equilateral triangles, the square sides as in
    `cube` (diagonals towards the face centre; `divisions` even). Corners have valence 5.
    Numbered for locality as `cube` (`Mesh.reordered(keep_triangle_order=True)`) unless `reorder=False`.
    """
    positive("edge", edge)
    _check_even_divisions(divisions)
    n = divisions
    angles = np.pi / 2 + 2 * np.pi * np.arange(3) / 3
    base = edge / np.sqrt(3.0) * np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], 1)
    parts = []
    for z, outward in ((-0.5 * edge, -1.0), (0.5 * edge, 1.0)):
        corners = base + np.array([0.0, 0.0, z])
        parts.append(_triangle_cap(corners, n, flip=outward < 0))
    up = np.array([0.0, 0.0, edge])
    for k in range(3):
        a, b = base[k], base[(k + 1) % 3]
        origin = a - 0.5 * up
        parts.append(_grid_face(origin, b - a, up, n, toward_centre=True))
    mesh = Mesh(*_merge(parts))
    return mesh.reordered(keep_triangle_order=True) if reorder else mesh


def _triangle_cap(corners, n, flip):
    """Equilateral triangle (counter-clockwise corners) cut into n² equilateral triangles."""
    a, b, c = corners
    index = {}
    points = []
    for i in range(n + 1):
        for j in range(n + 1 - i):
            index[i, j] = len(points)
            points.append(a + (b - a) * i / n + (c - a) * j / n)
    triangles = []
    for i in range(n):
        for j in range(n - i):
            triangles.append((index[i, j], index[i + 1, j], index[i, j + 1]))
            if i + j + 1 < n:
                triangles.append((index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]))
    triangles = np.array(triangles)
    return np.array(points), triangles[:, ::-1] if flip else triangles


def _check_even_divisions(divisions):
    if int(divisions) != divisions or divisions < 2 or divisions % 2:
        raise ValueError(f"divisions must be an even integer >= 2, got {plain(divisions)!r}")


# ---------------------------------------------------------------------------------------------
# Files


def load(path, *, weld: bool = True, reorder: bool = True) -> Mesh:
    """Read a closed triangle mesh from any file meshio reads.

    With `weld=True` (default) coincident vertices are merged, as formats such as STL store
    each triangle's corners separately; vertices used by no triangle are dropped. With
    `reorder=True` (default) the mesh is numbered for locality (`Mesh.reordered`: the file's
    order, or the weld's, sorted by coordinates, can scatter a patch over the vertex array);
    `reorder=False` keeps that order (the file's own with `weld=False`, less unused vertices).
    """
    import meshio

    path = os.fspath(path)
    try:
        data = meshio.read(path)
    except (Exception, SystemExit) as error:  # meshio raises many types (even SystemExit)
        raise ValueError(f"cannot read mesh file {path!r}: {error}") from error
    other = sorted({block.type for block in data.cells if block.type not in ("triangle", "vertex", "line")})
    if other:
        raise ValueError(
            f"{path!r} has {', '.join(other)} cells; wavewarp needs a triangle mesh: triangulate "
            "it first (e.g. split each quad along a diagonal)"
        )
    blocks = [block.data for block in data.cells if block.type == "triangle"]
    if not blocks:
        raise ValueError(f"{path!r} contains no triangles")
    points = np.asarray(data.points, dtype=np.float64)
    if points.shape[1] == 2:
        raise ValueError(f"{path!r} holds a planar 2-D mesh; a shell needs 3-D vertices")
    triangles = np.concatenate(blocks).astype(np.int64)
    file_ids = np.arange(len(points))
    if weld and np.all(np.isfinite(points)):
        points, triangles, file_ids = _merge([(points[:, :3], triangles)], with_first=True)
    used, triangles = np.unique(triangles, return_inverse=True)
    mesh = Mesh(points[used], triangles.reshape(-1, 3), numbering=file_numbering(path, file_ids[used], points[used]))
    return mesh.reordered() if reorder else mesh


def file_numbering(path: str, vertex_ids, points) -> Numbering:
    """How a mesh file numbers its vertices and triangles: OBJ from 1, PLY, OFF, VTK and others from 0;
    STL has no vertex numbers (its vertices are named by their coordinates, its facets from 1)."""
    name, kind = os.path.basename(path), os.path.splitext(path)[1].lower()
    if kind == ".stl":
        return Numbering(base=1, source=f"in {name}: facets counted from 1", points=points)
    base = 1 if kind == ".obj" else 0
    return Numbering(vertex_ids, base=base, source=f"in {name}, counted from {base}")


def save(mesh: Mesh, path) -> None:
    """Write `mesh` to any format meshio writes (chosen by the extension), atomically."""
    import meshio

    path = os.fspath(path)
    with atomic_path(path) as tmp:
        meshio.write(tmp, meshio.Mesh(mesh.vertices, [("triangle", mesh.triangles)]))
