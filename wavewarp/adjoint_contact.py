"""The implicit contact's adjoint (docs/theory/gradients.md, "Reverse mode"): the point contact's per-point solve and
its Jacobi sweeps (kernels/contact.py `eval_implicit_ground`, the lab frame), run again at a substep and then taken
backwards.

Forward: the contact set's responses r = scale × (the row sums of L M⁻¹ Lᵀ over the points in contact; piecewise
constant in x, no derivative), f⁰ = law(p, u*, r), and each sweep f^s = law(p, o^s, r) with o^s = u* + scale (A f^(s-1)
- r f^(s-1)), A = L M⁻¹ Lᵀ (symmetric). Backward, given f̂ of the final forces: each sweep's law adjoint gives ô^s,
ẑ and the parameters'; û* += ô^s and f̂^(s-1) = scale (A ô^s - r ô^s); the first law's adjoint gives û* its last
share.
"""

from __future__ import annotations

import warp as wp

from .kernels.adjoint import eval_add, eval_implicit_law_adjoint, eval_weighted_dot
from .kernels.contact import (
    contact_indicator_kernel,
    ground_motion,
    implicit_contact_kernel,
    limit_coupled_velocity_kernel,
    limit_response_kernel,
    spread_to_control_points,
)


class ImplicitContactAdjoint:
    """The implicit point contact of `solver` (an InertialSolver or OverdampedSolver with Ground(solve="implicit"),
    the lab frame, one world, float64): `forward(x, v_star, scale, dt)` solves it again storing every sweep,
    `backward(force_hat, ...)` takes it back."""

    def __init__(self, solver):
        self.solver, self.ground, self.mask = solver, solver.ground, solver.mask
        self.gradient = wp.zeros(5, dtype=wp.float64, device=solver.device)  # ∂/∂(k, β, μ, k_f, scale)
        n = len(solver.mass)
        sweeps = self.ground.sweeps
        with wp.ScopedDevice(solver.device):
            self.p, self.u_star = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.response, self.normal = wp.zeros(n, dtype=wp.float64), wp.zeros(n, dtype=wp.float64)
            self.load, self.zeros = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.body = wp.zeros(1, dtype=wp.vec3d)
            self.forces = [wp.zeros(n, dtype=wp.vec3d) for _ in range(sweeps + 1)]  # f^0 … f^S
            self.others = [wp.zeros(n, dtype=wp.vec3d) for _ in range(sweeps + 1)]  # o^1 … o^S (o^0 = u*)
            self.u_hat, self.o_hat = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
            self.f_hat, self.scratch = wp.zeros(n, dtype=wp.vec3d), wp.zeros(n, dtype=wp.vec3d)
        self._ring = [self.mask.ring_start, self.mask.ring, self.mask.centre_weight, self.mask.ring_weight]

    def _laws(self, scale: float, dt: float) -> list:
        g = self.ground
        return [wp.float64(value) for value in (scale, dt, g.stiffness, g.damping, g.friction, g.sharpness)]

    def _coupled(self, forces, predictor, scale: float, out) -> None:
        """out = predictor + scale (A forces - r forces) (`limit_coupled_velocity_kernel`)."""
        self.load.zero_()
        spread_to_control_points(self.ground, forces, self.mask, None, None, self.load)
        wp.launch(limit_coupled_velocity_kernel, dim=len(out), inputs=[self.load, self.solver.inverse_mass,
                                                                       wp.float64(scale), *self._ring, predictor,
                                                                       self.response, forces],
                  outputs=[out], device=out.device)  # fmt: skip

    def forward(self, x, v_star, scale: float, dt: float) -> None:
        """The contact solve at positions x from the predictor v_star, every sweep's forces and velocities kept."""
        device, n = x.device, len(x)
        ground_motion(self.ground, x, v_star, self.mask, None, self.p, self.u_star)
        wp.launch(contact_indicator_kernel, dim=n, inputs=[self.p], outputs=[self.forces[0]], device=device)
        self.load.zero_()
        spread_to_control_points(self.ground, self.forces[0], self.mask, None, None, self.load)
        wp.launch(limit_response_kernel, dim=n, inputs=[self.load, self.solver.inverse_mass, *self._ring],
                  outputs=[self.response], device=device)  # fmt: skip
        laws = self._laws(scale, dt)
        inputs = [self.p, self.u_star]
        for s in range(len(self.forces)):
            if s > 0:
                self._coupled(self.forces[s - 1], self.u_star, scale, self.others[s])
                inputs = [self.p, self.others[s]]
            wp.launch(implicit_contact_kernel, dim=n, inputs=[*inputs, self.response, *laws, self.body],
                      outputs=[self.normal, self.forces[s]], device=device)  # fmt: skip

    def backward(self, force_hat, scale: float, dt: float, u_star_hat, p_hat) -> None:
        """Given f̂ of the final forces at the points: u_star_hat = û* (overwritten), p_hat += ẑ, and `gradient` +=
        ∂/∂(k, β, μ, k_f, scale) of f̂ · f, the final velocity's share of scale included."""
        gradient = self.gradient
        eval_weighted_dot(force_hat, self.forces[-1], 1.0 / scale, 4, gradient)  # v = v* + scale M⁻¹ Lᵀ f
        wp.copy(self.f_hat, force_hat)
        u_star_hat.zero_()
        for s in reversed(range(len(self.forces))):
            velocity = self.u_star if s == 0 else self.others[s]
            eval_implicit_law_adjoint(self.ground, self.p, velocity, self.response, scale, dt, self.f_hat, self.o_hat,
                                      p_hat, gradient)  # fmt: skip
            eval_add(u_star_hat, self.o_hat)
            if s > 0:  # o^s = u* + scale (A - r) f^(s-1): ∂/∂scale, then f̂^(s-1)
                self._coupled(self.o_hat, self.zeros, scale, self.f_hat)
                eval_weighted_dot(self.f_hat, self.forces[s - 1], 1.0 / scale, 4, gradient)

