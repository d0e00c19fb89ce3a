"""The Laplace–Beltrami operator on a shell's limit surface (docs/theory/chemistry.md, docs/theory/scenes.md).

`LaplaceBeltrami(mesh, x)` discretises -Δ_LB on the surface at control positions `x`:

* `discretization="subdivision"` (default): Galerkin on the Loop basis, the field
  `c(θ) = Σ N_I c_I` (control values, docs/theory/geometry.md), lumped mass `M_I = ∫ N_I dω` and the
  matrix-free stiffness action `(K c)_I = ∫ a^{αβ} N_I,α c,β dω`;
* `discretization="p1"`: piecewise-linear (cotangent) elements on the control connectivity,
  with every vertex placed at its Loop limit point, so that the polyhedron interpolates the
  same limit surface; barycentric lumped mass; nodal values.

Both expose the same interface, so the two can be charted against each other (docs/theory/chemistry.md).
`assembled=True` (default) sums K into CSR rows whenever the surface moves and applies it with
one gather per vertex; `assembled=False` applies it matrix-free, per quadrature point with
atomic scatter to the patch. Same K; the assembled action is several times faster (measured in
BENCHMARKS.md), the matrix-free one needs no sparsity pattern. `deterministic=True` (default: as
`wavewarp.device.set_deterministic` chose) computes the lumped mass and the matrix-free actions by
per-point factors and one fixed-order gather per vertex (kernels/laplace.py), bitwise-reproducible
on a GPU.
Device-level methods (`*_device`) take and fill Warp arrays without host round-trips, for the
steppers in `wavewarp.waves`; the NumPy methods are the public API.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .device import deterministic_default, mat22, numpy_dtype, run_steps, vec3
from .geometry import LimitMask, SurfaceTables
from .kernels import laplace as kernels_laplace
from .kernels import one_device_methods
from .kernels.laplace import (
    assemble_mass_kernel,
    assemble_stiffness_kernel,
    assembled_diagonal_kernel,
    assembled_mass_kernel,
    assembled_stiffness_kernel,
    consistent_mass_kernel,
    divide_kernel,
    dot_kernel,
    flux_factors_kernel,
    gather_point_factors_kernel,
    mass_factors_kernel,
    normalize_kernel,
    p1_consistent_mass_kernel,
    p1_assemble_kernel,
    p1_assemble_mass_kernel,
    p1_diagonal_kernel,
    p1_geometry_kernel,
    p1_stiffness_kernel,
    richardson_kernel,
    stiffness_diagonal_kernel,
    stiffness_kernel,
    surface_metric_factors_kernel,
    surface_metric_kernel,
)
from .kernels.limit_surface import limit_positions_kernel
from .mesh import Mesh

DISCRETIZATIONS = ("subdivision", "p1")
# j_floor / rest j: the stiffness's area element is kept above this fraction of the rest one. Only a
# singular limit surface reaches it (a fold sharper than the mesh: level-5 buckling, H100, 2e-9 at
# one point and λ_max 4e7× before the blow-up); contraction e^{-AC c} at AC = 1.5 leaves 0.22
J_FLOOR = 1e-2
DOT_STRIDE = 16384  # partial sums per dot product: few atomics, enough threads for a GPU


@one_device_methods("apply_device", "diagonal_device", "consistent_mass_device", "inverse_mass_device",
                    "dot_device")
class LaplaceBeltrami:
    """-Δ_LB on the limit surface of `mesh` at control positions `x` (default: the mesh's own).

    `mass()` (V,) lumped mass, `apply(c)` (V,) the stiffness action K c (symmetric, positive
    semi-definite, K·1 = 0), `stiffness_matrix()` K as scipy.sparse CSR. `update(x)` moves the
    surface (deformation-sensitive waves); the deformation-insensitive twin builds once.
    """

    def __init__(self, mesh: Mesh, x=None, *, discretization="subdivision", rule="3", assembled=True, device=None,
                 dtype="float32", deterministic=None):  # fmt: skip
        if not isinstance(mesh, Mesh):
            raise ValueError(f"mesh must be a wavewarp.mesh.Mesh, got {type(mesh).__name__}")
        if discretization not in DISCRETIZATIONS:
            raise ValueError(f"discretization must be one of {', '.join(DISCRETIZATIONS)}, got {discretization!r}")
        self.mesh, self.discretization, self.assembled = mesh, discretization, bool(assembled)
        self.deterministic = deterministic_default(deterministic) and discretization == "subdivision"
        self._mask = LimitMask.of(mesh, device=device, dtype=dtype)
        self.device, self.scalar, self.vec3 = self._mask.device, self._mask.scalar, self._mask.vec3
        self._real = numpy_dtype(self.scalar)
        n = mesh.n_vertices
        with wp.ScopedDevice(self.device):
            if discretization == "subdivision":
                self.tables = SurfaceTables.of(mesh, str(rule), device=self.device, dtype=dtype)
                self._flux_metric = wp.empty(self.tables.n_quadrature_points, dtype=mat22(self.scalar))
                self._area = wp.empty(self.tables.n_quadrature_points, dtype=self.scalar)
                self._j_floor = wp.zeros(self.tables.n_quadrature_points, dtype=self.scalar)
                self._factors = wp.empty(self.tables.n_quadrature_points if self.deterministic else 0,
                                         dtype=vec3(self.scalar))  # fmt: skip
            else:
                self._triangles = wp.array(mesh.triangles, dtype=wp.int32)
                self._cot_weight = wp.empty(mesh.n_triangles, dtype=self.vec3)
                self._area = wp.empty(mesh.n_triangles, dtype=self.scalar)
            self._x = wp.empty(n, dtype=self.vec3)
            self._points = wp.empty(n, dtype=self.vec3)
            self.mass_device = wp.zeros(n, dtype=self.scalar)
            self._c = wp.empty(n, dtype=self.scalar)
            self._out = wp.empty(n, dtype=self.scalar)
            self._mass_product = wp.empty(n, dtype=self.scalar)
            if self.assembled:
                row_start, columns = self._sparsity()
                self._row_start = wp.array(row_start, dtype=wp.int32)
                self._columns = wp.array(columns, dtype=wp.int32)
                self._values = wp.zeros(len(columns), dtype=self.scalar)
                self._mass_values = wp.zeros(len(columns), dtype=self.scalar)
                self._mass_diagonal = wp.zeros(n, dtype=self.scalar)
        self._power = {}  # per mass_corrections: the power iteration's vectors, sums and window graphs
        self.version = 0
        self._mass_version = None
        if discretization == "subdivision":  # the floor of j in D: a fraction of the rest surface's
            self.update(mesh.vertices)
            weights = np.tile(self.tables.host.weights, self.tables.n_quadrature_points // len(self.tables.host.weights))
            self._j_floor.assign((J_FLOOR * self._area.numpy() / weights).astype(self._real))
        self.update(x)

    @property
    def n_vertices(self) -> int:
        return self.mesh.n_vertices

    def _sparsity(self):
        """CSR rows and sorted columns of K without its diagonal: I, J share a patch (P1: an edge)."""
        from scipy.sparse import csr_matrix

        if self.discretization == "subdivision":
            start, vertices = self.tables.host.patch_start, self.tables.host.patch_vertices
        else:
            start, vertices = 3 * np.arange(self.mesh.n_triangles + 1), self.mesh.triangles.reshape(-1)
        incidence = csr_matrix((np.ones(len(vertices), dtype=np.int8), vertices, start),
                               shape=(len(start) - 1, self.n_vertices))  # fmt: skip
        pattern = (incidence.T @ incidence).tocsr()
        pattern.setdiag(0)
        pattern.eliminate_zeros()
        pattern.sort_indices()
        return pattern.indptr.astype(np.int32), pattern.indices.astype(np.int32)

    # ---------------------------------------------------------------- geometry
    def update(self, x=None) -> None:
        """Move the surface to control positions `x` ((V, 3) NumPy or a wp.array of vec3 on this device).

        Recomputes the mass and the metric factors of the stiffness; increments `version`.
        """
        if isinstance(x, wp.array) and wp.types.types_equal(x.dtype, self.vec3):
            x = x.view(self.vec3)  # e.g. wp.vec3d, equal to but not the same object as our vec3 type
        wp.copy(self._x, self._mask.positions(x))
        wp.launch(limit_positions_kernel, dim=self.n_vertices,
                  inputs=[self._x, self._mask.ring_start, self._mask.ring, self._mask.centre_weight,
                          self._mask.ring_weight], outputs=[self._points], device=self.device)  # fmt: skip
        if not self.deterministic:
            self.mass_device.zero_()  # the scatters add; the gather writes
        if self.discretization == "subdivision":
            t = self.tables
            metric = [self._x, *t.weighted_patch(), self._j_floor]
            if self.deterministic:
                wp.launch(surface_metric_factors_kernel, dim=t.n_quadrature_points, inputs=metric,
                          outputs=[self._flux_metric, self._area, self._factors], device=self.device)  # fmt: skip
                self._gather_factors(self.mass_device)
            else:
                wp.launch(surface_metric_kernel, dim=t.n_quadrature_points, inputs=metric,
                          outputs=[self._flux_metric, self._area, self.mass_device], device=self.device)  # fmt: skip
        else:
            wp.launch(p1_geometry_kernel, dim=self.mesh.n_triangles, inputs=[self._points, self._triangles],
                      outputs=[self._cot_weight, self._area, self.mass_device], device=self.device)  # fmt: skip
        if self.assembled:
            self._assemble()
        self.version += 1

    @property
    def j_floor(self) -> wp.array:
        """The floor of j in the stiffness's D at every quadrature point (subdivision): a hundredth of the rest j."""
        return self._j_floor

    def moved_on_device(self) -> None:
        """A captured graph's replay ran `update` on the device: take a new `version`, so that what the host
        derives from the surface (the wave's stability bound, the consistent mass) is refreshed."""
        self.version += 1

    def _assemble(self) -> None:
        """K's off-diagonal entries into the CSR pattern."""
        self._values.zero_()
        csr, n = [self._row_start, self._columns], self.mesh.n_triangles
        if self.discretization == "subdivision":
            wp.launch(assemble_stiffness_kernel, dim=n, inputs=[*self._patch(), self._flux_metric, *csr],
                      outputs=[self._values], device=self.device)  # fmt: skip
        else:
            wp.launch(p1_assemble_kernel, dim=n, inputs=[self._triangles, self._cot_weight, *csr], outputs=[self._values],
                      device=self.device)  # fmt: skip

    def _assemble_mass(self) -> None:
        """The consistent mass into the CSR pattern and a diagonal, on first use after each update."""
        self._mass_values.zero_()
        self._mass_diagonal.zero_()
        csr, mass, n = [self._row_start, self._columns], [self._mass_values, self._mass_diagonal], self.mesh.n_triangles
        if self.discretization == "subdivision":
            wp.launch(assemble_mass_kernel, dim=n, inputs=[*self._patch(), self._area, *csr], outputs=mass, device=self.device)
        else:
            wp.launch(p1_assemble_mass_kernel, dim=n, inputs=[self._triangles, self._area, *csr], outputs=mass,
                      device=self.device)  # fmt: skip
        self._mass_version = self.version

    def _patch(self) -> list:
        t = self.tables
        return t.patch()

    def _gather_factors(self, out: wp.array) -> None:
        """out_I = Σ N_I s₀ + N_I,1 s₁ + N_I,2 s₂ of the points' factors, in a fixed order (deterministic)."""
        t = self.tables
        wp.launch(gather_point_factors_kernel, dim=self.n_vertices,
                  inputs=[self._factors, *t.vertex_entries(), t.patch_start, t.triangle_type, t.basis,
                          t.points_per_triangle], outputs=[out], device=self.device)  # fmt: skip

    def mass(self) -> np.ndarray:
        """(V,) lumped mass: ∫ N_I dω (subdivision; sums to the limit-surface area) or area / 3 (P1)."""
        return self.mass_device.numpy().astype(np.float64)

    def area_elements(self) -> np.ndarray:
        """dω at every quadrature point (subdivision; (Q,)) or the triangles' areas (P1; (T,))."""
        return self._area.numpy().astype(np.float64)

    @property
    def area(self) -> float:
        """Σ M_I: the limit-surface area (subdivision) or the polyhedron's (P1)."""
        return float(self.mass().sum())

    def points(self) -> np.ndarray:
        """(V, 3) nodal points: the Loop limit points of the control vertices (P1's vertices)."""
        return self._points.numpy().astype(np.float64)

    # ---------------------------------------------------------------- operator, device level
    def apply_device(self, c: wp.array, out: wp.array) -> None:
        """out = K c (both wp.arrays of the operator's scalar type on its device; out is overwritten)."""
        if self.assembled:
            wp.launch(assembled_stiffness_kernel, dim=self.n_vertices, inputs=[c, self._row_start, self._columns, self._values],
                      outputs=[out], device=self.device)  # fmt: skip
            return
        if self.deterministic:
            wp.launch(flux_factors_kernel, dim=self.tables.n_quadrature_points, inputs=[c, *self._patch(), self._flux_metric],
                      outputs=[self._factors], device=self.device)  # fmt: skip
            self._gather_factors(out)
            return
        out.zero_()
        if self.discretization == "subdivision":
            wp.launch(stiffness_kernel, dim=self.tables.n_quadrature_points, inputs=[c, *self._patch(), self._flux_metric],
                      outputs=[out], device=self.device)  # fmt: skip
        else:
            wp.launch(p1_stiffness_kernel, dim=self.mesh.n_triangles, inputs=[c, self._triangles, self._cot_weight],
                      outputs=[out], device=self.device)  # fmt: skip

    def diagonal_device(self, out: wp.array) -> None:
        """out = diag K (Jacobi preconditioning of the implicit steppers)."""
        if self.assembled:
            wp.launch(assembled_diagonal_kernel, dim=self.n_vertices, inputs=[self._row_start, self._values], outputs=[out],
                      device=self.device)  # fmt: skip
            return
        out.zero_()
        if self.discretization == "subdivision":
            wp.launch(stiffness_diagonal_kernel, dim=self.tables.n_quadrature_points, inputs=[*self._patch(), self._flux_metric],
                      outputs=[out], device=self.device)  # fmt: skip
        else:
            wp.launch(p1_diagonal_kernel, dim=self.mesh.n_triangles, inputs=[self._triangles, self._cot_weight],
                      outputs=[out], device=self.device)  # fmt: skip

    def consistent_mass_device(self, c: wp.array, out: wp.array) -> None:
        """out = M_c c, the consistent Galerkin mass ∫ N_I N_J dω c_J (P1: the consistent P1 mass)."""
        if self.assembled:
            if self._mass_version != self.version:
                self._assemble_mass()
            wp.launch(assembled_mass_kernel, dim=self.n_vertices,
                      inputs=[c, self._row_start, self._columns, self._mass_values, self._mass_diagonal], outputs=[out],
                      device=self.device)  # fmt: skip
            return
        if self.deterministic:
            wp.launch(mass_factors_kernel, dim=self.tables.n_quadrature_points, inputs=[c, *self._patch(), self._area],
                      outputs=[self._factors], device=self.device)  # fmt: skip
            self._gather_factors(out)
            return
        out.zero_()
        if self.discretization == "subdivision":
            wp.launch(consistent_mass_kernel, dim=self.tables.n_quadrature_points, inputs=[c, *self._patch(), self._area],
                      outputs=[out], device=self.device)  # fmt: skip
        else:
            wp.launch(p1_consistent_mass_kernel, dim=self.mesh.n_triangles, inputs=[c, self._triangles, self._area],
                      outputs=[out], device=self.device)  # fmt: skip

    def inverse_mass_device(self, f: wp.array, out: wp.array, corrections: int = 0) -> None:
        """out = W_p f: M_L⁻¹ f, then p = `corrections` Richardson steps r += M_L⁻¹ (f - M_c r).

        W_p = M_L⁻¹ Σ_{j≤p} (I - M_c M_L⁻¹)^j is symmetric positive definite, tends to M_c⁻¹ as p
        grows, and keeps 1ᵀM_L W_p = 1ᵀ (total concentration conserved exactly); on smooth fields
        it matches M_c⁻¹ to O(h^{2p+2}) (docs/theory/chemistry.md).
        """
        n = self.n_vertices
        wp.launch(divide_kernel, dim=n, inputs=[f, self.mass_device], outputs=[out], device=self.device)
        for _ in range(corrections):
            self.consistent_mass_device(out, self._mass_product)
            wp.launch(richardson_kernel, dim=n, inputs=[f, self._mass_product, self.mass_device], outputs=[out],
                      device=self.device)  # fmt: skip

    def dot_device(self, a: wp.array, b: wp.array, out: wp.array, index: int = 0) -> None:
        """out[index] = a · b on the device (strided partial sums, then atomics)."""
        total = out[index : index + 1]
        total.zero_()
        stride = min(len(a), DOT_STRIDE)
        wp.launch(dot_kernel, dim=stride, inputs=[a, b, stride], outputs=[total], device=self.device)

    # ---------------------------------------------------------------- operator, NumPy
    def checked_values(self, c, name: str = "c") -> np.ndarray:
        """(V,) finite float64 values, or a ValueError naming the argument and the problem."""
        c = np.asarray(c, dtype=np.float64)
        if c.shape != (self.n_vertices,):
            raise ValueError(f"{name} must have shape ({self.n_vertices},) for this mesh, got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError(f"{name}[{int(np.flatnonzero(~np.isfinite(c))[0])}] is not finite (NaN or Inf)")
        return c

    def apply(self, c) -> np.ndarray:
        """(V,) the stiffness action K c of values c (V,)."""
        self._c.assign(self.checked_values(c).astype(self._real))
        self.apply_device(self._c, self._out)
        return self._out.numpy().astype(np.float64)

    def stiffness_matrix(self):
        """K as a scipy.sparse CSR matrix (V, V), assembled on the host from the same geometry."""
        from scipy.sparse import coo_matrix

        n = self.n_vertices
        if self.discretization == "p1":
            w = self._cot_weight.numpy().astype(np.float64)
            tri = self.mesh.triangles
            i, j = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]]), np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
            w = np.concatenate([w[:, 0], w[:, 1], w[:, 2]])
            rows, cols, vals = np.concatenate([i, j, i, j]), np.concatenate([i, j, j, i]), np.concatenate([w, w, -w, -w])
        else:
            D = self._flux_metric.numpy().astype(np.float64).reshape(self.mesh.n_triangles, -1, 2, 2)
            rows, cols, vals = self._subdivision_triplets(D, "tpab,pka,plb->tkl", slice(1, 3))
        return coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()

    def mass_matrix(self):
        """The consistent Galerkin mass ∫ N_I N_J dω as a scipy.sparse CSR matrix (for spectra)."""
        from scipy.sparse import coo_matrix

        n = self.n_vertices
        if self.discretization == "p1":
            area = self._area.numpy().astype(np.float64)
            tri = self.mesh.triangles
            rows = np.concatenate([tri[:, a] for a in range(3) for _ in range(3)])
            cols = np.concatenate([tri[:, b] for _ in range(3) for b in range(3)])
            vals = np.concatenate([area * (2.0 if a == b else 1.0) / 12.0 for a in range(3) for b in range(3)])
        else:
            area = self._area.numpy().astype(np.float64)
            rows, cols, vals = self._subdivision_triplets(
                area.reshape(self.mesh.n_triangles, -1), "tp,pk,pl->tkl", slice(0, 1), squeeze=True
            )
        return coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()

    def _subdivision_triplets(self, weight, contraction, columns, squeeze=False):
        """Per triangle and patch pair (k, l), Σ_q weight_q ⊗ B_k ⊗ B_l, grouped by patch type.

        B are the basis `columns` (N: slice(0, 1); N,α: slice(1, 3)) at the triangle's points.
        """
        host = self.tables.host
        P = host.points_per_triangle
        sizes = np.diff(host.patch_start)
        rows, cols, vals = [], [], []
        for type_id in range(len(host.types)):
            members = np.flatnonzero(host.triangle_type == type_id)
            if len(members) == 0:
                continue
            size = int(sizes[members[0]])
            B = host.basis[type_id * P:(type_id + 1) * P, :size, columns]  # (P, K, ·)
            block = np.einsum(contraction, weight[members], B[..., 0] if squeeze else B, B[..., 0] if squeeze else B)
            patch = host.patch_vertices[host.patch_start[members][:, None] + np.arange(size)]
            rows.append(np.repeat(patch, size, axis=1).reshape(-1))
            cols.append(np.tile(patch, (1, size)).reshape(-1))
            vals.append(block.reshape(-1))
        return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)

    # ---------------------------------------------------------------- fields
    def field_values(self, c) -> np.ndarray:
        """(V,) the field's values at `points()`: Loop's limit mask applied to control values (P1: c)."""
        c = self.checked_values(c)
        if self.discretization == "p1":
            return c
        rows, cols, vals = self.mesh.limit_mask_matrix()
        return np.bincount(rows, vals * c[cols], minlength=self.n_vertices)

    def control_values(self, f) -> np.ndarray:
        """(V,) coefficients whose field takes the values f (V,) at `points()` (P1: f itself).

        Subdivision: solves L c = f for Loop's limit mask L (Richardson iteration; L's spectrum
        lies in (0, 1], as in `mesh.control_points_for_limit`).
        """
        f = self.checked_values(f, "f")
        if self.discretization == "p1":
            return f
        rows, cols, vals = self.mesh.limit_mask_matrix()
        scale = max(float(np.max(np.abs(f))), np.finfo(float).tiny)
        c = f.copy()
        for _ in range(1000):
            residual = f - np.bincount(rows, vals * c[cols], minlength=self.n_vertices)
            c += residual
            if np.max(np.abs(residual)) <= 1e-14 * scale:
                return c
        raise RuntimeError("control_values: the limit-mask solve did not converge")

    # ---------------------------------------------------------------- spectrum
    def largest_eigenvalue(self, mass_corrections: int = 0, tol: float = 1e-5, max_iterations: int = 20000,
                           check_every: int = 20) -> float:  # fmt: skip
        """λ_max(W_p K) by power iteration on the device (W_0 = M⁻¹, lumped; see inverse_mass_device).

        With y = K u and z = W_p y, the estimate (y·z)/(u·y) is the Rayleigh quotient in the K inner
        product, in which W_p K is self-adjoint: it rises monotonically towards λ_max. Iteration
        stops when a window of `check_every` iterations changes it by less than `tol` (relative),
        or after `max_iterations`, and returns the estimate. Each window is one captured graph (one
        host read per window). The vector is kept and warm-starts the next call (after `update`,
        typically two windows).
        """
        corrections = int(mass_corrections)
        if corrections < 0 or max_iterations < 1 or check_every < 1 or not tol > 0:
            raise ValueError("largest_eigenvalue needs mass_corrections >= 0, max_iterations >= 1, check_every >= 1, tol > 0")
        n = self.n_vertices
        if corrections not in self._power:
            with wp.ScopedDevice(self.device):
                start = np.random.default_rng(corrections).uniform(-1.0, 1.0, n)
                u = wp.array(start.astype(self._real), dtype=self.scalar)
                y, z = wp.empty(n, dtype=self.scalar), wp.empty(n, dtype=self.scalar)
                sums = wp.zeros(3, dtype=self.scalar)  # y·z, u·y, z·z
            self._power[corrections] = (u, y, z, sums, {})
        u, y, z, sums, graphs = self._power[corrections]
        if corrections and self.assembled and self._mass_version != self.version:
            self._assemble_mass()  # host logic stays out of the captured window

        def iterate():
            self.apply_device(u, y)
            self.inverse_mass_device(y, z, corrections)
            self.dot_device(y, z, sums, 0)
            self.dot_device(u, y, sums, 1)
            self.dot_device(z, z, sums, 2)
            wp.launch(normalize_kernel, dim=n, inputs=[z, sums[2:3]], outputs=[u], device=self.device)

        previous, iteration = 0.0, 0
        while iteration < max_iterations:
            window = min(check_every, max_iterations - iteration)
            run_steps(iterate, window, device=self.device, graphs=graphs, modules=(kernels_laplace,), capture=True)
            iteration += window
            yz, uy, _ = sums.numpy().astype(np.float64)
            estimate = yz / uy
            if not math.isfinite(estimate) or estimate <= 0:
                raise RuntimeError(f"largest_eigenvalue: power iteration broke down (estimate {estimate})")
            if estimate - previous <= tol * estimate:
                break
            previous = estimate
        return estimate

    def world_largest_eigenvalues(self, worlds: int, mass_corrections: int = 0, tol: float = 1e-5,
                                  max_iterations: int = 20000, check_every: int = 20) -> np.ndarray:  # fmt: skip
        """λ_max(W_p K) of each of `worlds` equal blocks (batched worlds never couple: W_p K is block
        diagonal), by `largest_eigenvalue`'s power iteration with each block normalised on its own.
        Host-driven (a read per iteration): for naming the world that lowered a batch's bound, not for
        the step loop."""
        n, corrections = self.n_vertices, int(mass_corrections)
        start = np.random.default_rng(corrections).uniform(-1.0, 1.0, (worlds, n // worlds))
        u = wp.array(start.ravel().astype(self._real), dtype=self.scalar, device=self.device)
        y, z = wp.empty_like(u), wp.empty_like(u)
        if corrections and self.assembled and self._mass_version != self.version:
            self._assemble_mass()
        previous = np.zeros(worlds)
        for iteration in range(1, max_iterations + 1):
            self.apply_device(u, y)
            self.inverse_mass_device(y, z, corrections)
            uu, yy, zz = (a.numpy().astype(np.float64).reshape(worlds, -1) for a in (u, y, z))
            estimate = np.sum(yy * zz, axis=1) / np.sum(uu * yy, axis=1)
            if not np.all(np.isfinite(estimate) & (estimate > 0)):
                raise RuntimeError(f"world_largest_eigenvalues: power iteration broke down (estimates {estimate})")
            u.assign((zz / np.linalg.norm(zz, axis=1, keepdims=True)).ravel().astype(self._real))
            if iteration % check_every == 0:
                if np.all(estimate - previous <= tol * estimate):
                    break
                previous = estimate
        return estimate
