"""Newton finish of a relaxation (docs/theory/shell.md#newton-finish): Levenberg–Marquardt steps on the
exact sparse Hessian, for the equilibria nonlinear CG crawls towards.

Near the late oocyte equilibria the Hessian's condition number reaches 1e6 and more (a nearly
isometric soft mode against the stretching stiffness), so CG needs thousands of iterations and
may spend its budget. Newton's method converges there in a few steps. The Hessian comes from
coloured central differences of the device forces (kernels/newton.py): `n_colours` × 3 × 2 force
evaluations fill every 3×3 block that two vertices sharing a triangle patch make. The volume
term's dense rank-one part 2μV ∇V ∇Vᵀ is kept apart and solved with Woodbury; the
factorization is SciPy's sparse LU on the host. One dense part is left out: the volume about the
centroid, V = V₀ − x̄·S, couples every vertex through 2μV (V − V̄) ∇²(x̄·S), a rank-6 term as
small as the quadrature's error in S = ⅓∫ n dω = 0 (measured: 1e-5 of the Hessian's largest
entry). Newton's convergence is therefore quadratic down to residuals ~1e-6 and linear (ratio
~0.1 per step) below. Every step is checked on the energy, so the
energy still falls monotonically, and solves with a positive definite H + shift I in the complement
of the rigid motions (the factorization's inertia says so), so it is the minimum of a quadratic
model: an indefinite model's step amplifies round-off along the soft modes and can jump to another
equilibrium's basin next to a bifurcation. A float32 shell is finished on a float64 twin (a float32
Hessian by differences is too coarse), and its own residual at the result is its round-off floor.
The last factorization is kept: a step first tries CG on the exact Hessian action preconditioned by
it, and factors anew only where that fails (across steps, shifts and relaxations).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
import warp as wp

from .kernels.newton import hessian_columns_kernel, perturb_kernel

# relative central-difference step: its round-off (1e-16 / STEP) and truncation (STEP²) errors are both ~1e-10
DIFFERENCE_STEP = 1e-6
MAX_SHIFT_TRIES = 40  # LM shift increases before the step gives up (round-off floor)
# a step first tries CG preconditioned by the last factorization; this many iterations to this
# relative residual, or the Hessian is factored anew
KRYLOV_ITERATIONS, KRYLOV_TOL = 25, 1e-4
# relative round-off of the energy sum (float64 accumulation of float32 or float64 terms)
ENERGY_NOISE = {wp.float32: 1e-7, wp.float64: 1e-12}


def patch_pairs(host, n_vertices: int) -> sparse.csr_matrix:
    """(V, V) pattern of vertex pairs that share a triangle patch: the Hessian's nonzero blocks."""
    starts, vertices = np.asarray(host.patch_start), np.asarray(host.patch_vertices)
    sizes = np.diff(starts)
    rows, columns = [], []
    for size in np.unique(sizes):
        members = np.flatnonzero(sizes == size)
        patches = vertices[starts[members, None] + np.arange(size)]
        rows.append(np.repeat(patches, size, axis=1).ravel())
        columns.append(np.tile(patches, (1, size)).ravel())
    rows, columns = np.concatenate(rows), np.concatenate(columns)
    pattern = sparse.csr_matrix((np.ones(len(rows), dtype=np.int32), (rows, columns)), shape=(n_vertices, n_vertices))
    pattern.data[:] = 1  # the duplicates were summed: a pair counts once
    pattern.sort_indices()
    return pattern


def distance_two_colouring(pattern: sparse.csr_matrix) -> np.ndarray:
    """Colours such that no row of `pattern` holds two vertices of one colour: Warp's graph colouring
    (`warp.utils.graph_coloring_assign`, the better of its MCS and greedy orderings) of the graph whose
    edges join the vertices that share a row. Measured against a greedy NumPy colouring
    (benchmarks/warp_libraries.py): 2× faster and 3–9% fewer colours, so fewer force evaluations."""
    square = (pattern @ pattern).tocoo()
    upper = square.row < square.col
    edges = wp.array(np.stack([square.row[upper], square.col[upper]], axis=1).astype(np.int32), device="cpu")
    best = None
    for algorithm in (wp.utils.GraphColoringAlgorithm.MCS, wp.utils.GraphColoringAlgorithm.GREEDY):
        colours = wp.empty(pattern.shape[0], dtype=wp.int32, device="cpu")
        count = wp.utils.graph_coloring_assign(edges, colours, algorithm)
        if best is None or count < best[0]:
            best = (count, colours.numpy().copy())
    return best[1]


def rigid_modes(x: np.ndarray) -> np.ndarray:
    """(6, 3V) orthonormal translations and rotations about the centroid of positions x."""
    r = x - x.mean(axis=0)
    modes = []
    for axis in np.eye(3):
        modes.append(np.broadcast_to(axis, x.shape))
        modes.append(np.cross(axis, r))
    q, _ = np.linalg.qr(np.stack([m.ravel() for m in modes], axis=1))
    return q.T


class NewtonFinish:
    """Levenberg–Marquardt Newton steps for one shell: pattern, colours and buffers built once."""

    def __init__(self, shell):
        self.shell = shell
        self.work = shell if shell.scalar == wp.float64 else shell.twin("float64")
        n = shell.mesh.n_vertices
        pattern = patch_pairs(self.work.tables.host, n)
        self.indptr, self.indices = pattern.indptr, pattern.indices
        self.colour = distance_two_colouring(pattern)
        self.n_colours = int(self.colour.max()) + 1
        block_row = np.repeat(np.arange(n, dtype=np.int32), np.diff(pattern.indptr))
        with wp.ScopedDevice(shell.device):
            self.colour_device = wp.array(self.colour, dtype=wp.int32)
            self.block_row, self.block_column = wp.array(block_row), wp.array(pattern.indices.astype(np.int32))
            self.blocks = wp.zeros((len(block_row), 3, 3), dtype=wp.float64)
            self.x, self.shifted = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.forces = wp.zeros(n, dtype=wp.vec3d)
            self.forces_plus, self.forces_minus = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.gradient = wp.zeros(n, dtype=wp.vec3d)
            self.energy = wp.zeros(1, dtype=wp.float64)
        # the last factorization and LM shift, kept across steps and relaxations (a preconditioner)
        self.inverse, self.shift = None, None
        self._twinned = ()  # the shell's terms the twin's were made from
        self.factorizations = self.krylov_steps = 0

    def share_reference(self) -> None:
        """Give the float64 twin (if any) the shell's active reference concentrations, V̄ and terms (each term's
        own `twin`, given the step's state by its `share`)."""
        if self.work is not self.shell:
            c = self.shell.reference_c.numpy().astype(np.float64)
            self.work.update_reference(wp.array(c, dtype=wp.float64, device=self.work.device))
            self.work.rest_volume = self.shell.rest_volume
            terms = self.shell.terms
            if self._twinned != terms:
                self.work.terms = tuple(term.twin(self.work) for term in terms)
                self._twinned = terms
            for term, twin in zip(terms, self.work.terms):
                term.share(twin)

    def evaluate(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """(E, F) at positions x (float64 NumPy)."""
        self.x.assign(x)
        self.work.forces_device(self.x, self.forces, self.energy)
        return float(self.energy.numpy()[0]), self.forces.numpy().copy()  # on the CPU .numpy() is a view

    def hessian(self, x: np.ndarray) -> tuple[sparse.csr_matrix, np.ndarray, np.ndarray]:
        """(H_sparse, W, C): the Hessian of E at x is H_sparse + W C Wᵀ, W = ∇V, C = 2μV."""
        work, n = self.work, len(x)
        mu = work.volume_penalty
        self.x.assign(x)
        if mu > 0:
            work.volume_gradient_device(self.x, self.gradient)
        g = self.gradient.numpy().copy()
        step = DIFFERENCE_STEP * work.edge_length
        with wp.ScopedDevice(work.device):
            for k in range(self.n_colours):
                colour_sum = g[self.colour == k].sum(axis=0)
                for axis in range(3):
                    for sign, out in ((1.0, self.forces_plus), (-1.0, self.forces_minus)):
                        wp.launch(perturb_kernel, dim=n, inputs=[self.x, self.colour_device, k, axis, sign * step],
                                  outputs=[self.shifted])  # fmt: skip
                        work.forces_device(self.shifted, out)
                    wp.launch(hessian_columns_kernel, dim=len(self.block_row),
                              inputs=[self.forces_plus, self.forces_minus, self.block_row, self.block_column,
                                      self.colour_device, k, axis, wp.float64(step), self.gradient,
                                      wp.float64(2 * mu * colour_sum[axis])],
                              outputs=[self.blocks])  # fmt: skip
        h = sparse.bsr_matrix((self.blocks.numpy(), self.indices, self.indptr), shape=(3 * n, 3 * n)).tocsr()
        return 0.5 * (h + h.T), g.reshape(-1, 1), np.array([[2 * mu]])

    def hessian_action(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """H v at x (flat, float64) by central differences of the forces: the exact Hessian's action,
        the volume about the centroid included."""
        step = DIFFERENCE_STEP * self.work.edge_length / max(float(np.abs(v).max()), 1e-300)
        shift = (step * v).reshape(-1, 3)
        plus, minus = self.evaluate(x + shift)[1], self.evaluate(x - shift)[1]
        return (minus - plus).ravel() / (2 * step)

    def run(self, x0: np.ndarray, tol: float, max_steps: int, callback=None, iteration: int = 0):
        """Newton steps from x0 until max |F| <= tol · Y h ℓ̄ (in float64). Returns (x, status,
        residual, energies); status "converged", "budget" or "round-off"."""
        work = self.work
        if self.shell.self_contact is not None:
            raise ValueError("the Newton finish does not support self-contact (its pairs are not in the Hessian's "
                             "pattern): relax with method='ncg'")  # fmt: skip
        if self.shell.gradient == "autodiff":
            raise ValueError("the Newton finish needs the analytic forces: relax with method='ncg'")
        self.share_reference()
        scale = work.force_scale()
        x = np.asarray(x0, dtype=np.float64).copy()
        energy, forces = self.evaluate(x)
        residual = float(np.linalg.norm(forces, axis=1).max()) / scale
        energies = [energy]
        self.shift = None if self.inverse is None else 1e-8 * self.inverse.scale
        for step in range(max_steps):
            if residual <= tol:
                return x, "converged", residual, energies
            hessian, f = None, forces.ravel()
            # a term that holds rigid motions (a drag): no projection, and a factorization every step (the last one
            # preconditions Krylov steps only in the complement of the rigid motions)
            free = all(getattr(term, "rigid_invariant", True) for term in work.terms)
            rigid = rigid_modes(x) if free else None
            indefinite = False  # H(x) + shift I had a negative eigenvalue at this step's first shifts
            for _ in range(MAX_SHIFT_TRIES):
                d = None if self.inverse is None or indefinite or not free else self._krylov_step(x, f, rigid)
                if d is None:  # no factorization yet, or it no longer preconditions: factor H(x) + shift I
                    hessian = self.hessian(x) if hessian is None else hessian
                    self.factorizations += 1
                    try:
                        inverse = ShiftedInverse(*hessian, self.shift)
                        self.shift = inverse.shift
                        inverse.constrain(rigid)
                        indefinite = inverse.negative_eigenvalues() > 0
                    except RuntimeError:  # exactly singular
                        self.shift = self.shift or 1e-8 * float(np.abs(hessian[0].diagonal()).mean())
                        indefinite = True
                    if indefinite:  # the quadratic model has no minimum: a larger shift
                        self.shift *= 8.0
                        continue
                    self.inverse = inverse
                    d = self.inverse.solve(f)
                predicted = f @ d - 0.5 * d @ self.hessian_action(x, d)
                trial = x + d.reshape(-1, 3)
                trial_energy, trial_forces = self.evaluate(trial)
                trial_residual = float(np.linalg.norm(trial_forces, axis=1).max()) / scale
                drop = energy - trial_energy
                if predicted > 0 and drop >= 1e-4 * predicted or (
                    abs(drop) <= ENERGY_NOISE[wp.float64] * abs(energy) and trial_residual < residual
                ):
                    break
                self.shift *= 8.0
            else:
                return x, "round-off", residual, energies
            if predicted > 0 and drop >= 0.75 * predicted and not indefinite:
                self.shift = max(self.shift / 8.0, 1e-12 * self.inverse.scale)
            x, energy, forces, residual = trial, trial_energy, trial_forces, trial_residual
            energies.append(energy)
            if callback is not None:
                callback(iteration + step + 1, energy, residual)
        return x, ("converged" if residual <= tol else "budget"), residual, energies

    def _krylov_step(self, x: np.ndarray, f: np.ndarray, rigid: np.ndarray) -> np.ndarray | None:
        """(H(x) + shift I) d = f by CG on the exact Hessian action, preconditioned by the last
        factorization (of an earlier x, shift or relaxation), in the complement of the rigid modes;
        None where that does not solve it to KRYLOV_TOL within KRYLOV_ITERATIONS (or meets negative
        curvature): the caller factors H(x) anew."""

        def project(v):
            return v - rigid.T @ (rigid @ v)

        self.inverse.constrain(rigid)
        d, r = np.zeros_like(f), project(f)
        z = self.inverse.solve(r)  # in the complement (KKT)
        p, rz, target = z.copy(), r @ z, KRYLOV_TOL * np.linalg.norm(r)
        for _ in range(KRYLOV_ITERATIONS):
            q = project(self.hessian_action(x, p) + self.shift * p)
            curvature = p @ q
            if not (curvature > 0 and rz > 0):
                return None
            alpha = rz / curvature
            d += alpha * p
            r -= alpha * q
            if np.linalg.norm(r) <= target:
                self.krylov_steps += 1
                return d
            z = self.inverse.solve(r)
            rz, rz_old = r @ z, rz
            p = z + (rz / rz_old) * p
        return None


class ShiftedInverse:
    """(H + W C Wᵀ + shift I)⁻¹ by sparse LU and Woodbury (its form without C⁻¹: C may be singular);
    W is one column (the volume gradient), C = 2μV ≥ 0. After `constrain(rows)` it solves in the
    complement of those rows (the rigid motions), and counts the eigenvalues there."""

    def __init__(self, h: sparse.csr_matrix, w: np.ndarray, coupling: np.ndarray, shift: float | None):
        """shift None: 1e-8 × the mean |diagonal| (the first LM shift). The LU has a symmetric ordering
        and diagonal pivots, so U's diagonal holds the pivots of L D Lᵀ (`negative_eigenvalues`); it
        raises RuntimeError on an exactly singular matrix."""
        self.scale = float(np.abs(h.diagonal()).mean())
        self.shift = 1e-8 * self.scale if shift is None else shift
        self.lu = sparse_linalg.splu((h + self.shift * sparse.identity(h.shape[0], format="csr")).tocsc(),
                                     permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                     options={"SymmetricMode": True})  # fmt: skip
        self.w, self.coupling = w, coupling
        if coupling.any():
            self.z = self.lu.solve(w)
            self.capacitance = np.eye(len(coupling)) + coupling @ (w.T @ self.z)
        self.rows = None

    def constrain(self, rows: np.ndarray) -> None:
        """Solve from now on for d with rows d = 0 (rows orthonormal, (k, n)): the minimum of the
        quadratic model in their complement, d = A⁻¹ (f − rowsᵀ λ), A = H + W C Wᵀ + shift I (a KKT
        system). None: no constraint (a term such as a drag holds the rigid motions itself)."""
        self.rows = rows
        if rows is not None:
            self.solved_rows = self._solve(rows.T)
            self.schur = rows @ self.solved_rows

    def _solve(self, f: np.ndarray) -> np.ndarray:
        y = self.lu.solve(f)
        if not self.coupling.any():
            return y
        return y - self.z @ np.linalg.solve(self.capacitance, self.coupling @ (self.w.T @ y))

    def solve(self, f: np.ndarray) -> np.ndarray:
        y = self._solve(f)
        if self.rows is None:
            return y
        return y - self.solved_rows @ np.linalg.solve(self.schur, self.rows @ y)

    def negative_eigenvalues(self) -> int:
        """Eigenvalues of A = H + W C Wᵀ + shift I below zero, in the complement of the constrained rows
        if any. Sylvester's law of inertia counts those of H + shift I in the pivots. The PSD rank-one
        W C Wᵀ lifts one of them exactly when it flips the determinant's sign, 1 + C Wᵀ (H + shift I)⁻¹ W
        < 0. The complement of the rows R has those of A less the non-positive eigenvalues of R A⁻¹ Rᵀ
        (the inertia of A's KKT matrix)."""
        count = int(np.count_nonzero(self.lu.U.diagonal() < 0))
        if self.coupling.any():
            count -= int(self.capacitance[0, 0] < 0)
        if self.rows is not None:
            count -= int(np.count_nonzero(np.linalg.eigvalsh(0.5 * (self.schur + self.schur.T)) <= 0))
        return count
