"""Quasi-static relaxation of a Shell: preconditioned nonlinear CG (Polak–Ribière+) with an
Armijo line search on a parabolic step estimate (SPEC §3; choice and measurements in
docs/shell.md). All vectors live on the device; each iteration reads a few scalars back.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .kernels.relax import direction_kernel, dot_kernel, precondition_kernel, reductions_kernel, step_kernel

ARMIJO = 1e-4
# relative round-off of the energy sum (float64 accumulation of float32 or float64 terms)
ENERGY_NOISE = {wp.float32: 1e-7, wp.float64: 1e-12}


def _inverse_stiffness(shell) -> np.ndarray:
    """1/k with k = (Y h / ℓ̄² + Y h³ / ℓ̄⁴) Ā, Ā the mean control area per vertex.

    One value for all vertices: it sets the step scale without giving the search direction a
    net translation or rotation (internal forces have none), so rigid modes cannot stall it.
    """
    mesh, ell = shell.mesh, shell.edge_length
    a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    area_per_vertex = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum() / mesh.n_vertices
    stiffness = shell.young * shell.thickness * (1 / ell**2 + shell.thickness**2 / ell**4) * area_per_vertex
    return np.full(mesh.n_vertices, 1.0 / stiffness)


def relax(shell, x: wp.array, tol: float, max_iterations: int, callback=None) -> np.ndarray:
    device, vec3, scalar = shell.device, shell.vec3, shell.scalar
    n = shell.mesh.n_vertices
    noise = ENERGY_NOISE[scalar]
    with wp.ScopedDevice(device):
        x = wp.clone(x)
        trial = wp.empty_like(x)
        forces, trial_forces = wp.zeros(n, dtype=vec3), wp.zeros(n, dtype=vec3)
        s, s_old, direction = wp.zeros(n, dtype=vec3), wp.zeros(n, dtype=vec3), wp.zeros(n, dtype=vec3)
        inverse_stiffness = wp.array(_inverse_stiffness(shell).astype(shell._real), dtype=scalar)
        energy, trial_energy = wp.zeros(1, dtype=wp.float64), wp.zeros(1, dtype=wp.float64)
        sums = wp.zeros(4, dtype=scalar)

    def evaluate(at, f, e):
        shell.forces_device(at, f, e)
        return float(e.numpy()[0])

    def reduce():
        sums.zero_()
        wp.launch(reductions_kernel, dim=n, inputs=[forces, s, s_old, direction], outputs=[sums], device=device)
        return sums.numpy().astype(np.float64)

    force_scale = shell.force_scale()
    e = evaluate(x, forces, energy)
    wp.launch(precondition_kernel, dim=n, inputs=[forces, inverse_stiffness], outputs=[s], device=device)
    wp.copy(direction, s)
    fs, _, fd, fmax = reduce()
    alpha = 1.0
    history = [e]
    for iteration in range(max_iterations):
        residual = fmax / force_scale
        if callback is not None:
            callback(iteration, e, residual)
        if residual <= tol:
            shell.relax_history = history
            return x.numpy().astype(np.float64)
        slope = -fd  # dE/dα along d (< 0)
        alpha, e_new = _line_search(shell, x, direction, trial, trial_forces, trial_energy, e, slope, alpha, noise,
                                    evaluate)  # fmt: skip
        if alpha == 0.0:
            break
        x, trial = trial, x
        forces, trial_forces = trial_forces, forces
        energy, trial_energy = trial_energy, energy
        e = e_new
        history.append(e)
        wp.copy(s_old, s)
        wp.launch(precondition_kernel, dim=n, inputs=[forces, inverse_stiffness], outputs=[s], device=device)
        fs_new, f_ds, _, _ = reduce()
        beta = max(0.0, f_ds / fs) if fs > 0 else 0.0
        wp.launch(direction_kernel, dim=n, inputs=[s, scalar(beta)], outputs=[direction], device=device)
        fs, _, fd, fmax = reduce()
        fs = fs_new
        if fd <= 0.0:  # not a descent direction: restart along the preconditioned force
            wp.copy(direction, s)
            fs, _, fd, fmax = reduce()
    shell.relax_history = history
    from .shell import RelaxationError

    residual = fmax / force_scale
    raise RelaxationError(
        f"relax stopped after {len(history) - 1} iterations at residual max|F|/(Y h ℓ̄) = {residual:.3g}, "
        f"{residual / tol:.3g}× the tolerance {tol:g}"
        + (" (the line search found no lower energy: round-off floor; use dtype='float64' or a larger tol)"
           if alpha == 0.0 else "; raise max_iterations or tol"),  # fmt: skip
        residual, x.numpy().astype(np.float64), round_off=alpha == 0.0,
    )  # fmt: skip


def _line_search(shell, x, direction, trial, trial_forces, trial_energy, e0, slope, alpha, noise, evaluate):
    """Step along d: secant estimate of dE/dα = 0 from the slopes at 0 and α, then backtracking.

    A step is accepted when it satisfies Armijo's condition, or, where the energy change is
    below round-off (float32 near equilibrium), when it keeps E within round-off and reduces
    the slope |dE/dα| or still descends. Returns (α, E(x + α d)), or (0, e0) when no step helps.
    """
    n = shell.mesh.n_vertices
    device, scalar = shell.device, shell.scalar
    dot = wp.zeros(1, dtype=scalar, device=device)

    def at(a):
        wp.launch(step_kernel, dim=n, inputs=[x, direction, scalar(a)], outputs=[trial], device=device)
        e = evaluate(trial, trial_forces, trial_energy)
        dot.zero_()
        wp.launch(dot_kernel, dim=n, inputs=[trial_forces, direction], outputs=[dot], device=device)
        return e, -float(dot.numpy()[0])

    e1, slope1 = at(alpha)
    candidate = alpha * slope / (slope - slope1) if slope1 > slope else 4 * alpha
    candidate = min(candidate, 4 * alpha)
    tolerance = noise * max(abs(e0), 1e-300)
    for _ in range(40):
        e, slope_new = (e1, slope1) if candidate == alpha else at(candidate)
        armijo = e <= e0 + ARMIJO * candidate * slope
        # below round-off (float32): accept a step that keeps E within round-off and either
        # flattens the slope or still descends (dE/dα ≤ 0 at both ends: negative curvature near
        # a buckling instability, where energy differences drown in round-off)
        if armijo or (e <= e0 + tolerance and (abs(slope_new) < abs(slope) or slope_new <= 0.0)):
            return candidate, e
        candidate *= 0.5
    return 0.0, e0
