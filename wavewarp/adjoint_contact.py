"""The implicit contact's adjoint (docs/theory/gradients.md, "Reverse mode"): the per-point solve and its Jacobi
sweeps (kernels/contact.py `eval_implicit_ground`, the lab frame), on the limit points (point contact) or the limit
surface's quadrature points (area contact), run again at a substep and then taken backwards.

With G the points' gather from the control points (L, or the quadrature basis N) and S = Gᵀ weighted by each point's
area a (1 on limit points): forward, the responses r = scale × G M⁻¹ S 1_contact (piecewise constant in x, no
derivative), f⁰ = law(p, u*, r), and each sweep f^s = law(p, o^s, r) with o^s = u* + scale (G M⁻¹ S - r) f^(s-1).
Backward, given f̂ of the final forces: each sweep's law adjoint gives ô^s, ẑ and the parameters'; û* += ô^s and
f̂^(s-1) = scale (Sᵀ M⁻¹ Gᵀ - r) ô^s; the first law's adjoint gives û* its last share.
"""

from __future__ import annotations

import warp as wp

from .kernels.adjoint import eval_add, eval_coupling_transpose, eval_implicit_law_adjoint, eval_weighted_dot, implicit_laws
from .kernels.contact import (
    contact_indicator_kernel,
    ground_motion,
    implicit_contact_kernel,
    limit_coupled_velocity_kernel,
    limit_response_kernel,
    quadrature_coupled_velocity_kernel,
    quadrature_response_kernel,
    spread_to_control_points,
)


class ImplicitContactAdjoint:
    """The implicit contact of `solver` (an InertialSolver or OverdampedSolver with Ground(solve="implicit"), the lab
    frame, one world, float64): `forward(x, v_star, scale, dt)` solves it again storing every sweep,
    `backward(force_hat, ...)` takes it back."""

    def __init__(self, solver):
        self.solver, self.ground, self.mask = solver, solver.ground, solver.mask
        self.point = self.ground.contact == "point"
        self.patch, area = solver.ground_tables()
        self.tables = ([self.mask.ring_start, self.mask.ring, self.mask.centre_weight, self.mask.ring_weight]
                       if self.point else list(self.patch))  # fmt: skip
        n, vertices, sweeps = solver.ground_points, len(solver.mass), self.ground.sweeps
        self.gradient = wp.zeros(5, dtype=wp.float64, device=solver.device)  # ∂/∂(k, β, μ, k_f, scale)
        with wp.ScopedDevice(solver.device):
            self.area = wp.ones(n, dtype=wp.float64) if area is None else area  # a: dω̄⁰, or 1 on limit points
            self.ones = wp.ones(n, dtype=wp.float64)
            self.p, self.u_star = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.response, self.normal = wp.zeros(n, dtype=wp.float64), wp.zeros(n, dtype=wp.float64)
            self.no_response, self.zeros = wp.zeros(n, dtype=wp.float64), wp.zeros(n, dtype=wp.vec3d)
            self.load = wp.zeros(vertices, dtype=wp.vec3d)
            self.body = wp.zeros(1, dtype=wp.vec3d)
            self.forces = [wp.zeros(n, dtype=wp.vec3d) for _ in range(sweeps + 1)]  # f^0 … f^S
            self.others = [wp.zeros(n, dtype=wp.vec3d) for _ in range(sweeps + 1)]  # o^1 … o^S (o^0 = u*)
            self.o_hat, self.f_hat, self.gathered = (wp.zeros(n, dtype=wp.vec3d) for _ in range(3))

    def _coupled(self, forces, predictor, response, area, scale: float, out) -> None:
        """out = predictor + scale (G M⁻¹ S_area forces - response forces) (the sweep's velocity without the point's
        own force; `area` weights the spread: the points' areas, or 1 for the transpose's first half)."""
        self.load.zero_()
        spread_to_control_points(self.ground, forces, self.mask, self.patch, None if self.point else area, self.load)
        kernel = limit_coupled_velocity_kernel if self.point else quadrature_coupled_velocity_kernel
        wp.launch(kernel, dim=len(out), inputs=[self.load, self.solver.inverse_mass, wp.float64(scale), *self.tables,
                                                predictor, response, forces],
                  outputs=[out], device=out.device)  # fmt: skip

    def forward(self, x, v_star, scale: float, dt: float) -> None:
        """The contact solve at positions x from the predictor v_star, every sweep's forces and velocities kept."""
        device, n = x.device, len(self.p)
        ground_motion(self.ground, x, v_star, self.mask, self.patch, self.p, self.u_star)
        wp.launch(contact_indicator_kernel, dim=n, inputs=[self.p], outputs=[self.forces[0]], device=device)
        self.load.zero_()
        spread_to_control_points(self.ground, self.forces[0], self.mask, self.patch, None if self.point else self.area,
                                 self.load)  # fmt: skip
        kernel = limit_response_kernel if self.point else quadrature_response_kernel
        wp.launch(kernel, dim=n, inputs=[self.load, self.solver.inverse_mass, *self.tables], outputs=[self.response],
                  device=device)  # fmt: skip
        laws = implicit_laws(self.ground, scale, dt)
        velocities = self.u_star
        for s in range(len(self.forces)):
            if s > 0:
                self._coupled(self.forces[s - 1], self.u_star, self.response, self.area, scale, self.others[s])
                velocities = self.others[s]
            wp.launch(implicit_contact_kernel, dim=n, inputs=[self.p, velocities, self.response, *laws, self.body],
                      outputs=[self.normal, self.forces[s]], device=device)  # fmt: skip

    def backward(self, force_hat, scale: float, dt: float, u_star_hat, p_hat) -> None:
        """Given f̂ of the final forces at the points: u_star_hat = û* (overwritten), p_hat += ẑ, and `gradient` +=
        ∂/∂(k, β, μ, k_f, scale) of f̂ · f, the final velocity's share of scale included."""
        gradient = self.gradient
        eval_weighted_dot(force_hat, self.forces[-1], 1.0 / scale, 4, gradient)  # v = v* + scale M⁻¹ S f
        wp.copy(self.f_hat, force_hat)
        u_star_hat.zero_()
        for s in reversed(range(len(self.forces))):
            velocity = self.u_star if s == 0 else self.others[s]
            eval_implicit_law_adjoint(self.ground, self.p, velocity, self.response, scale, dt, self.f_hat, self.o_hat,
                                      p_hat, gradient)  # fmt: skip
            eval_add(u_star_hat, self.o_hat)
            if s > 0:  # o^s = u* + scale (G M⁻¹ S - r) f^(s-1): f̂^(s-1), then ∂/∂scale
                self._coupled(self.o_hat, self.zeros, self.no_response, self.ones, scale, self.gathered)
                eval_coupling_transpose(self.gathered, self.area, self.response, scale, self.o_hat, self.f_hat)
                eval_weighted_dot(self.f_hat, self.forces[s - 1], 1.0 / scale, 4, gradient)
