"""The Loop limit surface on a device (docs/theory/geometry.md, docs/theory/scenes.md).

`SurfaceTables` holds a mesh's patch tables on one device in one dtype, built once and
shared by every kernel that evaluates the surface (geometry, mechanics, chemistry).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import warp as wp

from .device import mat22, numpy_dtype, resolve_device, resolve_dtype, vec3, vec6
from .kernels.contact import quadrature_spread_kernel
from .kernels.limit_surface import limit_positions_kernel, limit_surface_kernel, quadrature_points_kernel
from .kernels.self_contact import quadrature_gather_kernel
from .mesh import Mesh
from .patches import PatchTables, build_patch_tables
from .subdivision import limit_weight, patch_basis

_patch_tables: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_device_tables: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def patch_tables(mesh: Mesh, rule: str = "3") -> PatchTables:
    """NumPy patch tables of `mesh` for quadrature `rule`, built once per mesh and rule."""
    per_mesh = _patch_tables.setdefault(mesh, {})
    if rule not in per_mesh:
        per_mesh[rule] = build_patch_tables(mesh.triangles, mesh.n_vertices, rule)
    return per_mesh[rule]


class _DeviceArrays:
    """Per-mesh Warp arrays for one device and dtype, built once and cached per mesh."""

    def __init__(self, mesh: Mesh, *, device=None, dtype="float32"):
        self.mesh = mesh
        self.device = resolve_device(device)
        self.scalar = resolve_dtype(dtype)
        self.vec3 = vec3(self.scalar)

    @classmethod
    def of(cls, mesh: Mesh, *args, device=None, dtype="float32"):
        """Cached instance: one build per (class, mesh, arguments, device, dtype)."""
        key = (cls.__name__, args, resolve_device(device).alias, resolve_dtype(dtype).__name__)
        per_mesh = _device_tables.setdefault(mesh, {})
        if key not in per_mesh:
            per_mesh[key] = cls(mesh, *args, device=device, dtype=dtype)
        return per_mesh[key]

    def positions(self, x=None) -> wp.array:
        """Control positions as a Warp array (the mesh's own vertices when `x` is None)."""
        if isinstance(x, wp.array):
            if x.device != self.device or x.dtype != self.vec3 or x.shape != (self.mesh.n_vertices,):
                raise ValueError(
                    f"x must be a wp.array of {self.mesh.n_vertices} {self.vec3.__name__} on {self.device}"
                )
            return x
        x = self.mesh.vertices if x is None else checked_positions(x, self.mesh.n_vertices)
        return wp.array(x.astype(numpy_dtype(self.scalar)), dtype=self.vec3, device=self.device)


class LimitMask(_DeviceArrays):
    """Loop's limit-position mask as a CSR of one-rings (docs/theory/scenes.md)."""

    def __init__(self, mesh: Mesh, *, device=None, dtype="float32"):
        super().__init__(mesh, device=device, dtype=dtype)
        ring_start, ring, centre, neighbour = _limit_mask_csr(mesh)
        real = numpy_dtype(self.scalar)
        with wp.ScopedDevice(self.device):
            self.ring_start = wp.array(ring_start, dtype=wp.int32)
            self.ring = wp.array(ring, dtype=wp.int32)
            self.centre_weight = wp.array(centre.astype(real), dtype=self.scalar)
            self.ring_weight = wp.array(neighbour.astype(real), dtype=self.scalar)


class SurfaceTables(_DeviceArrays):
    """Patch tables of one mesh and quadrature rule as Warp arrays on one device and dtype."""

    def __init__(self, mesh: Mesh, rule: str = "3", *, device=None, dtype="float32"):
        super().__init__(mesh, device=device, dtype=dtype)
        self.host = patch_tables(mesh, str(rule))
        host, real = self.host, numpy_dtype(self.scalar)
        with wp.ScopedDevice(self.device):
            self.patch_start = wp.array(host.patch_start, dtype=wp.int32)
            self.patch_vertices = wp.array(host.patch_vertices, dtype=wp.int32)
            self.triangle_type = wp.array(host.triangle_type, dtype=wp.int32)
            self.basis = wp.array(host.basis.astype(real), dtype=vec6(self.scalar))
            self.weights = wp.array(host.weights.astype(real), dtype=self.scalar)
        self._vertex_entries = None

    def vertex_entries(self) -> list:
        """For the deterministic gathers (built on first use): each vertex's entries in the patch table,
        as [vertex_entry_start, vertex_entries, entry_triangle] (a vertex's entries in table order)."""
        if self._vertex_entries is None:
            sizes = np.diff(self.host.patch_start)
            triangle = np.repeat(np.arange(len(sizes)), sizes)
            vertex = np.asarray(self.host.patch_vertices)
            order = np.argsort(vertex, kind="stable")
            start = np.concatenate([[0], np.cumsum(np.bincount(vertex, minlength=self.mesh.n_vertices))])
            self._vertex_entries = [wp.array(a.astype(np.int32), dtype=wp.int32, device=self.device)
                                    for a in (start, order, triangle)]  # fmt: skip
        return self._vertex_entries

    def patch(self) -> list:
        """The arguments of every kernel that gathers over a triangle's patch, in their order: patch_start,
        patch_vertices, triangle_type, basis, points_per_triangle."""
        return [self.patch_start, self.patch_vertices, self.triangle_type, self.basis, self.points_per_triangle]

    def weighted_patch(self) -> list:
        """`patch()` with the quadrature weights before points_per_triangle (the kernels that integrate)."""
        return [self.patch_start, self.patch_vertices, self.triangle_type, self.basis, self.weights, self.points_per_triangle]

    @property
    def n_quadrature_points(self) -> int:
        return self.host.n_quadrature_points

    @property
    def points_per_triangle(self) -> int:
        return self.host.points_per_triangle


def checked_positions(x, n_vertices: int, name: str = "x") -> np.ndarray:
    """(V, 3) finite float64 positions, or a ValueError naming the argument and the problem."""
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (n_vertices, 3):
        raise ValueError(f"{name} must have shape ({n_vertices}, 3) for this mesh, got {x.shape}")
    if not np.all(np.isfinite(x)):
        i = int(np.flatnonzero(~np.all(np.isfinite(x), axis=1))[0])
        raise ValueError(f"{name}[{i}] = {x[i].tolist()} is not finite (NaN or Inf)")
    return x


def limit_coupling(mesh: Mesh, inverse_mass: np.ndarray) -> tuple:
    """C = L M⁻¹ Lᵀ (L Loop's limit mask, M⁻¹ = diag(inverse_mass)) as CSR (row start, columns, values; float64): a
    control point's coupling to the points within two rings, the implicit contact's sweeps' operator."""
    ring_start, ring, centre, neighbour = _limit_mask_csr(mesh)
    n = mesh.n_vertices
    rows = np.concatenate([np.arange(n), np.repeat(np.arange(n), np.diff(ring_start))])
    columns = np.concatenate([np.arange(n), ring])
    values = np.concatenate([centre, np.repeat(neighbour, np.diff(ring_start))])
    limit = sp.csr_matrix((values, (rows, columns)), shape=(n, n))
    coupling = (limit @ sp.diags(np.asarray(inverse_mass, dtype=np.float64)) @ limit.T).tocsr()
    coupling.sort_indices()
    return coupling.indptr, coupling.indices, coupling.data


def _limit_mask_csr(mesh: Mesh):
    edges = mesh.edges
    centre = np.concatenate([edges[:, 0], edges[:, 1]])
    other = np.concatenate([edges[:, 1], edges[:, 0]])
    order = np.argsort(centre, kind="stable")
    counts = np.bincount(centre, minlength=mesh.n_vertices)
    ring_start = np.concatenate([[0], np.cumsum(counts)])
    chi = limit_weight(mesh.valence.astype(np.float64))
    return ring_start, other[order], 1.0 - mesh.valence * chi, chi


@dataclass(frozen=True)
class LimitSurface:
    """The limit surface at every quadrature point (Q = triangles × points per triangle).

    Quadrature point q lies on triangle `triangle[q]` at parameters `parameters[q]` (v, w).
    """

    points: np.ndarray  # (Q, 3) x
    tangents: np.ndarray  # (Q, 2, 3) a_1, a_2
    normals: np.ndarray  # (Q, 3) outward unit normal
    metric: np.ndarray  # (Q, 2, 2) a_αβ
    curvature: np.ndarray  # (Q, 2, 2) b_αβ = n·x,αβ
    area: np.ndarray  # (Q,) dω = j w_q; sums to the surface area
    mean_curvature: np.ndarray  # (Q,) +1/R on a sphere
    gauss_curvature: np.ndarray  # (Q,) det b / det a
    triangle: np.ndarray  # (Q,)
    parameters: np.ndarray  # (Q, 2)

    @property
    def total_area(self) -> float:
        return float(self.area.sum())

    def integrate(self, values) -> float:
        """∫ f dω for f given at the quadrature points."""
        return float(np.dot(np.asarray(values, dtype=np.float64), self.area))


def limit_positions(mesh: Mesh, x=None, *, device=None, dtype="float32") -> np.ndarray:
    """(V, 3) limit points of the control vertices at positions `x` (default: the mesh's)."""
    tables = LimitMask.of(mesh, device=device, dtype=dtype)
    xw = tables.positions(x)
    out = wp.empty(mesh.n_vertices, dtype=tables.vec3, device=tables.device)
    wp.launch(
        limit_positions_kernel,
        dim=mesh.n_vertices,
        inputs=[xw, tables.ring_start, tables.ring, tables.centre_weight, tables.ring_weight],
        outputs=[out],
        device=tables.device,
    )
    return out.numpy().astype(np.float64)


def limit_surface(mesh: Mesh, x=None, *, rule: str = "3", device=None, dtype="float32") -> LimitSurface:
    """Evaluate the limit surface of `mesh` at positions `x` on every quadrature point.

    A mesh with a triangle touching two extraordinary vertices raises ValueError that
    points to `Mesh.subdivided()`.
    """
    tables = SurfaceTables.of(mesh, str(rule), device=device, dtype=dtype)
    out = evaluate(tables, tables.positions(x))
    host = tables.host
    n_q = tables.n_quadrature_points
    arrays = {name: a.numpy().astype(np.float64) for name, a in out.items()}
    return LimitSurface(
        **arrays,
        triangle=np.repeat(np.arange(host.n_triangles), host.points_per_triangle),
        parameters=np.tile(host.points, (host.n_triangles, 1))[:n_q],
    )


def sample_points(mesh: Mesh, triangle, parameters, x=None) -> np.ndarray:
    """(n, 3) limit-surface points of `triangle[i]` at `parameters[i]` = (v, w), in NumPy.

    (v, w) are barycentric weights of the triangle's 2nd and 3rd vertex: (0, 0) is its 1st.
    For probes and checks; the Warp kernels serve whole-surface evaluation.
    """
    triangle = np.atleast_1d(np.asarray(triangle, dtype=np.int64))
    parameters = np.atleast_2d(np.asarray(parameters, dtype=np.float64))
    if parameters.shape != (len(triangle), 2):
        raise ValueError(f"parameters must have shape ({len(triangle)}, 2), got {parameters.shape}")
    if np.any(triangle < 0) or np.any(triangle >= mesh.n_triangles):
        raise ValueError(f"triangle indices must lie in [0, {mesh.n_triangles})")
    x = mesh.vertices if x is None else checked_positions(x, mesh.n_vertices)
    host = patch_tables(mesh)
    out = np.empty((len(triangle), 3))
    kind = host.triangle_type[triangle]
    for type_id in np.unique(kind):
        members = np.flatnonzero(kind == type_id)
        valence, corner = host.types[type_id]
        basis = patch_basis(valence, corner, parameters[members, 0], parameters[members, 1])[..., 0]
        starts = host.patch_start[triangle[members]]
        rings = host.patch_vertices[starts[:, None] + np.arange(basis.shape[1])]
        out[members] = np.einsum("pk,pkd->pd", basis, x[rings])
    return out


def quadrature_points(tables: SurfaceTables, x: wp.array, out: wp.array) -> None:
    """out_q = Σ N_I(q) x_I: the limit surface at every quadrature point (values only). Capturable."""
    wp.launch(quadrature_points_kernel, dim=tables.n_quadrature_points, inputs=[x, *tables.patch()], outputs=[out],
              device=tables.device)  # fmt: skip


def spread_quadrature_forces(tables: SurfaceTables, pressures: wp.array, area: wp.array, forces: wp.array,
                             deterministic: bool) -> None:
    """forces_I += Σ_q N_I(q) f_q w_q: a force per rest area at the quadrature points (`pressures`, rest areas
    `area`) on the control points — atomically, or gathered in a fixed order where `deterministic`. Capturable."""
    if deterministic:
        wp.launch(quadrature_gather_kernel, dim=len(forces),
                  inputs=[pressures, area, *tables.vertex_entries(), tables.patch_start, tables.triangle_type,
                          tables.basis, tables.points_per_triangle],
                  outputs=[forces], device=tables.device)  # fmt: skip
    else:
        wp.launch(quadrature_spread_kernel, dim=tables.n_quadrature_points, inputs=[pressures, area, *tables.patch()],
                  outputs=[forces], device=tables.device)  # fmt: skip


def evaluate(tables: SurfaceTables, x: wp.array, out: dict | None = None) -> dict:
    """Launch the limit-surface kernel into `out` (allocated when None); returns the arrays."""
    n_q = tables.n_quadrature_points
    if out is None:
        with wp.ScopedDevice(tables.device):
            out = {
                "points": wp.empty(n_q, dtype=tables.vec3),
                "tangents": wp.empty((n_q, 2), dtype=tables.vec3),
                "normals": wp.empty(n_q, dtype=tables.vec3),
                "metric": wp.empty(n_q, dtype=mat22(tables.scalar)),
                "curvature": wp.empty(n_q, dtype=mat22(tables.scalar)),
                "area": wp.empty(n_q, dtype=tables.scalar),
                "mean_curvature": wp.empty(n_q, dtype=tables.scalar),
                "gauss_curvature": wp.empty(n_q, dtype=tables.scalar),
            }
    wp.launch(
        limit_surface_kernel,
        dim=n_q,
        inputs=[
            x,
            tables.patch_start,
            tables.patch_vertices,
            tables.triangle_type,
            tables.basis,
            tables.weights,
            tables.points_per_triangle,
        ],
        outputs=[out[k] for k in LIMIT_SURFACE_FIELDS],
        device=tables.device,
    )
    return out


LIMIT_SURFACE_FIELDS = (
    "points", "tangents", "normals", "metric", "curvature", "area", "mean_curvature", "gauss_curvature",
)  # fmt: skip
